//! The H-Net architecture (paper section II.B, Fig. 2).
//!
//! Each view goes through a U-Net-like encoder-decoder: `depth` encoder blocks of two 3x3
//! convolutions with ReLU followed by 2x2 max pooling (the block output before pooling is kept as
//! a skip connection), a bottleneck of two 3x3 convolutions, and `depth` decoder blocks of a 3x3
//! transposed convolution with stride 2, concatenation with the matching skip and two 3x3
//! convolutions. A 1x1 convolution and a sigmoid give the view's catheter mask. There are no
//! normalization layers.
//!
//! By default the encoder, decoder and segmentation head are one set of weights applied to both
//! views (the two views run as one batch of `2B`), so swapping the views swaps the masks.
//!
//! The force head global-average-pools the bottleneck and every decoder block output of each view
//! (eq. 1, 2, 4), concatenates the pooled vectors of both views (eq. 5) and regresses the tip force
//! `(Fx, Fy, Fz)` in newtons through dense layers of 64 and 32 units with ReLU and a linear output.
//!
//! The convolutions go through `hnet_conv` (the project's kernels on the flex CPU backend, Burn's
//! own operations on every other backend); the weights and their files are burn-nn's modules.

use alloc::vec::Vec;

use hnet_units::{ImageSize, TipForce, View};
use serde::{Deserialize, Serialize};

use burn::config::Config;
use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::{Linear, LinearConfig, PaddingConfig2d};
use burn::tensor::activation::{relu, sigmoid};
use burn::tensor::{Device, Tensor};
use hnet_conv::{conv_transpose2d_module, conv2d_module, conv2d_relu_module, max_pool2x2};

/// Settings of the network. The defaults are the paper's.
#[derive(Config, Debug, PartialEq)]
pub struct HNetConfig {
    /// Channels of each input image (3: RGB, or grey replicated to three channels).
    #[config(default = 3)]
    pub in_channels: usize,
    /// Filters of every convolution (the paper uses 32 throughout).
    #[config(default = 32)]
    pub filters: usize,
    /// Number of encoder blocks, and of decoder blocks (the paper uses 4).
    #[config(default = 4)]
    pub depth: usize,
    /// Input image size in pixels; width and height must be divisible by `2^depth`.
    #[config(default = "ImageSize::square(224)")]
    pub image_size: ImageSize,
    /// One encoder-decoder and segmentation head for both views (the paper's design). When false,
    /// each view gets its own weights.
    #[config(default = true)]
    pub share_weights: bool,
    /// Units of the two hidden dense layers of the force head.
    #[config(default = "[64, 32]")]
    pub force_hidden: [usize; 2],
    /// Give the first convolution two more input channels holding each pixel's column and row,
    /// scaled to `[-1, 1]` ("CoordConv", Liu et al., NeurIPS 2018). The force head only sees
    /// globally averaged features, from which the paper's network must learn where the
    /// catheter is through the convolutions' zero padding alone; with the position as an
    /// input, averaged features carry the catheter's position and spread (its shape, hence
    /// the force) from the first step. Off (absent or false) in the paper's design and in
    /// weights written before it existed; see [`HNetConfig::uses_position_channels`].
    pub position_channels: Option<bool>,
    /// When set, the force head's linear output is a standardised force that the network turns
    /// back into newtons (`F = mean + std · output`), so that it learns targets of unit scale
    /// while every output stays in newtons. Absent in weights written before it existed.
    pub force_scale: Option<ForceScale>,
}

/// The tip force's per-axis mean and standard deviation over a training set, in newtons.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ForceScale {
    /// Mean of `(Fx, Fy, Fz)`, N.
    pub mean_n: [f64; 3],
    /// Standard deviation of `(Fx, Fy, Fz)`, N (each positive).
    pub std_n: [f64; 3],
}

impl ForceScale {
    /// The statistics of `forces` (N); `None` for fewer than two forces or an axis that does
    /// not vary.
    pub fn of(forces: impl IntoIterator<Item = TipForce>) -> Option<Self> {
        let (mut n, mut sum, mut sum_sq) = (0usize, [0.0f64; 3], [0.0f64; 3]);
        for f in forces {
            let f = f.to_f64();
            n += 1;
            for axis in 0..3 {
                sum[axis] += f[axis];
                sum_sq[axis] += f[axis] * f[axis];
            }
        }
        if n < 2 {
            return None;
        }
        let mean_n = sum.map(|s| s / n as f64);
        let mut std_n = [0.0; 3];
        for axis in 0..3 {
            let variance = (sum_sq[axis] / n as f64 - mean_n[axis] * mean_n[axis]).max(0.0);
            std_n[axis] = variance.sqrt();
        }
        (std_n.iter().all(|s| *s > 1e-12 && s.is_finite())).then_some(Self { mean_n, std_n })
    }
}

