//! Behaviour of the H-Net network: shapes, weight sharing, gradients, learning.

use burn::module::{Module, ModuleVisitor, Param};
use burn::optim::{GradientsParams, RmsPropConfig};
use burn::tensor::Gradients;
use burn::tensor::{Device, Distribution, Tensor, Tolerance};
use hnet_model::catheter_entry::{CatheterEntry, EntrySetting};
use hnet_model::inference::{
    JoinViewsError, StereoPair, StereoPrediction, ViewReading, host_values, stereo_batch,
};
use hnet_model::mask_averaging::MaskAveraging;
use hnet_model::model::ForceScale;
use hnet_model::predictor::{PairInput, Predictor};
use hnet_model::{HNet, HNetConfig, HNetLossConfig};
use hnet_units::{ImageSize, TipForce, View};

/// A small network that still has the paper's structure (two pooling levels, 8 filters).
fn small_config() -> HNetConfig {
    HNetConfig::new()
        .with_filters(8)
        .with_depth(2)
        .with_image_size(ImageSize::square(16))
}

fn random_views(device: &Device, batch: usize, size: usize) -> (Tensor<4>, Tensor<4>) {
    let shape = [batch, 3, size, size];
    (
        Tensor::random(shape, Distribution::Uniform(0.0, 1.0), device),
        Tensor::random(shape, Distribution::Uniform(0.0, 1.0), device),
    )
}

#[test]
fn outputs_have_the_documented_shapes() {
    let device = Device::flex();
    // The paper's depth and filters, at a small input size.
    let model = HNetConfig::new()
        .with_image_size(ImageSize::new(48, 32))
        .init(&device)
        .unwrap();
    let shape = [2, 3, 32, 48];
    let a = Tensor::zeros(shape, &device);
    let b = Tensor::ones(shape, &device);
    let out = model.forward(a, b);
    assert_eq!(out.mask_logits_a.dims(), [2, 1, 32, 48]);
    assert_eq!(out.mask_logits_b.dims(), [2, 1, 32, 48]);
    assert_eq!(out.force.dims(), [2, 3]);
    let mask = out.mask_a().into_data();
    let values = mask.as_slice::<f32>().unwrap();
    assert!(values.iter().all(|p| (0.0..=1.0).contains(p)));
}

