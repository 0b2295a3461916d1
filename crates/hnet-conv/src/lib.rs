//! The project's own convolution kernels for Burn's flex CPU backend (issue #11).
//!
//! Burn 0.22's flex computes a convolution's weight gradient with burn-backend's generic default
//! (one small product per input channel) and its forward pass through an NHWC copy and tiled
//! im2col; on H-Net's layers both are several times slower than PyTorch on the same cores. Here a
//! 2-D convolution and a transposed 2-D convolution are each lowered to one matrix product per
//! image ([`lowering`]), computed by register-blocked products written for these shapes
//! ([`products`]), with the weight gradient as one accumulating product per image ([`kernels`]).
//! Stride-1 convolutions skip the lowering: their forward pass and weight gradient read the
//! zero-padded image directly ([`direct`]). A strided convolution's input gradient (a transposed
//! convolution's forward pass, H-Net's upsampling) is split into one stride-1 convolution per
//! class of the transposed convolution's output positions (even or odd row and column, for
//! stride 2; [`geometry::Axis::gradient_phases`]), which the direct kernels compute. The 2 x 2
//! max pooling between the encoder's blocks has its own kernel too
//! ([`pooling`], [`max_pool2x2`]): flex pools through a general 3-D max pooling with indices.
//! Each thread keeps the weights it prepared (Winograd-transformed, packed, turned) for its next
//! call with the same weight, checked bit for bit against a copy (`prepared.rs`).
//!
//! Model code calls [`conv2d_module`] / [`conv_transpose2d_module`] where it would call a
//! burn-nn module's `forward` (or [`conv2d`] / [`conv_transpose2d`] where it would call Burn's
//! tensor operations): on a
//! flex device (with or without autodiff) covered convolutions go to the project's kernels
//! through a Burn backend extension ([`backend`]); on every other device (wgpu, CUDA, ndarray),
//! and for what the kernels do not cover (groups, non-f32 tensors, an output padding not
//! smaller than the stride), Burn's own operation runs, so the result is never a guess.

extern crate alloc;

pub mod backend;
pub mod conformance;
pub mod direct;
pub mod geometry;
pub mod kernels;
pub mod lowering;
pub mod pooling;
mod prepared;
pub mod products;
pub mod winograd;

use core::sync::atomic::{AtomicBool, Ordering};

use burn::backend::Dispatch;
use burn::nn::PaddingConfig2d;
use burn::nn::conv::{Conv2d, ConvTranspose2d};
use burn::tensor::ops::{ConvOptions, ConvTransposeOptions, MaxPoolOptions};
use burn::tensor::{DType, Device, Tensor, activation, module};

use backend::{ConvBias, ProjectConvBackend};

/// Off only for A/B measurements against Burn's own kernels ([`use_project_kernels`]).
static PROJECT_KERNELS: AtomicBool = AtomicBool::new(true);

/// Off only for A/B measurements of the Winograd kernel against the direct one ([`use_winograd`]).
static WINOGRAD: AtomicBool = AtomicBool::new(true);

/// Off only for A/B measurements of Winograd's F(4x4, 3x3) against F(2x2, 3x3)
/// ([`use_large_winograd_tiles`]).
static LARGE_WINOGRAD_TILES: AtomicBool = AtomicBool::new(true);

/// Whether the project's kernels compute the convolutions Winograd's kernel serves (stride-1,
/// undilated 3 x 3 with an output of whole tiles at least one strip wide,
/// [`winograd::WinogradLayout::of`]) by it ([`winograd`], the default) or directly ([`direct`]),
/// for the whole process: the switch behind `hnet bench --kernels direct`.
pub fn use_winograd(enabled: bool) {
    WINOGRAD.store(enabled, Ordering::Relaxed);
}

/// True unless [`use_winograd`] turned the Winograd kernel off.
pub(crate) fn winograd_enabled() -> bool {
    WINOGRAD.load(Ordering::Relaxed)
}

/// Whether the Winograd kernel uses F(4x4, 3x3) where it serves (the default) or only
/// F(2x2, 3x3), for the whole process: the switch behind `hnet bench --kernels winograd2x2`.
pub fn use_large_winograd_tiles(enabled: bool) {
    LARGE_WINOGRAD_TILES.store(enabled, Ordering::Relaxed);
}

/// The largest Winograd tile [`use_large_winograd_tiles`] allows.
pub(crate) fn largest_winograd_tile() -> winograd::Tile {
    if LARGE_WINOGRAD_TILES.load(Ordering::Relaxed) {
        winograd::Tile::Four
    } else {
        winograd::Tile::Two
    }
}

/// Whether flex convolutions use the project's kernels (the default) or Burn's own, for the whole
/// process: the switch behind `hnet bench --kernels burn`.
pub fn use_project_kernels(enabled: bool) {
    PROJECT_KERNELS.store(enabled, Ordering::Relaxed);
}

/// True when tensors on `device` of `dtype` go to the project's kernels: flex, with or without
/// autodiff (autodiff only when this crate was built with its `autodiff` feature), and f32.
pub fn runs_on_project_kernels(device: &Device, dtype: DType) -> bool {
    use burn::backend::DispatchDevice;
    if !PROJECT_KERNELS.load(Ordering::Relaxed)
        || dtype != DType::F32
        || (device.is_autodiff() && !cfg!(feature = "autodiff"))
    {
        return false;
    }
    matches!(
        device.clone().inner().as_dispatch(),
        DispatchDevice::Flex(_)
    )
}

