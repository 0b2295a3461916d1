//! The project's kernels against Burn's own convolutions on flex: random shapes, strides,
//! paddings, dilations and batch sizes, forward and every gradient, within
//! `conformance::TOLERANCE`. Uncovered convolutions (groups) must fall back to Burn exactly, and
//! the burn-nn module helpers must give the module's own `forward`.

use burn::nn::PaddingConfig2d;
use burn::nn::conv::{Conv2dConfig, ConvTranspose2dConfig};
use burn::tensor::ops::ConvOptions;
use burn::tensor::{Device, Tensor, module};
use hnet_conv::conformance::{ConvCase, TOLERANCE, relative_error};
use proptest::prelude::*;

fn check(case: &ConvCase) -> Result<(), TestCaseError> {
    let forward = case.forward_error(&Device::flex());
    prop_assert!(
        forward <= TOLERANCE,
        "forward error {forward:e} for {case:?}"
    );
    let [x, weight, bias] = case.gradient_errors(&Device::flex().autodiff());
    prop_assert!(
        x <= TOLERANCE && weight <= TOLERANCE && bias <= TOLERANCE,
        "gradient errors x {x:e}, weight {weight:e}, bias {bias:e} for {case:?}"
    );
    Ok(())
}

proptest! {
    #![proptest_config(hnet_mutations::cases(48))]

    #[test]
    fn random_convolutions_match_burn(seed in any::<u64>()) {
        let case = ConvCase::from_seed(seed);
        prop_assume!(case.is_valid());
        check(&case)?;
    }
}

/// H-Net's shapes are covered by the kernels (not passed on to Burn, which would make the
/// comparison Burn against itself), and give Burn's results.
#[test]
fn h_net_layers_match_burn() {
    use burn::tensor::ops::ConvTransposeOptions;
    use hnet_conv::geometry::ConvGeometry;
    let same = ConvOptions::new([1, 1], [1, 1], [1, 1], 1);
    assert!(ConvGeometry::of_conv2d([2, 4, 8, 6], [3, 4, 3, 3], &same).is_some());
    let up = ConvTransposeOptions::new([2, 2], [1, 1], [1, 1], [1, 1], 1);
    assert!(ConvGeometry::of_conv_transpose2d([2, 4, 8, 6], [4, 3, 3, 3], &up).is_some());
    for transposed in [false, true] {
        check(&ConvCase::h_net_layer(transposed, 7)).unwrap();
    }
}

/// Images wide enough that the forward pass lowers a few output rows at a time (bands of about
/// 256 pixels), the last band partial, with and without stride.
#[test]
fn wide_images_lowered_in_bands_match_burn() {
    for (stride, bias) in [(1, true), (2, false)] {
        check(&ConvCase {
            size: [9, 100],
            stride: [stride, stride],
            bias,
            ..ConvCase::h_net_layer(false, 11)
        })
        .unwrap();
    }
}

/// Stride-1 convolutions go to the direct kernels (`hnet_conv::direct`): rows that are not a
/// whole number of vectors (the weight gradient's zero-extended tail), more output channels than
/// one register tile, dilation, padding on one side only, and many input channels (the
/// accumulators kept over 333 channel-taps).
#[test]
fn direct_stride_1_convolutions_match_burn() {
    check(&ConvCase {
        in_channels: 37,
        out_channels: 13,
        size: [5, 40],
        ..ConvCase::h_net_layer(false, 17)
    })
    .unwrap();
    for (size, dilation, padding, out_channels) in [
        ([5, 13], [1, 1], [(1, 1), (1, 1)], 7),
        ([9, 20], [2, 1], [(2, 0), (0, 3)], 13),
        ([3, 3], [1, 2], [(0, 0), (2, 2)], 1),
    ] {
        check(&ConvCase {
            size,
            dilation,
            padding,
            out_channels,
            ..ConvCase::h_net_layer(false, 13)
        })
        .unwrap();
    }
}