#[test]
fn predict_gives_each_pair_its_masks_and_force() {
    let device = Device::flex();
    let size = ImageSize::new(32, 16);
    let config = small_config().with_image_size(size);
    let model = config.init(&device).unwrap();
    let image = |seed: u8| -> Vec<u8> {
        (0..size.pixels() * 3)
            .map(|i| (i as u8).wrapping_mul(seed))
            .collect()
    };
    let views = [image(3), image(5), image(7), image(11)];
    let pairs = [
        StereoPair {
            view_a: &views[0],
            view_b: &views[1],
        },
        StereoPair {
            view_a: &views[2],
            view_b: &views[3],
        },
    ];
    let predictions = model
        .predict(&pairs, size, &device, MaskAveraging::Single)
        .unwrap();
    // The same as the forward pass of the batch, split per pair.
    let (a, b) = stereo_batch(&pairs, size, &device).unwrap();
    let out = model.forward(a, b);
    let mask_a = host_values(out.mask_a()).unwrap();
    let mask_b = host_values(out.mask_b()).unwrap();
    let force = host_values(out.force).unwrap();
    assert_eq!(predictions.len(), 2);
    let close = |x: &[f32], y: &[f32]| x.iter().zip(y).all(|(x, y)| (x - y).abs() < 1e-6);
    for (i, p) in predictions.iter().enumerate() {
        let pixels = i * size.pixels()..(i + 1) * size.pixels();
        assert_eq!(p.size, size);
        assert_eq!(p.mask_a.len(), size.pixels());
        assert!(close(&p.mask_a, &mask_a[pixels.clone()]), "pair {i}");
        assert!(close(&p.mask_b, &mask_b[pixels]), "pair {i}");
        assert!(
            close(&p.force.newtons(), &force[3 * i..3 * i + 3]),
            "pair {i}"
        );
        // The packed form (the WebGPU worker's) gives the prediction back, and only for its size.
        let packed = p.to_packed();
        assert_eq!(
            StereoPrediction::from_packed(&packed, size).as_ref(),
            Some(p)
        );
        assert_eq!(StereoPrediction::from_packed(&packed[1..], size), None);
        assert_eq!(
            StereoPrediction::from_packed(&packed, ImageSize::square(16)),
            None
        );
    }
    // The registry's predictor, loaded from the weights file's bytes, reads the same pairs the
    // same way, turned or not; it refuses another size by name.
    let bytes = model
        .to_weights_bytes(&config, &Default::default())
        .unwrap();
    let predictor = Predictor::from_weights_bytes(&bytes, None, &device, "small.bpk").unwrap();
    assert_eq!(predictor.image_size, size);
    let inputs: Vec<PairInput<'_>> = pairs
        .iter()
        .map(|p| PairInput {
            view_a: p.view_a,
            view_b: p.view_b,
            masks: None,
        })
        .collect();
    let outputs = predictor.predict(&inputs, &device).unwrap();
    for (p, o) in predictions.iter().zip(&outputs) {
        let [a, b] = o.masks.as_ref().unwrap();
        assert!(close(a, &p.mask_a) && close(b, &p.mask_b));
        assert!(close(&o.force.unwrap().newtons(), &p.force.newtons()));
    }
    // Averaged over each view and its mirror image: the mean of the two readings' masks, the
    // mirror's moved back, and the force of the views as given.
    let mut averaging = Predictor::from_weights_bytes(&bytes, None, &device, "small.bpk").unwrap();
    averaging.mask_averaging = MaskAveraging::Mirrored;
    let mirror = |rgb: &[u8]| -> Vec<u8> {
        rgb.chunks_exact(3 * size.width)
            .flat_map(|row| row.chunks_exact(3).rev().flatten().copied())
            .collect()
    };
    let mirrored_views: Vec<[Vec<u8>; 2]> = inputs
        .iter()
        .map(|p| [mirror(p.view_a), mirror(p.view_b)])
        .collect();
    let mirrored_inputs: Vec<PairInput<'_>> = mirrored_views
        .iter()
        .map(|[a, b]| PairInput {
            view_a: a,
            view_b: b,
            masks: None,
        })
        .collect();
    let mirrored = predictor.predict(&mirrored_inputs, &device).unwrap();
    let averaged = averaging.predict(&inputs, &device).unwrap();
    for ((single, mirrored), averaged) in outputs.iter().zip(&mirrored).zip(&averaged) {
        for view in 0..2 {
            let back: Vec<f32> = mirrored.masks.as_ref().unwrap()[view]
                .chunks_exact(size.width)
                .flat_map(|row| row.iter().rev().copied())
                .collect();
            let mean: Vec<f32> = single.masks.as_ref().unwrap()[view]
                .iter()
                .zip(&back)
                .map(|(a, b)| 0.5 * (a + b))
                .collect();
            assert!(close(&averaged.masks.as_ref().unwrap()[view], &mean));
        }
        assert_eq!(averaged.force, single.force);
    }
    // The page's paths read the same averaged masks: a pair's batch with its mirror images
    // (page thread, WebGPU), and each view with its own on a CPU worker.
    let page = model
        .predict(&pairs, size, &device, MaskAveraging::Mirrored)
        .unwrap();
    for ((p, averaged), pair) in page.iter().zip(&averaged).zip(&pairs) {
        let [a, b] = averaged.masks.as_ref().unwrap();
        assert!(close(&p.mask_a, a) && close(&p.mask_b, b));
        assert!(close(
            &p.force.newtons(),
            &averaged.force.unwrap().newtons()
        ));
        let read = |view, image| {
            model
                .read_view(view, image, size, &device, MaskAveraging::Mirrored)
                .unwrap()
        };
        let joined = model
            .join_views(
                read(View::A, pair.view_a),
                read(View::B, pair.view_b),
                &device,
            )
            .unwrap();
        assert!(close(&joined.mask_a, a) && close(&joined.mask_b, b));
        assert!(close(&joined.force.newtons(), &p.force.newtons()));
    }
    let known = EntrySetting::Known([CatheterEntry::Bottom; 2]);
    let read = predictor.predict_entry(&inputs, &device, known).unwrap();
    assert_eq!(
        read.iter().map(|r| &r.output).collect::<Vec<_>>(),
        outputs.iter().collect::<Vec<_>>()
    );
    let turned = predictor
        .predict_entry(
            &inputs,
            &device,
            EntrySetting::Known([CatheterEntry::Top; 2]),
        )
        .unwrap_err();
    assert!(turned.to_string().contains("square network"), "{turned}");
    let other =
        Predictor::from_weights_bytes(&bytes, Some(ImageSize::square(16)), &device, "small.bpk")
            .err()
            .unwrap();
    assert!(
        other.to_string().contains("takes 32×16 images, not 16×16"),
        "{other}"
    );
    // An image of another size is refused by name.
    let short = [StereoPair {
        view_a: &views[0][3..],
        view_b: &views[1],
    }];
    let err = model
        .predict(&short, size, &device, MaskAveraging::Single)
        .unwrap_err();
    assert!(err.to_string().starts_with("pair 0 view A: "), "{err}");
}

