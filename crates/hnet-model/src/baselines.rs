//! The networks H-Net is compared with (paper Tables I and II), in the same harness:
//!
//! - [`UNet`], [`Fcn`] and [`HrNet`]: single-view segmentation networks, applied to both views
//!   with one set of weights (no force head);
//! - [`YNet`]: force only, from a segmented image pair (the two catheter masks), with one encoder
//!   per view joined like a Y.
//!
//! Their sizes are settings; the defaults are small enough to train on a CPU.

use alloc::vec::Vec;

use burn::config::Config;
use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::{BatchNorm, BatchNormConfig, Linear, LinearConfig, PaddingConfig2d};
use burn::tensor::activation::relu;
use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};
use burn::tensor::{Device, Tensor};
use hnet_conv::{conv_transpose2d_module, conv2d_module, conv2d_relu_module, max_pool2x2};

fn conv3x3(cin: usize, cout: usize, device: &Device) -> Conv2d {
    Conv2dConfig::new([cin, cout], [3, 3])
        .with_padding(PaddingConfig2d::Same)
        .init(device)
}

/// Bilinear resize of `[N, C, H, W]` to `size` (`[height, width]`).
fn resize(x: Tensor<4>, size: [usize; 2]) -> Tensor<4> {
    interpolate(
        x,
        InterpolateOptions::new(InterpolateMode::Bilinear)
            .with_align_corners(false)
            .with_output_size(size),
    )
}

/// Two 3x3 convolutions with ReLU.
#[derive(Module, Debug)]
pub struct ConvBlock {
    first: Conv2d,
    second: Conv2d,
}

impl ConvBlock {
    fn new(cin: usize, cout: usize, device: &Device) -> Self {
        Self {
            first: conv3x3(cin, cout, device),
            second: conv3x3(cout, cout, device),
        }
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        conv2d_relu_module(&self.second, conv2d_relu_module(&self.first, x))
    }
}

/// Settings of the U-Net baseline (Ronneberger et al. 2015), filters doubling at each level.
#[derive(Config, Debug, PartialEq)]
pub struct UNetConfig {
    /// Filters of the first level.
    #[config(default = 16)]
    pub base_filters: usize,
    /// Pooling levels.
    #[config(default = 4)]
    pub depth: usize,
}

/// U-Net: one mask per image.
#[derive(Module, Debug)]
pub struct UNet {
    down: Vec<ConvBlock>,
    bottom: ConvBlock,
    up: Vec<ConvTranspose2d>,
    merge: Vec<ConvBlock>,
    head: Conv2d,
}

impl UNetConfig {
    /// The network on `device`.
    pub fn init(&self, device: &Device) -> UNet {
        let f = |level: usize| self.base_filters << level;
        UNet {
            down: (0..self.depth)
                .map(|l| ConvBlock::new(if l == 0 { 3 } else { f(l - 1) }, f(l), device))
                .collect(),
            bottom: ConvBlock::new(f(self.depth - 1), f(self.depth), device),
            up: (0..self.depth)
                .rev()
                .map(|l| {
                    ConvTranspose2dConfig::new([f(l + 1), f(l)], [2, 2])
                        .with_stride([2, 2])
                        .init(device)
                })
                .collect(),
            merge: (0..self.depth)
                .rev()
                .map(|l| ConvBlock::new(2 * f(l), f(l), device))
                .collect(),
            head: Conv2dConfig::new([f(0), 1], [1, 1]).init(device),
        }
    }
}

impl UNet {
    /// Mask logits `[N, 1, H, W]` of images `[N, 3, H, W]`.
    pub fn forward(&self, images: Tensor<4>) -> Tensor<4> {
        let mut skips = Vec::with_capacity(self.down.len());
        let mut x = images;
        for block in &self.down {
            x = block.forward(x);
            skips.push(x.clone());
            x = max_pool2x2(x);
        }
        x = self.bottom.forward(x);
        for ((up, merge), skip) in self.up.iter().zip(&self.merge).zip(skips.into_iter().rev()) {
            x = merge.forward(Tensor::cat(
                alloc::vec![relu(conv_transpose2d_module(up, x)), skip],
                1,
            ));
        }
        conv2d_module(&self.head, x)
    }
}

/// Settings of the FCN-8s baseline (Long et al. 2015) on a small VGG-style encoder.
#[derive(Config, Debug, PartialEq)]
pub struct FcnConfig {
    /// Filters of the first of the five encoder blocks (doubling, at most 8x).
    #[config(default = 16)]
    pub base_filters: usize,
}