/// Held by the tests that need a known state of the process-wide Winograd switch: the one that
/// turns it off, and the one that must run through the Winograd kernel.
static WINOGRAD_SWITCH: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Stride-1 3x3 convolutions with outputs of whole tiles at least one strip wide go to Winograd's
/// F(4x4, 3x3) or F(2x2, 3x3) (`hnet_conv::winograd`), forward and input gradient: paddings 1
/// (the browser tests' case), 0 and 2, on one side only, a partial last strip, channel counts that
/// leave uneven register tiles; and the same with the kernel switched off (the direct path). The switch
/// is process-wide: other tests running meanwhile may take either path, both of which must match
/// Burn.
#[test]
fn winograd_convolutions_match_burn() {
    let _switch = WINOGRAD_SWITCH.lock().unwrap_or_else(|e| e.into_inner());
    let wide = 2 * hnet_conv::winograd::STRIP_TILES;
    let cases = [
        ([8, wide + 2], [(0, 0), (0, 0)], 3, 13),
        ([4, wide], [(2, 2), (2, 2)], 8, 32),
        ([8, wide + 2], [(2, 0), (0, 2)], 2, 6),
        ([8, 2 * wide + 4], [(1, 1), (1, 1)], 5, 7),
        ([8, 2 * wide], [(2, 0), (0, 2)], 3, 13),
    ];
    let others = cases.map(|(size, padding, in_channels, out_channels)| ConvCase {
        size,
        padding,
        in_channels,
        out_channels,
        ..ConvCase::h_net_layer(false, 23)
    });
    let layers = [
        ConvCase::winograd_layer(23),
        ConvCase::winograd_large_tile_layer(23),
    ];
    for case in layers.into_iter().chain(others) {
        check(&case).unwrap();
        hnet_conv::use_winograd(false);
        let direct = check(&case);
        hnet_conv::use_winograd(true);
        direct.unwrap();
    }
}

/// A NaN stays NaN through the fused ReLU, where Burn's ReLU keeps it (a diverged network must
/// not look finite): on the direct path (stride 1) and the lowered one (stride 2).
#[test]
fn the_fused_relu_keeps_nan_as_burn_does() {
    // Not while the test above has the Winograd kernel switched off.
    let _switch = WINOGRAD_SWITCH.lock().unwrap_or_else(|e| e.into_inner());
    let device = Device::flex();
    // 40 pixels wide: the direct path stores whole strips from its vector registers there; 8
    // rows, so that Winograd's kernel serves the stride-1 case.
    let shape = [2, 3, 8, 40];
    for stride in [1, 2] {
        let mut image = vec![0.5f32; shape.iter().product()];
        image[4 * 40 + 20] = f32::NAN;
        let x = Tensor::<4>::from_data(burn::tensor::TensorData::new(image, shape), &device);
        let weight = Tensor::<4>::ones([4, 3, 3, 3], &device);
        let options = ConvOptions::new([stride, stride], [1, 1], [1, 1], 1);
        let nan_mask =
            |y: Tensor<4>| -> Vec<bool> { values(y).iter().map(|v| v.is_nan()).collect() };
        let ours = nan_mask(hnet_conv::conv2d_relu(
            x.clone(),
            weight.clone(),
            None,
            options.clone(),
        ));
        let burn = nan_mask(burn::tensor::activation::relu(module::conv2d(
            x, weight, None, options,
        )));
        assert!(
            ours.iter().any(|&n| n),
            "stride {stride}: no NaN came through"
        );
        assert_eq!(ours, burn, "stride {stride}");
    }
}

#[test]
fn flex_and_autodiff_flex_reach_the_project_kernels() {
    use burn::tensor::DType;
    assert!(hnet_conv::runs_on_project_kernels(
        &Device::flex(),
        DType::F32
    ));
    assert!(hnet_conv::runs_on_project_kernels(
        &Device::flex().autodiff(),
        DType::F32
    ));
    assert!(!hnet_conv::runs_on_project_kernels(
        &Device::flex(),
        DType::F64
    ));
}

#[test]
fn grouped_convolutions_fall_back_to_burn() {
    let device = Device::flex();
    let x = Tensor::<4>::random([2, 4, 6, 6], burn::tensor::Distribution::Default, &device);
    let w = Tensor::<4>::random([6, 2, 3, 3], burn::tensor::Distribution::Default, &device);
    let options = ConvOptions::new([1, 1], [1, 1], [1, 1], 2);
    let ours = hnet_conv::conv2d(x.clone(), w.clone(), None, options.clone());
    let burn = module::conv2d(x, w, None, options);
    assert_eq!(relative_error(ours, burn), 0.0);
}