#[test]
fn one_view_at_a_time_reads_the_pair_as_the_whole_network_does() {
    // How the page spreads a pair over two workers: each view's branch apart, then the force
    // head on both views' pooled features; with shared weights and without.
    let device = Device::flex();
    let size = ImageSize::new(32, 16);
    let image = |seed: u8| -> Vec<u8> {
        (0..size.pixels() * 3)
            .map(|i| (i as u8).wrapping_mul(seed).wrapping_add(seed))
            .collect()
    };
    let (view_a, view_b) = (image(3), image(7));
    let pair = StereoPair {
        view_a: &view_a,
        view_b: &view_b,
    };
    for shared in [true, false] {
        let model = small_config()
            .with_image_size(size)
            .with_share_weights(shared)
            .init(&device)
            .unwrap();
        let whole = model
            .predict(&[pair], size, &device, MaskAveraging::Single)
            .unwrap()
            .remove(0);
        let read = |view, image: &[u8]| {
            model
                .read_view(view, image, size, &device, MaskAveraging::Single)
                .unwrap()
        };
        let (a, b) = (read(View::A, &view_a), read(View::B, &view_b));
        assert_eq!(a.pooled.len(), model.pooled_per_view());
        // The packed form (the CPU workers') gives the reading back, and only for its shape.
        let packed = a.to_packed();
        let pooled = model.pooled_per_view();
        assert_eq!(
            ViewReading::from_packed(&packed, size, pooled).as_ref(),
            Some(&a)
        );
        assert_eq!(ViewReading::from_packed(&packed[1..], size, pooled), None);
        let joined = model.join_views(a.clone(), b.clone(), &device).unwrap();
        let close = |x: &[f32], y: &[f32]| {
            x.len() == y.len() && x.iter().zip(y).all(|(x, y)| (x - y).abs() < 1e-5)
        };
        assert!(close(&joined.mask_a, &whole.mask_a), "shared {shared}");
        assert!(close(&joined.mask_b, &whole.mask_b), "shared {shared}");
        assert!(
            close(&joined.force.newtons(), &whole.force.newtons()),
            "shared {shared}"
        );
        // A reading of another network's shape is refused, naming both views.
        let mut short = b;
        short.pooled.pop();
        let refused = model.join_views(a, short, &device).unwrap_err();
        assert!(matches!(refused, JoinViewsError::Mismatch(_)), "{refused}");
        assert!(
            refused.to_string().contains("view B's (32×16, 23)"),
            "{refused}"
        );
    }
    // A view of another size is refused, naming the view.
    let model = small_config().with_image_size(size).init(&device).unwrap();
    let refused = model
        .read_view(View::B, &view_a[3..], size, &device, MaskAveraging::Single)
        .unwrap_err();
    assert!(refused.to_string().contains("view B"), "{refused}");
}

#[test]
fn swapping_the_views_swaps_the_masks_exactly() {
    let device = Device::flex();
    let model = small_config().init(&device).unwrap();
    assert!(model.shares_weights());
    let (a, b) = random_views(&device, 2, 16);
    let forward = model.forward(a.clone(), b.clone());
    let swapped = model.forward(b, a);
    swapped
        .mask_logits_a
        .into_data()
        .assert_eq(&forward.mask_logits_b.into_data(), true);
    swapped
        .mask_logits_b
        .into_data()
        .assert_eq(&forward.mask_logits_a.into_data(), true);
}