/// FCN-8s: class scores at 1/8, 1/16 and 1/32 of the input, fused by upsampling.
#[derive(Module, Debug)]
pub struct Fcn {
    blocks: Vec<ConvBlock>,
    score_8: Conv2d,
    score_16: Conv2d,
    score_32: Conv2d,
}

impl FcnConfig {
    /// The network on `device`.
    pub fn init(&self, device: &Device) -> Fcn {
        let f = |level: usize| self.base_filters << level.min(3);
        Fcn {
            blocks: (0..5)
                .map(|l| ConvBlock::new(if l == 0 { 3 } else { f(l - 1) }, f(l), device))
                .collect(),
            score_8: Conv2dConfig::new([f(2), 1], [1, 1]).init(device),
            score_16: Conv2dConfig::new([f(3), 1], [1, 1]).init(device),
            score_32: Conv2dConfig::new([f(4), 1], [1, 1]).init(device),
        }
    }
}

impl Fcn {
    /// Mask logits `[N, 1, H, W]` of images `[N, 3, H, W]` (H, W divisible by 32).
    pub fn forward(&self, images: Tensor<4>) -> Tensor<4> {
        let [_, _, h, w] = images.dims();
        let mut x = images;
        let mut pooled = Vec::with_capacity(5);
        for block in &self.blocks {
            x = max_pool2x2(block.forward(x));
            pooled.push(x.clone());
        }
        let s32 = conv2d_module(&self.score_32, pooled[4].clone());
        let s16 = conv2d_module(&self.score_16, pooled[3].clone()) + resize(s32, [h / 16, w / 16]);
        let s8 = conv2d_module(&self.score_8, pooled[2].clone()) + resize(s16, [h / 8, w / 8]);
        resize(s8, [h, w])
    }
}

/// Settings of the small HRNet baseline (Wang et al. 2020): three resolutions kept in parallel
/// and exchanged, HRNetV2's concatenated head.
#[derive(Config, Debug, PartialEq)]
pub struct HrNetConfig {
    /// Channels of the highest-resolution branch (1/4 of the input); the others double.
    #[config(default = 16)]
    pub width: usize,
}

/// A residual block of two 3x3 convolutions with batch normalisation.
#[derive(Module, Debug)]
pub struct BasicBlock {
    conv1: Conv2d,
    norm1: BatchNorm,
    conv2: Conv2d,
    norm2: BatchNorm,
}

impl BasicBlock {
    fn new(channels: usize, device: &Device) -> Self {
        Self {
            conv1: conv3x3(channels, channels, device),
            norm1: BatchNormConfig::new(channels).init(device),
            conv2: conv3x3(channels, channels, device),
            norm2: BatchNormConfig::new(channels).init(device),
        }
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let y = relu(self.norm1.forward(conv2d_module(&self.conv1, x.clone())));
        relu(self.norm2.forward(conv2d_module(&self.conv2, y)) + x)
    }
}

/// Small HRNet.
#[derive(Module, Debug)]
pub struct HrNet {
    stem1: Conv2d,
    stem2: Conv2d,
    /// Per branch (1/4, 1/8, 1/16): two residual blocks.
    branches: Vec<Vec<BasicBlock>>,
    /// Strided 3x3 convolutions making the 1/8 and 1/16 branches from the one above.
    transitions: Vec<Conv2d>,
    /// 1x1 convolutions bringing each branch to every other branch's channels, `[to][from]`.
    exchange: Vec<Vec<Conv2d>>,
    head: Conv2d,
    classifier: Conv2d,
}

impl HrNetConfig {
    /// The network on `device`.
    pub fn init(&self, device: &Device) -> HrNet {
        let c = |b: usize| self.width << b;
        let stride2 = |cin, cout| {
            Conv2dConfig::new([cin, cout], [3, 3])
                .with_stride([2, 2])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .init(device)
        };
        HrNet {
            stem1: stride2(3, c(0)),
            stem2: stride2(c(0), c(0)),
            branches: (0..3)
                .map(|b| (0..2).map(|_| BasicBlock::new(c(b), device)).collect())
                .collect(),
            transitions: (1..3).map(|b| stride2(c(b - 1), c(b))).collect(),
            exchange: (0..3)
                .map(|to| {
                    (0..3)
                        .map(|from| Conv2dConfig::new([c(from), c(to)], [1, 1]).init(device))
                        .collect()
                })
                .collect(),
            head: Conv2dConfig::new([c(0) + c(1) + c(2), c(0)], [1, 1]).init(device),
            classifier: Conv2dConfig::new([c(0), 1], [1, 1]).init(device),
        }
    }
}