/// Why a [`HNetConfig`] cannot build a network.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum HNetConfigError {
    /// A size that must be positive is zero.
    #[error("`{0}` must be at least 1")]
    Zero(&'static str),
    /// The image size cannot be halved `depth` times.
    #[error("image size {image_size} (width×height) must be divisible by 2^depth = 2^{depth}")]
    ImageSizeNotDivisible {
        /// The configured size.
        image_size: ImageSize,
        /// The configured depth: sizes must be divisible by `2^depth`.
        depth: usize,
    },
    /// A weight tensor's element count, from the settings, does not fit in `usize` (a file
    /// claiming absurd sizes: no real network has them).
    #[error("the settings' {0} overflow: no network of these sizes can exist")]
    Overflow(&'static str),
}

impl HNetConfig {
    /// Checks that the settings describe a network that can be built.
    pub fn validate(&self) -> Result<(), HNetConfigError> {
        for (name, value) in [
            ("in_channels", self.in_channels),
            ("filters", self.filters),
            ("depth", self.depth),
            ("image_size.width", self.image_size.width),
            ("image_size.height", self.image_size.height),
            ("force_hidden[0]", self.force_hidden[0]),
            ("force_hidden[1]", self.force_hidden[1]),
        ] {
            if value == 0 {
                return Err(HNetConfigError::Zero(name));
            }
        }
        let divisible = |size: usize| {
            u32::try_from(self.depth)
                .ok()
                .and_then(|depth| 1usize.checked_shl(depth))
                .is_some_and(|divisor| divisor <= size && size.is_multiple_of(divisor))
        };
        if !divisible(self.image_size.width) || !divisible(self.image_size.height) {
            return Err(HNetConfigError::ImageSizeNotDivisible {
                image_size: self.image_size,
                depth: self.depth,
            });
        }
        self.check_tensor_sizes()
    }

    /// Refuses settings whose largest weight tensors' element counts overflow `usize`: the
    /// convolutions' `channels × filters × 3 × 3` and the force head's layers, whose input is
    /// both views' [`HNetConfig::pooled_features_per_view`] (found by the weights property tests).
    fn check_tensor_sizes(&self) -> Result<(), HNetConfigError> {
        let product = |factors: &[usize]| {
            factors
                .iter()
                .try_fold(1usize, |total, &factor| total.checked_mul(factor))
        };
        let channels = self.in_channels.checked_add(2).map(|c| c.max(self.filters));
        let features = self
            .depth
            .checked_add(1)
            .and_then(|blocks| product(&[blocks, self.filters, 2]));
        let [hidden1, hidden2] = self.force_hidden;
        let sizes = [
            (
                "convolution sizes",
                channels.and_then(|c| product(&[c, self.filters, 9])),
            ),
            (
                "force head's input",
                features.and_then(|f| product(&[f, hidden1])),
            ),
            (
                "force head's hidden layers",
                product(&[hidden1, hidden2, 3]),
            ),
        ];
        match sizes.into_iter().find(|(_, size)| size.is_none()) {
            Some((what, _)) => Err(HNetConfigError::Overflow(what)),
            None => Ok(()),
        }
    }

    /// Whether the first convolution also reads each pixel's position
    /// ([`HNetConfig::position_channels`]).
    pub fn uses_position_channels(&self) -> bool {
        self.position_channels == Some(true)
    }

    /// Length of the pooled feature vector of one view: the bottleneck and every decoder block.
    pub fn pooled_features_per_view(&self) -> usize {
        (self.depth + 1) * self.filters
    }

    /// Builds a network with freshly initialised weights on `device`.
    pub fn init(&self, device: &Device) -> Result<HNet, HNetConfigError> {
        self.validate()?;
        let segmentation = SegmentationBranch::new(self, device);
        let segmentation_b = (!self.share_weights).then(|| SegmentationBranch::new(self, device));
        let features = 2 * self.pooled_features_per_view();
        let force = ForceHead {
            hidden1: LinearConfig::new(features, self.force_hidden[0]).init(device),
            hidden2: LinearConfig::new(self.force_hidden[0], self.force_hidden[1]).init(device),
            output: LinearConfig::new(self.force_hidden[1], 3).init(device),
        };
        Ok(HNet {
            segmentation,
            segmentation_b,
            force,
            force_scale: self.force_scale,
        })
    }
}

/// Two 3x3 convolutions, each followed by ReLU, keeping the spatial size.
#[derive(Module, Debug)]
pub struct DoubleConv {
    first: Conv2d,
    second: Conv2d,
}

impl DoubleConv {
    fn new(in_channels: usize, filters: usize, device: &Device) -> Self {
        let conv = |cin| {
            Conv2dConfig::new([cin, filters], [3, 3])
                .with_padding(PaddingConfig2d::Same)
                .init(device)
        };
        Self {
            first: conv(in_channels),
            second: conv(filters),
        }
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        // Each convolution's ReLU fused into it on the CPU (`hnet_conv::conv2d_relu_module`).
        conv2d_relu_module(&self.second, conv2d_relu_module(&self.first, x))
    }
}

/// A decoder block: 3x3 transposed convolution with stride 2 (doubling height and width), then
/// concatenation with the encoder's skip connection and two 3x3 convolutions.
#[derive(Module, Debug)]
pub struct UpBlock {
    up: ConvTranspose2d,
    conv: DoubleConv,
}

impl UpBlock {
    fn new(filters: usize, device: &Device) -> Self {
        Self {
            // padding 1 and output padding 1 give exactly twice the input size, like Keras'
            // `Conv2DTranspose(strides=2, padding="same")`.
            up: ConvTranspose2dConfig::new([filters, filters], [3, 3])
                .with_stride([2, 2])
                .with_padding([1, 1])
                .with_padding_out([1, 1])
                .init(device),
            conv: DoubleConv::new(2 * filters, filters, device),
        }
    }

    fn forward(&self, x: Tensor<4>, skip: Tensor<4>) -> Tensor<4> {
        let up = conv_transpose2d_module(&self.up, x);
        self.conv.forward(Tensor::cat(alloc::vec![up, skip], 1))
    }
}

/// The per-view encoder-decoder with its segmentation head.
#[derive(Module, Debug)]
pub struct SegmentationBranch {
    #[module(skip)]
    position_channels: bool,
    /// Width of [`BranchOutput::pooled`]: `(depth+1)·filters`.
    #[module(skip)]
    pooled_width: usize,
    encoder: Vec<DoubleConv>,
    bottleneck: DoubleConv,
    decoder: Vec<UpBlock>,
    head: Conv2d,
}

/// What one pass of a [`SegmentationBranch`] produces.
#[derive(Debug, Clone)]
pub struct BranchOutput {
    /// Mask logits `[N, 1, H, W]` (apply a sigmoid for probabilities).
    pub mask_logits: Tensor<4>,
    /// Global average pools of the bottleneck and of each decoder block, `[N, (depth+1)*filters]`.
    pub pooled: Tensor<2>,
}

impl SegmentationBranch {
    fn new(config: &HNetConfig, device: &Device) -> Self {
        let f = config.filters;
        let first_in = config.in_channels
            + if config.uses_position_channels() {
                2
            } else {
                0
            };
        let encoder = (0..config.depth)
            .map(|i| DoubleConv::new(if i == 0 { first_in } else { f }, f, device))
            .collect();
        Self {
            position_channels: config.uses_position_channels(),
            pooled_width: (config.depth + 1) * f,
            encoder,
            bottleneck: DoubleConv::new(f, f, device),
            decoder: (0..config.depth).map(|_| UpBlock::new(f, device)).collect(),
            head: Conv2dConfig::new([f, 1], [1, 1]).init(device),
        }
    }

    /// The branch with its encoder blocks frozen (no gradient): the bottleneck, decoder and
    /// head still learn.
    fn with_frozen_encoder(mut self) -> Self {
        self.encoder = self.encoder.into_iter().map(Module::freeze).collect();
        self
    }

    /// Runs images `[N, C, H, W]` through the branch.
    pub fn forward(&self, images: Tensor<4>) -> BranchOutput {
        let mut skips = Vec::with_capacity(self.encoder.len());
        let mut x = if self.position_channels {
            with_position_channels(images)
        } else {
            images
        };
        for block in &self.encoder {
            x = block.forward(x);
            skips.push(x.clone());
            x = max_pool2x2(x);
        }
        x = self.bottleneck.forward(x);
        let mut pooled = Vec::with_capacity(self.decoder.len() + 1);
        pooled.push(global_average_pool(x.clone()));
        for (block, skip) in self.decoder.iter().zip(skips.into_iter().rev()) {
            x = block.forward(x, skip);
            pooled.push(global_average_pool(x.clone()));
        }
        BranchOutput {
            mask_logits: conv2d_module(&self.head, x),
            pooled: Tensor::cat(pooled, 1),
        }
    }
}

/// `images` `[N, C, H, W]` with two more channels: the column and the row of each pixel's
/// centre, scaled linearly to `[-1, 1]` across the image (see
/// [`HNetConfig::position_channels`]).
fn with_position_channels(images: Tensor<4>) -> Tensor<4> {
    let [n, _, h, w] = images.dims();
    let across = |i: usize, len: usize| (2 * i + 1) as f32 / len as f32 - 1.0;
    let mut planes = Vec::with_capacity(2 * h * w);
    planes.extend((0..h * w).map(|p| across(p % w, w)));
    planes.extend((0..h * w).map(|p| across(p / w, h)));
    let planes = Tensor::<4>::from_data(
        burn::tensor::TensorData::new(planes, [1, 2, h, w]),
        &images.device(),
    )
    .expand([n, 2, h, w]);
    Tensor::cat(alloc::vec![images, planes], 1)
}

/// Mean over height and width: `[N, C, H, W]` to `[N, C]`.
fn global_average_pool(x: Tensor<4>) -> Tensor<2> {
    x.mean_dims(&[2, 3]).flatten(1, 3)
}

/// Dense regression head from the pooled stereo features to the tip force in newtons.
#[derive(Module, Debug)]
pub struct ForceHead {
    hidden1: Linear,
    hidden2: Linear,
    output: Linear,
}

impl ForceHead {
    fn forward(&self, features: Tensor<2>) -> Tensor<2> {
        let x = relu(self.hidden1.forward(features));
        let x = relu(self.hidden2.forward(x));
        self.output.forward(x)
    }
}

/// The H-Net network. Build it with [`HNetConfig::init`].
#[derive(Module, Debug)]
pub struct HNet {
    /// View A's branch, and both views' when weights are shared.
    segmentation: SegmentationBranch,
    /// View B's own branch when weights are not shared.
    segmentation_b: Option<SegmentationBranch>,
    force: ForceHead,
    /// Turns the force head's standardised output into newtons (see [`HNetConfig::force_scale`]).
    #[module(skip)]
    force_scale: Option<ForceScale>,
}

/// The three heads' outputs for a batch of `B` stereo pairs.
#[derive(Debug, Clone)]
pub struct HNetOutput {
    /// View A mask logits `[B, 1, H, W]`.
    pub mask_logits_a: Tensor<4>,
    /// View B mask logits `[B, 1, H, W]`.
    pub mask_logits_b: Tensor<4>,
    /// Tip force `[B, 3]` as `(Fx, Fy, Fz)` in newtons.
    pub force: Tensor<2>,
}

impl HNetOutput {
    /// View A catheter probabilities `[B, 1, H, W]`.
    pub fn mask_a(&self) -> Tensor<4> {
        sigmoid(self.mask_logits_a.clone())
    }

    /// View B catheter probabilities `[B, 1, H, W]`.
    pub fn mask_b(&self) -> Tensor<4> {
        sigmoid(self.mask_logits_b.clone())
    }
}

impl HNet {
    /// What the paths of the force head's parameters contain (`force.hidden1.weight`, ...), to
    /// give the head its own optimiser settings.
    pub const FORCE_HEAD_PATH: &'static str = "force.";

    /// This network with the encoder blocks of its segmentation branches frozen (no gradient),
    /// for fine-tuning on a few pairs: the bottleneck, decoders and heads still learn.
    pub fn with_frozen_encoders(mut self) -> Self {
        self.segmentation = self.segmentation.with_frozen_encoder();
        self.segmentation_b = self
            .segmentation_b
            .map(SegmentationBranch::with_frozen_encoder);
        self
    }

    /// Pooled features one view's branch hands the force head: `(depth+1)·filters`.
    pub fn pooled_per_view(&self) -> usize {
        self.segmentation.pooled_width
    }

    /// Whether both views run through one set of encoder-decoder weights.
    pub fn shares_weights(&self) -> bool {
        self.segmentation_b.is_none()
    }

    /// Runs a batch of stereo pairs: `view_a` and `view_b` are `[B, C, H, W]` images with values
    /// in `[0, 1]`, where `H` and `W` are divisible by `2^depth`.
    pub fn forward(&self, view_a: Tensor<4>, view_b: Tensor<4>) -> HNetOutput {
        self.forward_with_features(view_a, view_b).0
    }

    /// [`HNet::forward`], and the force head's input: the pooled features of both views
    /// `[B, 2·(depth+1)·filters]` (view A's, then view B's), e.g. to measure how much of the
    /// force they carry apart from what the head makes of them.
    pub fn forward_with_features(
        &self,
        view_a: Tensor<4>,
        view_b: Tensor<4>,
    ) -> (HNetOutput, Tensor<2>) {
        let (a, b) = self.branches(view_a, view_b);
        let features = Tensor::cat(alloc::vec![a.pooled, b.pooled], 1);
        let force = self.force_of_features(features.clone());
        let output = HNetOutput {
            mask_logits_a: a.mask_logits,
            mask_logits_b: b.mask_logits,
            force,
        };
        (output, features)
    }

    /// Both views through their branches. Natively (the `rayon` feature) and with no gradient
    /// recorded, each view runs on its own thread, every layer of it on one core: at 64 px a
    /// pair took 6.9 ms as one batch of both views, each layer split between the cores and
    /// handed back, against 4.9 ms so (224 px: 70.5 against 57.2 ms; docs/benchmarks.md). Else,
    /// with shared weights, both views go through as one batch of `2B`. Either way each view's
    /// result is the same: no layer mixes the images of a batch.
    fn branches(&self, view_a: Tensor<4>, view_b: Tensor<4>) -> (BranchOutput, BranchOutput) {
        let branch_b = self.segmentation_b.as_ref().unwrap_or(&self.segmentation);
        #[cfg(feature = "rayon")]
        if !view_a.device().is_autodiff() {
            return rayon::join(
                || self.segmentation.forward(view_a),
                || branch_b.forward(view_b),
            );
        }
        if self.segmentation_b.is_some() {
            return (self.segmentation.forward(view_a), branch_b.forward(view_b));
        }
        let batch = view_a.dims()[0];
        let both = self
            .segmentation
            .forward(Tensor::cat(alloc::vec![view_a, view_b], 0));
        let view = |output: &BranchOutput, first: usize| BranchOutput {
            mask_logits: output.mask_logits.clone().narrow(0, first, batch),
            pooled: output.pooled.clone().narrow(0, first, batch),
        };
        (view(&both, 0), view(&both, batch))
    }

    /// One view's branch alone: `images` `[B, C, H, W]` of `view` through view A's branch, or
    /// view B's own when weights are not shared. With [`HNet::force_of_features`] on both views'
    /// pooled features it computes what [`HNet::forward`] does, one view at a time (how the
    /// page spreads a pair over two workers).
    pub fn forward_view(&self, view: View, images: Tensor<4>) -> BranchOutput {
        match (view, &self.segmentation_b) {
            (View::B, Some(branch_b)) => branch_b.forward(images),
            _ => self.segmentation.forward(images),
        }
    }

    /// The tip force `[B, 3]` in newtons from the force head's input: both views' pooled
    /// features `[B, 2·(depth+1)·filters]`, view A's first (see
    /// [`HNet::forward_with_features`]).
    pub fn force_of_features(&self, features: Tensor<2>) -> Tensor<2> {
        let mut force = self.force.forward(features);
        if let Some(scale) = self.force_scale {
            let device = force.device();
            let row = |v: [f64; 3]| Tensor::<2>::from_floats([v.map(|x| x as f32)], &device);
            force = force * row(scale.std_n) + row(scale.mean_n);
        }
        force
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn config_rejects_sizes_that_cannot_be_pooled() {
        let config = HNetConfig::new().with_image_size(ImageSize::new(224, 100));
        assert_eq!(
            config.validate(),
            Err(HNetConfigError::ImageSizeNotDivisible {
                image_size: ImageSize::new(224, 100),
                depth: 4
            })
        );
        assert!(HNetConfig::new().with_depth(0).validate().is_err());
        assert!(HNetConfig::new().with_depth(70).validate().is_err());
        assert!(HNetConfig::new().validate().is_ok());
    }

    #[test]
    fn pooled_features_count_bottleneck_and_decoder_blocks() {
        assert_eq!(HNetConfig::new().pooled_features_per_view(), 5 * 32);
    }
}