#[test]
fn the_views_on_two_threads_read_as_in_one_batch() {
    // Natively with no gradient recorded, `forward` runs each view on its own thread; recording
    // gradients, both views go through as one batch (with shared weights). Same outputs. The
    // threads need hnet-model's `rayon` feature: on in `scripts/test.sh`'s workspace run (hnet-cli
    // asks for it); `cargo test -p hnet-model` alone compares the batch with itself.
    let device = Device::flex();
    let recording = Device::flex().autodiff();
    for shared in [true, false] {
        let model = small_config()
            .with_share_weights(shared)
            .init(&device)
            .unwrap();
        let (a, b) = random_views(&device, 2, 16);
        let threads = model.forward(a.clone(), b.clone());
        let batch = model
            .to_device(&recording)
            .forward(a.to_device(&recording), b.to_device(&recording));
        let same = |x: Tensor<4>, y: Tensor<4>| {
            x.into_data()
                .assert_approx_eq::<f32>(&y.into_data(), Tolerance::absolute(1e-6))
        };
        same(threads.mask_logits_a, batch.mask_logits_a);
        same(threads.mask_logits_b, batch.mask_logits_b);
        threads
            .force
            .into_data()
            .assert_approx_eq::<f32>(&batch.force.into_data(), Tolerance::absolute(1e-6));
    }
}

#[test]
fn without_sharing_each_view_has_its_own_weights() {
    let device = Device::flex();
    let model = small_config()
        .with_share_weights(false)
        .init(&device)
        .unwrap();
    assert!(!model.shares_weights());
    let shared = small_config().init(&device).unwrap();
    assert!(model.num_params() > shared.num_params());
    let (a, b) = random_views(&device, 1, 16);
    let forward = model.forward(a.clone(), b.clone());
    let swapped = model.forward(b, a);
    let difference = (swapped.mask_logits_a - forward.mask_logits_b)
        .abs()
        .max()
        .into_scalar::<f32>();
    assert!(difference > 1e-6, "separate branches gave identical masks");
}

#[test]
fn the_force_head_sees_both_views() {
    let device = Device::flex();
    let model = small_config().init(&device).unwrap();
    let (a, b) = random_views(&device, 1, 16);
    let (_, other_b) = random_views(&device, 1, 16);
    let force = model.forward(a.clone(), b).force;
    let force_other_b = model.forward(a, other_b).force;
    let change = (force - force_other_b).abs().max().into_scalar::<f32>();
    assert!(change > 1e-7, "changing view B did not change the force");
}

/// Fails the test for every parameter tensor whose gradient is missing or all zero.
struct NonZeroGradients<'a> {
    grads: &'a Gradients,
    checked: usize,
    missing: Vec<String>,
}

impl ModuleVisitor for NonZeroGradients<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        self.checked += 1;
        match param.val().grad(self.grads) {
            Some(grad) if grad.clone().abs().sum().into_scalar::<f32>() > 0.0 => {}
            Some(_) => self.missing.push(format!("{:?} (all zero)", param.id)),
            None => self.missing.push(format!("{:?} (none)", param.id)),
        }
    }
}

fn targets(device: &Device, batch: usize, size: usize) -> (Tensor<4>, Tensor<4>, Tensor<2>) {
    // A vertical bar in view A and a horizontal bar in view B.
    let mut a = vec![0.0f32; batch * size * size];
    let mut b = vec![0.0f32; batch * size * size];
    for n in 0..batch {
        for i in 0..size {
            a[n * size * size + i * size + size / 2] = 1.0;
            b[n * size * size + (size / 2) * size + i] = 1.0;
        }
    }
    let shape = [batch, 1, size, size];
    let force: Vec<f32> = (0..batch)
        .flat_map(|n| [0.1 * n as f32, -0.2, 0.3])
        .collect();
    (
        Tensor::from_data(burn::tensor::TensorData::new(a, shape), device),
        Tensor::from_data(burn::tensor::TensorData::new(b, shape), device),
        Tensor::from_data(burn::tensor::TensorData::new(force, [batch, 3]), device),
    )
}

