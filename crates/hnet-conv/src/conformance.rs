//! Random convolutions compared with Burn's own operations on the same device: the check the
//! native property tests (`tests/against_burn.rs`) and the browser tests (`tests/web.rs` at the
//! workspace root) both run, so that the kernels are held to one standard everywhere.
//!
//! A [`ConvCase`] is drawn from a seed: batch, channels, image size, kernel, stride, padding,
//! dilation, bias, and for transposed convolutions the output padding, each over a range that
//! includes the edge cases (1x1 images, kernels wider than the image, padding larger than the
//! kernel, stride larger than the kernel). Operand values are in [-1, 1].

use burn::tensor::ops::{ConvOptions, ConvTransposeOptions};
use burn::tensor::{Device, Tensor, TensorData, activation, module};

/// Largest difference from Burn allowed, relative to the largest magnitude of Burn's result
/// (plus one): `max |ours - burn| <= TOLERANCE * (1 + max |burn|)`. The sums of a case have at most
/// a few thousand terms of magnitude at most one; f32 rounding of such sums in another order
/// stays below 1e-5 relative.
pub const TOLERANCE: f32 = 1e-4;

/// One convolution (or transposed convolution) with deterministic operands.
#[derive(Debug, Clone, PartialEq)]
pub struct ConvCase {
    /// Transposed convolution rather than convolution.
    pub transposed: bool,
    /// Images in the batch.
    pub batch: usize,
    /// Channels of the input `x`.
    pub in_channels: usize,
    /// Channels of the result.
    pub out_channels: usize,
    /// Input height and width, pixels.
    pub size: [usize; 2],
    /// Kernel height and width, taps.
    pub kernel: [usize; 2],
    /// Stride per axis.
    pub stride: [usize; 2],
    /// Padding per axis, `(before, after)`; a transposed convolution uses `before` only.
    pub padding: [(usize, usize); 2],
    /// Dilation per axis.
    pub dilation: [usize; 2],
    /// Output padding per axis (transposed only).
    pub padding_out: [usize; 2],
    /// Whether the convolution has a bias.
    pub bias: bool,
    /// Whether a ReLU follows (fused into the project's kernels by [`crate::conv2d_relu`];
    /// convolutions only).
    pub relu: bool,
    /// Seed of the operand values.
    pub seed: u64,
}

/// splitmix64: a small, well-mixed sequence from a seed.
struct Draw(u64);

impl Draw {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// True once in `n` draws, on average.
    fn one_in(&mut self, n: u64) -> bool {
        self.next().is_multiple_of(n)
    }

    /// A value in `low..=high`.
    fn between(&mut self, low: usize, high: usize) -> usize {
        low + (self.next() % (high - low + 1) as u64) as usize
    }
}

impl ConvCase {
    /// The case drawn from `seed`.
    pub fn from_seed(seed: u64) -> Self {
        let mut d = Draw(seed);
        let transposed = d.one_in(3);
        let kernel = [d.between(1, 4), d.between(1, 4)];
        let stride = [d.between(1, 3), d.between(1, 3)];
        let dilation = [1 + usize::from(d.one_in(4)), 1 + usize::from(d.one_in(4))];
        let mut padding = [
            (d.between(0, 3), d.between(0, 3)),
            (d.between(0, 3), d.between(0, 3)),
        ];
        let relu = !transposed && d.one_in(2);
        let mut padding_out = [0, 0];
        if transposed {
            for axis in 0..2 {
                // Burn requires a symmetric padding and an output padding below the stride or
                // the dilation.
                padding[axis].1 = padding[axis].0;
                padding_out[axis] = d.between(0, stride[axis].max(dilation[axis]) - 1);
            }
        }
        Self {
            transposed,
            batch: d.between(1, 3),
            in_channels: d.between(1, 5),
            out_channels: d.between(1, 5),
            size: [d.between(1, 12), d.between(1, 12)],
            kernel,
            stride,
            padding,
            dilation,
            padding_out,
            bias: !d.one_in(4),
            relu,
            seed,
        }
    }

    /// H-Net's shapes at a small scale: a 3x3 convolution with padding 1, or the decoder's 3x3
    /// transposed convolution with stride 2, padding 1 and output padding 1.
    pub fn h_net_layer(transposed: bool, seed: u64) -> Self {
        Self {
            transposed,
            batch: 2,
            in_channels: 4,
            out_channels: 3,
            size: [8, 6],
            kernel: [3, 3],
            stride: if transposed { [2, 2] } else { [1, 1] },
            padding: [(1, 1), (1, 1)],
            dilation: [1, 1],
            padding_out: if transposed { [1, 1] } else { [0, 0] },
            bias: true,
            // H-Net's convolutions are each followed by a ReLU.
            relu: !transposed,
            seed,
        }
    }

    /// H-Net's 3x3 convolution on an image wide enough for Winograd's kernel
    /// ([`crate::winograd`]), its last strip partial, with 5 and 7 channels (uneven register
    /// tiles).
    pub fn winograd_layer(seed: u64) -> Self {
        Self {
            in_channels: 5,
            out_channels: 7,
            size: [6, 2 * crate::winograd::STRIP_TILES + 6],
            ..Self::h_net_layer(false, seed)
        }
    }

    /// The same on an image whose output is whole 4 x 4 tiles at least a strip of them wide, so
    /// that the Winograd kernel takes F(4x4, 3x3), its last strip partial.
    pub fn winograd_large_tile_layer(seed: u64) -> Self {
        Self {
            size: [8, 4 * crate::winograd::STRIP_TILES + 4],
            ..Self::winograd_layer(seed)
        }
    }