fn bias_of(bias: Option<Tensor<1>>) -> ConvBias<Dispatch> {
    match bias {
        Some(bias) => ConvBias::With(bias.into_dispatch()),
        None => ConvBias::Without,
    }
}

/// Burn's `module::conv2d(x, weight, bias, options)`, computed by the project's kernels on flex.
pub fn conv2d(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: ConvOptions<2>,
) -> Tensor<4> {
    conv2d_then(x, weight, bias, options, false)
}

/// `relu(module::conv2d(x, weight, bias, options))`; on flex the ReLU is fused into the project's
/// kernels (one pass over the result less, forward and backward).
pub fn conv2d_relu(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: ConvOptions<2>,
) -> Tensor<4> {
    conv2d_then(x, weight, bias, options, true)
}

/// [`conv2d`], then a ReLU when `relu`.
fn conv2d_then(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: ConvOptions<2>,
    relu: bool,
) -> Tensor<4> {
    if !runs_on_project_kernels(&x.device(), x.dtype()) {
        let y = module::conv2d(x, weight, bias, options);
        return if relu { activation::relu(y) } else { y };
    }
    Tensor::from_dispatch(<Dispatch as ProjectConvBackend>::project_conv2d(
        x.into_dispatch(),
        weight.into_dispatch(),
        bias_of(bias),
        options,
        relu,
    ))
}

/// Burn's `module::conv_transpose2d(x, weight, bias, options)`, computed by the project's kernels
/// on flex.
pub fn conv_transpose2d(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: ConvTransposeOptions<2>,
) -> Tensor<4> {
    if !runs_on_project_kernels(&x.device(), x.dtype()) {
        return module::conv_transpose2d(x, weight, bias, options);
    }
    Tensor::from_dispatch(<Dispatch as ProjectConvBackend>::project_conv_transpose2d(
        x.into_dispatch(),
        weight.into_dispatch(),
        bias_of(bias),
        options,
    ))
}

/// Burn's `module::max_pool2d(x, MaxPoolOptions::new([2, 2]))` (2 x 2 windows, stride 2, no
/// padding), computed by the project's kernel on flex ([`pooling`]).
pub fn max_pool2x2(x: Tensor<4>) -> Tensor<4> {
    if !runs_on_project_kernels(&x.device(), x.dtype()) {
        return module::max_pool2d(x, MaxPoolOptions::new([2, 2]));
    }
    Tensor::from_dispatch(<Dispatch as ProjectConvBackend>::project_max_pool2x2(
        x.into_dispatch(),
    ))
}

/// `(before, after)` padding of one axis under burn-nn's `PaddingConfig2d::Same`: the output has
/// `ceil(input / stride)` pixels, the extra pixel of an odd total padding after. (burn-nn keeps
/// its own formula private; `tests/against_burn.rs` checks that this one gives its results.)
fn same_padding(kernel: usize, stride: usize, input: usize) -> (usize, usize) {
    let output = input.div_ceil(stride);
    let total = (output.saturating_sub(1) * stride + kernel).saturating_sub(input);
    (total / 2, total - total / 2)
}

/// `conv.forward(x)` for a burn-nn `Conv2d`, computed by the project's kernels on flex.
pub fn conv2d_module(conv: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    let (weight, bias, options) = module_operands(conv, &x);
    conv2d(x, weight, bias, options)
}

/// `relu(conv.forward(x))` for a burn-nn `Conv2d`, the ReLU fused into the project's kernels on
/// flex ([`conv2d_relu`]).
pub fn conv2d_relu_module(conv: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    let (weight, bias, options) = module_operands(conv, &x);
    conv2d_relu(x, weight, bias, options)
}

/// A burn-nn `Conv2d`'s weight, bias and options for input `x`.
fn module_operands(conv: &Conv2d, x: &Tensor<4>) -> (Tensor<4>, Option<Tensor<1>>, ConvOptions<2>) {
    let [_, _, height, width] = x.dims();
    let padding = match conv.padding {
        PaddingConfig2d::Valid => [(0, 0), (0, 0)],
        PaddingConfig2d::Same => [
            same_padding(conv.kernel_size[0], conv.stride[0], height),
            same_padding(conv.kernel_size[1], conv.stride[1], width),
        ],
        PaddingConfig2d::Explicit(top, left, bottom, right) => [(top, bottom), (left, right)],
    };
    let options = ConvOptions::new_with_padding(conv.stride, padding, conv.dilation, conv.groups);
    (
        conv.weight.val(),
        conv.bias.as_ref().map(|b| b.val()),
        options,
    )
}

/// `conv.forward(x)` for a burn-nn `ConvTranspose2d`, computed by the project's kernels on flex.
pub fn conv_transpose2d_module(conv: &ConvTranspose2d, x: Tensor<4>) -> Tensor<4> {
    let options = ConvTransposeOptions::new(
        conv.stride,
        conv.padding,
        conv.padding_out,
        conv.dilation,
        conv.groups,
    );
    conv_transpose2d(
        x,
        conv.weight.val(),
        conv.bias.as_ref().map(|b| b.val()),
        options,
    )
}