#[test]
fn every_parameter_gets_a_gradient_from_the_total_loss() {
    for share in [true, false] {
        let device = Device::flex().autodiff();
        let model = small_config()
            .with_share_weights(share)
            .init(&device)
            .unwrap();
        let (a, b) = random_views(&device, 2, 16);
        let (mask_a, mask_b, force) = targets(&device, 2, 16);
        let out = model.forward(a, b);
        let loss = HNetLossConfig::new()
            .init()
            .forward(&out, mask_a, mask_b, force);
        let grads = loss.total.backward();
        let mut visitor = NonZeroGradients {
            grads: &grads,
            checked: 0,
            missing: Vec::new(),
        };
        model.visit(&mut visitor);
        // Per branch: 2 convs x (depth + 1) blocks + (1 transposed + 2 convs) x depth + head,
        // each with weight and bias; force head: 3 dense layers with weight and bias.
        let branch = 2 * (2 * 3 + 3 * 2 + 1);
        let expected = if share { branch } else { 2 * branch } + 6;
        assert_eq!(visitor.checked, expected, "share_weights = {share}");
        assert!(
            visitor.missing.is_empty(),
            "share_weights = {share}: parameters without gradient: {:?}",
            visitor.missing
        );
    }
}

#[test]
fn a_few_training_steps_on_a_fixed_batch_lower_the_loss() {
    // The seed does not make this run repeatable: flex has one random generator per process,
    // which the other tests of this binary draw from concurrently, so the weights and views
    // differ from run to run. Enough steps for any such start (15 left one start at 0.86 of its
    // first loss, still falling).
    let device = Device::flex().autodiff();
    device.seed(7);
    let mut model: HNet = small_config().init(&device).unwrap();
    let (a, b) = random_views(&device, 2, 16);
    let (mask_a, mask_b, force) = targets(&device, 2, 16);
    let loss_fn = HNetLossConfig::new().init();
    let mut optimizer = RmsPropConfig::new()
        .with_alpha(0.9)
        .with_momentum(0.0)
        .with_epsilon(1e-7)
        .init();
    let mut losses = Vec::new();
    for _ in 0..30 {
        let out = model.forward(a.clone(), b.clone());
        let loss = loss_fn.forward(&out, mask_a.clone(), mask_b.clone(), force.clone());
        losses.push(loss.total.clone().into_scalar::<f32>());
        let grads = GradientsParams::from_grads(loss.total.backward(), &model);
        model = optimizer.step(1e-3, model, grads);
    }
    let first = losses[0];
    let last = *losses.last().unwrap();
    assert!(last < 0.8 * first, "loss did not fall enough: {losses:?}");
}

#[test]
fn loss_terms_are_weighted_by_the_betas() {
    let device = Device::flex();
    let model = small_config().init(&device).unwrap();
    let (a, b) = random_views(&device, 1, 16);
    let (mask_a, mask_b, force) = targets(&device, 1, 16);
    let out = model.forward(a, b);
    let terms = HNetLossConfig::new()
        .with_beta_a(2.0)
        .with_beta_b(0.5)
        .with_beta_force(10.0)
        .init()
        .forward(&out, mask_a, mask_b, force);
    let expected = terms.bce_a.clone() * 2.0 + terms.bce_b.clone() * 0.5 + terms.mse.clone() * 10.0;
    terms
        .total
        .into_data()
        .assert_approx_eq::<f32>(&expected.into_data(), Tolerance::default());
}