    /// True when Burn itself gives a result (an output of at least one pixel).
    pub fn is_valid(&self) -> bool {
        (0..2).all(|a| {
            let reach = self.dilation[a] * (self.kernel[a] - 1) + 1;
            if self.transposed {
                (self.size[a] - 1) * self.stride[a] + reach + self.padding_out[a]
                    > 2 * self.padding[a].0
            } else {
                self.size[a] + self.padding[a].0 + self.padding[a].1 >= reach
            }
        })
    }

    fn values(&self, salt: u64, shape: &[usize]) -> TensorData {
        let count = shape.iter().product::<usize>();
        let mut d = Draw(self.seed ^ salt.wrapping_mul(0xA24B_AED4_963E_E407));
        let values: Vec<f32> = (0..count)
            .map(|_| (d.next() >> 40) as f32 / (1u64 << 23) as f32 - 1.0)
            .collect();
        TensorData::new(values, shape.to_vec())
    }

    /// The operands `(x, weight, bias)` on `device`.
    pub fn operands(&self, device: &Device) -> (Tensor<4>, Tensor<4>, Option<Tensor<1>>) {
        let x = [self.batch, self.in_channels, self.size[0], self.size[1]];
        let (weight, bias) = if self.transposed {
            (
                [
                    self.in_channels,
                    self.out_channels,
                    self.kernel[0],
                    self.kernel[1],
                ],
                self.out_channels,
            )
        } else {
            (
                [
                    self.out_channels,
                    self.in_channels,
                    self.kernel[0],
                    self.kernel[1],
                ],
                self.out_channels,
            )
        };
        (
            Tensor::from_data(self.values(1, &x), device),
            Tensor::from_data(self.values(2, &weight), device),
            self.bias
                .then(|| Tensor::from_data(self.values(3, &[bias]), device)),
        )
    }

    /// The convolution (with its ReLU when `relu`) computed by Burn's own operations
    /// (`project: false`) or by [`crate::conv2d`], [`crate::conv2d_relu`] or
    /// [`crate::conv_transpose2d`] (`project: true`).
    pub fn compute(
        &self,
        project: bool,
        x: Tensor<4>,
        weight: Tensor<4>,
        bias: Option<Tensor<1>>,
    ) -> Tensor<4> {
        if self.transposed {
            let options = ConvTransposeOptions::new(
                self.stride,
                [self.padding[0].0, self.padding[1].0],
                self.padding_out,
                self.dilation,
                1,
            );
            match project {
                true => crate::conv_transpose2d(x, weight, bias, options),
                false => module::conv_transpose2d(x, weight, bias, options),
            }
        } else {
            let options =
                ConvOptions::new_with_padding(self.stride, self.padding, self.dilation, 1);
            match (project, self.relu) {
                (true, false) => crate::conv2d(x, weight, bias, options),
                (true, true) => crate::conv2d_relu(x, weight, bias, options),
                (false, false) => module::conv2d(x, weight, bias, options),
                (false, true) => activation::relu(module::conv2d(x, weight, bias, options)),
            }
        }
    }

    /// `max |ours - burn| / (1 + max |burn|)` of the forward pass on `device`.
    pub fn forward_error(&self, device: &Device) -> f32 {
        let (x, w, b) = self.operands(device);
        let ours = self.compute(true, x.clone(), w.clone(), b.clone());
        let burn = self.compute(false, x, w, b);
        relative_error(ours, burn)
    }

    /// The same error for the gradients of `x`, the weight and the bias of
    /// `sum(result * r)` for a random `r`, on an autodiff `device`.
    #[cfg(feature = "autodiff")]
    pub fn gradient_errors(&self, device: &Device) -> [f32; 3] {
        let run = |project: bool| {
            let (x, w, b) = self.operands(device);
            let (x, w) = (x.require_grad(), w.require_grad());
            let b = b.map(|b| b.require_grad());
            let y = self.compute(project, x.clone(), w.clone(), b.clone());
            let r = Tensor::<4>::from_data(self.values(4, &y.dims()), device);
            let grads = (y * r).sum().backward();
            (
                x.grad(&grads),
                w.grad(&grads),
                b.and_then(|b| b.grad(&grads)),
            )
        };
        let (ours, burn) = (run(true), run(false));
        [
            gradient_error(ours.0, burn.0),
            gradient_error(ours.1, burn.1),
            gradient_error(ours.2, burn.2),
        ]
    }
}

/// [`relative_error`] of two gradients; infinite when only one exists.
#[cfg(feature = "autodiff")]
fn gradient_error<const D: usize>(ours: Option<Tensor<D>>, burn: Option<Tensor<D>>) -> f32 {
    match (ours, burn) {
        (Some(ours), Some(burn)) => relative_error(ours, burn),
        (None, None) => 0.0,
        _ => f32::INFINITY,
    }
}

/// `max |a - b| / (1 + max |b|)`, infinite when the shapes differ.
pub fn relative_error<const D: usize>(a: Tensor<D>, b: Tensor<D>) -> f32 {
    if a.dims() != b.dims() {
        return f32::INFINITY;
    }
    let a = a
        .into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .expect("f32");
    let b = b
        .into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .expect("f32");
    let scale = 1.0 + b.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let worst = a
        .iter()
        .zip(&b)
        .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
    if worst.is_nan() {
        f32::INFINITY
    } else {
        worst / scale
    }
}