#[test]
fn module_helpers_give_the_modules_forward() {
    let device = Device::flex();
    for (size, kernel, stride, padding) in [
        ([9, 7], 3, 1, PaddingConfig2d::Same),
        ([9, 8], 3, 2, PaddingConfig2d::Same),
        ([6, 5], 2, 2, PaddingConfig2d::Same),
        ([7, 7], 1, 1, PaddingConfig2d::Valid),
        ([7, 6], 3, 1, PaddingConfig2d::Explicit(1, 2, 0, 1)),
    ] {
        let conv = Conv2dConfig::new([3, 4], [kernel, kernel])
            .with_stride([stride, stride])
            .with_padding(padding)
            .init(&device);
        let x = Tensor::<4>::random(
            [2, 3, size[0], size[1]],
            burn::tensor::Distribution::Default,
            &device,
        );
        let error = relative_error(
            hnet_conv::conv2d_module(&conv, x.clone()),
            conv.forward(x.clone()),
        );
        assert!(error <= TOLERANCE, "{size:?} {kernel} {stride}: {error:e}");
        let error = relative_error(
            hnet_conv::conv2d_relu_module(&conv, x.clone()),
            burn::tensor::activation::relu(conv.forward(x)),
        );
        assert!(
            error <= TOLERANCE,
            "relu {size:?} {kernel} {stride}: {error:e}"
        );
    }
    let up = ConvTranspose2dConfig::new([4, 3], [3, 3])
        .with_stride([2, 2])
        .with_padding([1, 1])
        .with_padding_out([1, 1])
        .init(&device);
    let x = Tensor::<4>::random([2, 4, 5, 4], burn::tensor::Distribution::Default, &device);
    let error = relative_error(
        hnet_conv::conv_transpose2d_module(&up, x.clone()),
        up.forward(x),
    );
    assert!(error <= TOLERANCE, "transposed: {error:e}");
}

/// A tensor's values, row-major.
fn values(t: Tensor<4>) -> Vec<f32> {
    t.into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .unwrap()
}

/// Values as bits, so that NaN compares equal to NaN and -0 differs from 0.
fn bits(t: Tensor<4>) -> Vec<u32> {
    values(t).iter().map(|v| v.to_bits()).collect()
}

/// The project's 2 x 2 max pooling and its gradient against Burn's, bit for bit: odd sizes,
/// ties (values drawn from a few levels, zeros as after a ReLU, -0 and 0), NaN.
fn check_max_pool(dims: [usize; 4], seed: u64) -> Result<(), TestCaseError> {
    use burn::tensor::TensorData;
    use burn::tensor::ops::MaxPoolOptions;
    let len: usize = dims.iter().product();
    let mut state = seed | 1;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let levels = [0.0, -0.0, 0.0, 1.5, -2.0, 0.25, f32::NAN, 3.0];
    let x: Vec<f32> = (0..len)
        .map(|_| match next() % 16 {
            k @ 0..8 => levels[k as usize],
            _ => (next() % 1000) as f32 / 100.0 - 5.0,
        })
        .collect();
    // Output gradients with -0 among them (Burn's backward adds each to 0, giving +0).
    let dy: Vec<f32> = (0..len / 4 + 1)
        .map(|_| match next() % 8 {
            0 => -0.0,
            k => k as f32 - 4.0,
        })
        .collect();
    for device in [Device::flex(), Device::flex().autodiff()] {
        let input = || {
            let x = Tensor::<4>::from_data(TensorData::new(x.clone(), dims), &device);
            if device.is_autodiff() {
                x.require_grad()
            } else {
                x
            }
        };
        let ours = hnet_conv::max_pool2x2(input());
        let burn = module::max_pool2d(input(), MaxPoolOptions::new([2, 2]));
        prop_assert_eq!(ours.dims(), burn.dims());
        prop_assert_eq!(bits(ours.clone()), bits(burn.clone()), "forward {:?}", dims);
        if !device.is_autodiff() {
            continue;
        }
        let out_dims = ours.dims();
        let weights = Tensor::<4>::from_data(
            TensorData::new(dy[..out_dims.iter().product()].to_vec(), out_dims),
            &device,
        );
        let gradient = |x: Tensor<4>, y: Tensor<4>| {
            let grads = (y * weights.clone()).sum().backward();
            x.grad(&grads).unwrap()
        };
        let (x_ours, x_burn) = (input(), input());
        let ours = gradient(x_ours.clone(), hnet_conv::max_pool2x2(x_ours));
        let burn = gradient(
            x_burn.clone(),
            module::max_pool2d(x_burn, MaxPoolOptions::new([2, 2])),
        );
        prop_assert_eq!(bits(ours), bits(burn), "gradient {:?}", dims);
    }
    Ok(())
}

proptest! {
    #![proptest_config(hnet_mutations::cases(32))]

    #[test]
    fn max_pooling_matches_burn_bit_for_bit(
        dims in (1usize..4, 1usize..5, 0usize..12, 0usize..12),
        seed in any::<u64>(),
    ) {
        check_max_pool([dims.0, dims.1, dims.2, dims.3], seed)?;
    }
}