#[test]
fn a_standardised_force_head_answers_in_newtons_and_its_loss_is_standardised() {
    let device = Device::flex();
    let scale = ForceScale::of(
        [[0.1, -0.2, 0.0], [0.3, 0.2, 0.1], [0.2, 0.0, 0.2]].map(TipForce::from_newtons),
    )
    .unwrap();
    assert!((scale.mean_n[0] - 0.2).abs() < 1e-7);
    assert!(
        ForceScale::of([[0.1, 0.0, 0.0], [0.2, 0.0, 0.0]].map(TipForce::from_newtons)).is_none(),
        "Fy never varies"
    );
    // Same weights with and without the scale: the scaled force is mean + std · raw.
    let plain = small_config().init(&device).unwrap();
    let scaled_config = small_config().with_force_scale(Some(scale));
    let bytes = plain
        .to_weights_bytes(&scaled_config, &Default::default())
        .unwrap();
    let (scaled, read_config, _) = HNet::from_weights_bytes(&bytes, &device, "scaled.bpk").unwrap();
    assert_eq!(read_config.force_scale, Some(scale));
    let (a, b) = random_views(&device, 2, 16);
    let raw = plain.forward(a.clone(), b.clone()).force;
    let newtons = scaled.forward(a, b).force;
    let std = Tensor::<2>::from_floats([scale.std_n.map(|v| v as f32)], &device);
    let mean = Tensor::<2>::from_floats([scale.mean_n.map(|v| v as f32)], &device);
    newtons
        .into_data()
        .assert_approx_eq::<f32>(&(raw * std + mean).into_data(), Tolerance::absolute(1e-6));

    // An error of one standard deviation on every axis costs 1 in the standardised loss.
    let loss = HNetLossConfig::new()
        .with_force_std_n(Some(scale.std_n))
        .init();
    let target = Tensor::<2>::from_floats([scale.mean_n.map(|v| v as f32)], &device);
    let off = target.clone() + Tensor::<2>::from_floats([scale.std_n.map(|v| v as f32)], &device);
    let masks = || Tensor::<4>::zeros([1, 1, 4, 4], &device);
    let terms = loss.forward_heads(
        None,
        Some(off.clone()),
        [masks(), masks()],
        target.clone(),
        None,
    );
    terms.mse.into_data().assert_approx_eq::<f32>(
        &burn::tensor::TensorData::from([1.0f32]),
        Tolerance::absolute(1e-5),
    );

    // A pair without a force label adds nothing to the force term, whatever its error; with
    // no labelled pair in the batch the term is zero.
    let wild = target.clone().add_scalar(100.0);
    let two = |a: Tensor<2>, b: Tensor<2>| Tensor::cat(vec![a, b], 0);
    let masks = || Tensor::<4>::zeros([2, 1, 4, 4], &device);
    for (known, expected) in [([1.0f32, 0.0], 1.0f32), ([0.0, 0.0], 0.0)] {
        let known = Tensor::<2>::from_floats([[known[0]], [known[1]]], &device);
        let terms = loss.forward_heads(
            None,
            Some(two(off.clone(), wild.clone())),
            [masks(), masks()],
            two(target.clone(), target.clone()),
            Some(known),
        );
        terms.mse.into_data().assert_approx_eq::<f32>(
            &burn::tensor::TensorData::from([expected]),
            Tolerance::absolute(1e-5),
        );
    }
}