impl HrNet {
    /// Mask logits `[N, 1, H, W]` of images `[N, 3, H, W]` (H, W divisible by 16).
    pub fn forward(&self, images: Tensor<4>) -> Tensor<4> {
        let [_, _, h, w] = images.dims();
        let x = conv2d_relu_module(&self.stem2, conv2d_relu_module(&self.stem1, images));
        // Build the three branches, run their blocks, then exchange information.
        let mut branches = alloc::vec![x];
        for t in &self.transitions {
            let from = branches.last().expect("a branch").clone();
            branches.push(conv2d_relu_module(t, from));
        }
        let branches: Vec<Tensor<4>> = branches
            .into_iter()
            .zip(&self.branches)
            .map(|(mut x, blocks)| {
                for block in blocks {
                    x = block.forward(x);
                }
                x
            })
            .collect();
        let sizes: Vec<[usize; 2]> = branches
            .iter()
            .map(|b| {
                let [_, _, bh, bw] = b.dims();
                [bh, bw]
            })
            .collect();
        let fused: Vec<Tensor<4>> = (0..3)
            .map(|to| {
                let mut sum: Option<Tensor<4>> = None;
                for (from, branch) in branches.iter().enumerate() {
                    let y = resize(
                        conv2d_module(&self.exchange[to][from], branch.clone()),
                        sizes[to],
                    );
                    sum = Some(match sum {
                        Some(s) => s + y,
                        None => y,
                    });
                }
                relu(sum.expect("three branches"))
            })
            .collect();
        // HRNetV2 head: everything at the highest resolution, concatenated.
        let top = sizes[0];
        let joined = Tensor::cat(fused.into_iter().map(|f| resize(f, top)).collect(), 1);
        let logits = conv2d_module(&self.classifier, conv2d_relu_module(&self.head, joined));
        resize(logits, [h, w])
    }
}

/// Settings of the Y-Net baseline: force from the two views' catheter masks.
#[derive(Config, Debug, PartialEq)]
pub struct YNetConfig {
    /// Filters of the first encoder block (doubling, four blocks).
    #[config(default = 16)]
    pub base_filters: usize,
    /// Units of the two hidden dense layers.
    #[config(default = "[64, 32]")]
    pub hidden: [usize; 2],
}

/// Y-Net: one convolutional encoder per view's mask, pooled features joined, dense regression of
/// the tip force in newtons.
#[derive(Module, Debug)]
pub struct YNet {
    encoder_a: Vec<ConvBlock>,
    encoder_b: Vec<ConvBlock>,
    hidden1: Linear,
    hidden2: Linear,
    output: Linear,
}

impl YNetConfig {
    /// The network on `device`.
    pub fn init(&self, device: &Device) -> YNet {
        let f = |level: usize| self.base_filters << level;
        let encoder = || {
            (0..4)
                .map(|l| ConvBlock::new(if l == 0 { 1 } else { f(l - 1) }, f(l), device))
                .collect()
        };
        YNet {
            encoder_a: encoder(),
            encoder_b: encoder(),
            hidden1: LinearConfig::new(2 * f(3), self.hidden[0]).init(device),
            hidden2: LinearConfig::new(self.hidden[0], self.hidden[1]).init(device),
            output: LinearConfig::new(self.hidden[1], 3).init(device),
        }
    }
}

impl YNet {
    fn encode(encoder: &[ConvBlock], mask: Tensor<4>) -> Tensor<2> {
        let mut x = mask;
        for (i, block) in encoder.iter().enumerate() {
            x = block.forward(x);
            if i + 1 < encoder.len() {
                x = max_pool2x2(x);
            }
        }
        x.mean_dims(&[2, 3]).flatten(1, 3)
    }

    /// Tip force `[N, 3]` (N) from masks `[N, 1, H, W]` of both views.
    pub fn forward(&self, mask_a: Tensor<4>, mask_b: Tensor<4>) -> Tensor<2> {
        let features = Tensor::cat(
            alloc::vec![
                Self::encode(&self.encoder_a, mask_a),
                Self::encode(&self.encoder_b, mask_b)
            ],
            1,
        );
        let x = relu(self.hidden1.forward(features));
        self.output.forward(relu(self.hidden2.forward(x)))
    }
}