/// A fine-tune of small H-Net weights on a few synthetic pairs (a bright vertical bar, its
/// mask, and a force label on some): held-back pairs are scored before and after, epochs end
/// with reports, the best epoch's weights are a readable weights file, a frozen encoder does
/// not move, and a run that diverges says so and keeps no diverged weights.
#[cfg(feature = "training")]
#[test]
fn fine_tuning_scores_held_back_pairs_and_keeps_the_best_epoch() {
    use hnet_model::fine_tune::{
        FineTune, FineTuneError, FineTuneSettings, FinishReason, TrainingPair,
    };
    use std::collections::BTreeMap;

    let device = Device::flex();
    let net: HNet = small_config().init(&device).unwrap();
    let weights = net
        .to_weights_bytes(&small_config(), &BTreeMap::new())
        .unwrap();
    let pair = |column: usize, force: Option<[f32; 3]>| line_pair(|_| column, 2, force);
    let pairs: Vec<TrainingPair> = (0..6)
        .map(|i| {
            pair(
                2 + 2 * i,
                (i % 2 == 0).then_some([0.1 * i as f32, 0.0, -0.1]),
            )
        })
        .collect();
    let settings = FineTuneSettings {
        max_epochs: 3,
        patience: 3,
        batch_size: 2,
        learning_rate: 1e-3,
        hold_back_every: 3,
        ..FineTuneSettings::default()
    };
    let mut run = FineTune::new(&weights, "small.bpk", pairs.clone(), settings, &device)
        .unwrap()
        .with_reference(vec![pair(7, Some([0.0, 0.1, 0.0]))])
        .unwrap()
        .with_rehearsal(vec![pair(1, Some([0.0, 0.0, 0.1]))])
        .unwrap();
    // The rehearsed pair is trained on, never held back.
    assert_eq!(run.split(), (5, 2));
    assert_eq!(run.score_reference().unwrap().unwrap().pairs, 1);
    let before = run.score().unwrap();
    assert_eq!((before.pairs, before.force_pairs), (2, 1));
    assert!(before.loss.is_finite() && before.force_mae_n.is_some());
    let mut reports = Vec::new();
    while run.finished().is_none() {
        if let Some(report) = run.step().unwrap() {
            reports.push(report);
        }
    }
    assert_eq!(reports.len(), 3);
    assert_eq!(
        reports.last().unwrap().finished_because,
        Some(FinishReason::LastEpoch)
    );
    assert!(reports.iter().any(|r| r.best));
    assert!(
        reports
            .iter()
            .all(|r| r.reference.is_some_and(|s| s.force_pairs == 1))
    );
    let kept = run
        .best_weights(&BTreeMap::new())
        .unwrap()
        .expect("a best epoch");
    let (tuned, _, _) = HNet::from_weights_bytes(&kept, &device, "tuned.bpk").unwrap();
    // The first encoder block was frozen: its weights are the starting ones.
    let first_encoder = |net: &HNet| {
        let mut visitor = FirstParam::default();
        net.visit(&mut visitor);
        visitor.values.unwrap()
    };
    assert_eq!(first_encoder(&tuned), first_encoder(&net));

    // A share of the starting weights kept: the epoch's weights moved that far back towards
    // the start, every parameter (one epoch, so both runs keep the same epoch).
    let every_weight = |bytes: &[u8]| {
        let (net, _, _) = HNet::from_weights_bytes(bytes, &device, "w.bpk").unwrap();
        let mut visitor = AllParams::default();
        net.visit(&mut visitor);
        visitor.values
    };
    let one_epoch = |start_share| {
        let settings = FineTuneSettings {
            max_epochs: 1,
            start_share,
            ..settings
        };
        let mut run =
            FineTune::new(&weights, "small.bpk", pairs.clone(), settings, &device).unwrap();
        while run.finished().is_none() {
            run.step().unwrap();
        }
        every_weight(&run.best_weights(&BTreeMap::new()).unwrap().unwrap())
    };
    let (trained, kept, start) = (one_epoch(0.0), one_epoch(0.25), every_weight(&weights));
    assert_eq!(trained.len(), start.len());
    assert!(trained.iter().zip(&start).any(|(t, s)| t != s));
    for ((t, k), s) in trained.iter().zip(&kept).zip(&start) {
        assert!((k - (0.75 * t + 0.25 * s)).abs() < 1e-5, "{k} {t} {s}");
    }

    // Bad input, refused before anything runs.
    let whole = FineTuneSettings {
        start_share: 1.0,
        ..settings
    };
    let refused = FineTune::new(&weights, "small.bpk", pairs.clone(), whole, &device);
    assert!(matches!(refused, Err(FineTuneError::StartShare(1.0))));
    let too_few = FineTune::new(
        &weights,
        "small.bpk",
        pairs[..1].to_vec(),
        settings,
        &device,
    );
    assert!(matches!(
        too_few,
        Err(FineTuneError::TooFewPairs { found: 1 })
    ));
    let mut big = pairs.clone();
    big[3].mask_b.push(0);
    let other_size = FineTune::new(&weights, "small.bpk", big, settings, &device);
    let Err(error) = other_size else {
        panic!("a pair of another size was accepted")
    };
    assert!(error.to_string().contains("input size"), "{error}");

    // A learning rate that blows up ends the run as diverged, with no diverged weights kept.
    let wild = FineTuneSettings {
        learning_rate: 1e30,
        ..settings
    };
    let mut run = FineTune::new(&weights, "small.bpk", pairs, wild, &device).unwrap();
    let mut last = None;
    while run.finished().is_none() {
        last = run.step().unwrap().or(last);
    }
    assert_eq!(run.finished(), Some(FinishReason::Diverged));
    assert!(!last.unwrap().best);
}

/// The page's tuning workers split each step between them: each computes its share's gradients
/// and every worker applies the same average. Two workers so driven (one scoring, one only
/// training) keep the same weights as each other and as `hnet fine-tune --replicas 2`'s run,
/// which computes the shares one after another, bit for bit.
#[cfg(feature = "training")]
#[test]
fn replicas_in_two_workers_train_as_one_run_does() {
    use hnet_model::fine_tune::{FineTune, FineTuneError, FineTuneSettings, TrainingPair};
    use std::collections::BTreeMap;

    let device = Device::flex();
    let net: HNet = small_config().init(&device).unwrap();
    let weights = net
        .to_weights_bytes(&small_config(), &BTreeMap::new())
        .unwrap();
    let pairs: Vec<TrainingPair> = (0..7)
        .map(|i| {
            let force = (i % 2 == 0).then_some([0.05 * i as f32, 0.0, 0.1]);
            line_pair(|row| 2 + i + row / 4, 1, force)
        })
        .collect();
    let settings = FineTuneSettings {
        max_epochs: 2,
        batch_size: 2,
        learning_rate: 1e-3,
        hold_back_every: 3,
        replicas: 2,
        ..FineTuneSettings::default()
    };
    let new = || FineTune::new(&weights, "small.bpk", pairs.clone(), settings, &device).unwrap();
    let mut native = new();
    // 5 pairs trained on in steps of 2: the last step's second share is empty.
    assert_eq!((native.split(), native.replicas()), ((5, 2), 2));
    let mut native_reports = Vec::new();
    while native.finished().is_none() {
        native_reports.extend(native.step().unwrap());
    }
    let (mut first, mut second) = (new(), new().as_follower());
    let mut reports = Vec::new();
    while first.finished().is_none() {
        let shares = [first.share(0).unwrap(), second.share(1).unwrap()];
        reports.extend(first.apply(&shares).unwrap());
        assert_eq!(
            second.apply(&shares).unwrap(),
            None,
            "the follower scores nothing"
        );
        // Both hold the same weights: the same share, computed by either, is the same.
        if first.finished().is_none() {
            assert_eq!(first.share(1).unwrap(), second.share(1).unwrap());
        }
    }
    assert_eq!(reports, native_reports);
    assert_eq!(
        first.best_weights(&BTreeMap::new()).unwrap(),
        native.best_weights(&BTreeMap::new()).unwrap()
    );
    assert!(matches!(
        first.share(2),
        Err(FineTuneError::NoSuchReplica {
            replica: 2,
            replicas: 2
        })
    ));
    // Shares of another network's size are refused, and change nothing.
    let mut other = new();
    let mut share = other.share(0).unwrap();
    share.gradients.pop();
    assert!(matches!(
        other.apply(&[share]),
        Err(FineTuneError::Shares { .. })
    ));
}

/// A 16 x 16 pair for the fine-tuning tests: both views a bright line `width` pixels wide
/// starting at column `column(row)` of each row, on a dark background, its mask, and `force`
/// (newtons) when it has a label.
#[cfg(feature = "training")]
fn line_pair(
    column: impl Fn(usize) -> usize,
    width: usize,
    force: Option<[f32; 3]>,
) -> hnet_model::fine_tune::TrainingPair {
    let side = 16;
    let mut view = vec![20u8; side * side * 3];
    let mut mask = vec![0u8; side * side];
    for row in 0..side {
        for x in column(row)..column(row) + width {
            view[(row * side + x) * 3..][..3].fill(230);
            mask[row * side + x] = 255;
        }
    }
    hnet_model::fine_tune::TrainingPair {
        view_a: view.clone(),
        view_b: view,
        mask_a: mask.clone(),
        mask_b: mask,
        force_n: force.map(TipForce::from_newtons),
    }
}

/// The values of the first float parameter a visitor meets (the first encoder convolution).
#[cfg(feature = "training")]
#[derive(Default)]
struct FirstParam {
    values: Option<Vec<f32>>,
}

/// Every float parameter's values, in visiting order.
#[cfg(feature = "training")]
#[derive(Default)]
struct AllParams {
    values: Vec<f32>,
}

#[cfg(feature = "training")]
impl ModuleVisitor for AllParams {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        self.values.extend(host_values(param.val()).unwrap());
    }
}

#[cfg(feature = "training")]
impl ModuleVisitor for FirstParam {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if self.values.is_none() {
            self.values = Some(host_values(param.val()).unwrap());
        }
    }
}
