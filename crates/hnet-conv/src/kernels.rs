//! The three kernels of a convolution on plain `f32` slices (NCHW, row-major), each a matrix
//! product per image over the lowered input (see [`crate::lowering`]):
//!
//! - forward: `y[n] = W · lower(x[n]) + b`, the bias written first and accumulated into;
//! - input gradient: `dx[n] = raise(Wᵀ · dy[n])`;
//! - weight gradient: `dW = Σₙ dy[n] · lower(x[n])ᵀ`, one product of depth `output_plane` per
//!   image accumulated in place, the batch split across threads and the partial sums added.
//!
//! `W` is the OIHW weight seen as an `out_channels x taps` matrix. A pointwise convolution
//! (1x1, stride 1, no padding) skips the lowering: the image is its own lowered matrix. Every
//! other stride-1 convolution (all of H-Net's but the upsampling) computes its forward pass and
//! weight gradient with no lowered matrix at all, straight from the zero-padded image
//! ([`crate::direct`]), and its input gradient as the forward pass of the turned kernel. Those
//! forward passes go by Winograd's F(4x4, 3x3) or F(2x2, 3x3) ([`crate::winograd`]) where one
//! serves the shape (3 x 3, undilated, an output of whole tiles at least one strip wide) and by the
//! direct kernel elsewhere.
//! A strided convolution's input gradient (a transposed convolution's forward pass, H-Net's
//! upsampling) is one direct stride-1 convolution per class of positions
//! ([`crate::geometry::Axis::gradient_phases`]); raise (col2im) is left for dilated axes.
//!
//! The products are [`crate::products`]'. With the `rayon` feature, images run on rayon's
//! workers, one image per task (a single image gives gemm all the threads).

use alloc::vec;
use alloc::vec::Vec;
use core::cell::Cell;
use core::mem::MaybeUninit;

use alloc::sync::Arc;

use crate::direct::{self, PaddedLayout};
use crate::geometry::{AxisPhase, ConvGeometry};
use crate::lowering::{lower, raise_adding};
use crate::prepared::{kind, prepared};
use crate::products::{Lanes, MatrixView, Threads, broadcast_product, gemm_product};
use crate::winograd::{self, WinogradLayout};

std::thread_local! {
    /// Each thread's buffer for a lowered image, kept between calls so that the pages it
    /// touches are not returned to the system and zeroed again for every convolution.
    static LOWERED: Cell<Vec<f32>> = const { Cell::new(Vec::new()) };
}

/// Runs `work` with this thread's lowered-image buffer of `len` elements (contents unspecified).
/// The buffer is taken out of the thread-local for the duration, so nested or stolen work on the
/// same thread gets a buffer of its own instead of a borrow error.
fn with_lowered_buffer<R>(len: usize, work: impl FnOnce(&mut [f32]) -> R) -> R {
    let mut buffer = LOWERED.with(Cell::take);
    // Grown, never shrunk: resizing down and up again between a small and a large layer would
    // zero the difference every time.
    if buffer.len() < len {
        buffer.resize(len, 0.0);
    }
    let result = work(&mut buffer[..len]);
    LOWERED.with(|cell| cell.set(buffer));
    result
}

/// Runs `work` on the lowered matrix of one image `x`: `x` itself for a pointwise convolution,
/// else this thread's buffer holding `lower(x)`.
fn with_lowered_image<R>(g: &ConvGeometry, x: &[f32], work: impl FnOnce(&[f32]) -> R) -> R {
    if g.is_pointwise() {
        return work(x);
    }
    with_lowered_buffer(g.taps() * g.output_plane(), |lowered| {
        lower(g, x, lowered);
        work(lowered)
    })
}

/// Calls `work(n, chunk)` for every image `n` and its chunk of `out` (`out.len() / batch`
/// elements each): in parallel over images with `rayon`.
pub(crate) fn for_each_image<T: Send>(
    batch: usize,
    out: &mut [T],
    work: impl Fn(usize, &mut [T]) + Send + Sync,
) {
    if batch == 0 || out.is_empty() {
        return;
    }
    let per_image = out.len() / batch;
    #[cfg(feature = "rayon")]
    if batch > 1 {
        use rayon::prelude::*;
        out.par_chunks_mut(per_image)
            .enumerate()
            .for_each(|(n, chunk)| work(n, chunk));
        return;
    }
    for (n, chunk) in out.chunks_mut(per_image).enumerate() {
        work(n, chunk);
    }
}

/// The forward convolution: `y[n] = W · lower(x[n]) + b`, NCHW, `[batch, out_channels, output]`,
/// then a ReLU when `relu` (fused into the direct kernels' store).
pub fn forward(
    g: &ConvGeometry,
    x: &[f32],
    weight: &[f32],
    bias: Option<&[f32]>,
    relu: bool,
) -> Vec<f32> {
    let (taps, plane, out_plane) = (g.taps(), g.input_plane(), g.output_plane());
    assert_eq!(x.len(), g.batch * g.in_channels * plane, "input size");
    assert_eq!(weight.len(), g.out_channels * taps, "weight size");
    if let Some(y) = forward_by_winograd(g, x, weight, bias, relu) {
        return y;
    }
    if let Some(layout) = PaddedLayout::of(g) {
        let packed = packed_weight(weight, g.out_channels, taps);
        return forward_direct(g, &layout, x, &packed, bias, relu);
    }
    if relu {
        let mut y = forward(g, x, weight, bias, false);
        y.iter_mut().for_each(|v| *v = Lanes::relu(*v));
        return y;
    }
    let mut y = vec![0.0; g.batch * g.out_channels * out_plane];
    // Output rows lowered (and multiplied) at a time: about BAND_PIXELS pixels, so that the band's
    // lowered matrix stays in cache instead of being written whole and read back.
    let band_rows = (BAND_PIXELS / g.width.output).clamp(1, g.height.output);
    for_each_image(g.batch, &mut y, |n, y| {
        if let Some(bias) = bias {
            for (row, &b) in y.chunks_exact_mut(out_plane).zip(bias) {
                row.fill(b);
            }
        }
        let x = &x[n * g.in_channels * plane..][..g.in_channels * plane];
        if g.is_pointwise() {
            let shape = (g.out_channels, out_plane, taps);
            broadcast_product((y, out_plane), bias.is_some(), shape, weight, (taps, 1), x);
            return;
        }
        for first in (0..g.height.output).step_by(band_rows) {
            let rows = first..(first + band_rows).min(g.height.output);
            let pixels = rows.len() * g.width.output;
            with_lowered_buffer(taps * pixels, |lowered| {
                crate::lowering::lower_band(g, x, rows.clone(), lowered);
                let columns = &mut y[first * g.width.output..];
                let shape = (g.out_channels, pixels, taps);
                broadcast_product(
                    (columns, out_plane),
                    bias.is_some(),
                    shape,
                    weight,
                    (taps, 1),
                    lowered,
                );
            });
        }
    });
    y
}

/// [`direct::pack_weight`], kept for the next call with the same weight ([`prepared`]).
fn packed_weight(weight: &[f32], out_channels: usize, taps: usize) -> Arc<[f32]> {
    prepared(weight, vec![kind::PACKED, out_channels, taps], |weight| {
        direct::pack_weight(weight, out_channels, taps)
    })
}

/// [`ConvGeometry::gathered_weight`], kept for the next call with the same weight
/// ([`prepared`]).
fn gathered_weight(
    g: &ConvGeometry,
    weight: &[f32],
    rows: &[usize],
    columns: &[usize],
) -> Arc<[f32]> {
    let mut recipe = vec![kind::GATHERED];
    recipe.extend(g.weight_shape());
    recipe.push(rows.len());
    recipe.extend(rows.iter().chain(columns));
    prepared(weight, recipe, |weight| {
        g.gathered_weight(weight, rows, columns)
    })
}

/// Output pixels per band of the forward pass (at least one output row).
const BAND_PIXELS: usize = 256;

/// The forward convolution by the direct kernels, with the weight already packed.
fn forward_direct(
    g: &ConvGeometry,
    layout: &PaddedLayout,
    x: &[f32],
    packed_weight: &[f32],
    bias: Option<&[f32]>,
    relu: bool,
) -> Vec<f32> {
    // SAFETY: `direct::forward_image` writes every value of `y`.
    unsafe {
        forward_padded(g, x, layout.len(g.in_channels), |x, padded, y| {
            layout.pad(g, x, padded);
            direct::forward_image(g, layout, padded, packed_weight, bias, relu, y);
        })
    }
}

/// The forward convolution by Winograd's F(4x4, 3x3) or F(2x2, 3x3) ([`winograd`]), the largest
/// tile that serves `g`, when the kernel is switched on ([`crate::use_winograd`]).
fn forward_by_winograd(
    g: &ConvGeometry,
    x: &[f32],
    weight: &[f32],
    bias: Option<&[f32]>,
    relu: bool,
) -> Option<Vec<f32>> {
    if !crate::winograd_enabled() {
        return None;
    }
    let layout = WinogradLayout::of(g, crate::largest_winograd_tile())?;
    let tile = layout.tile();
    let recipe = vec![kind::WINOGRAD, g.out_channels, g.in_channels, tile.side()];
    let transformed = prepared(weight, recipe, |weight| {
        winograd::transform_weight(weight, g.out_channels, g.in_channels, tile)
    });
    // SAFETY: `winograd::forward_image` writes every value of `y`.
    Some(unsafe {
        forward_padded(g, x, layout.len(g.in_channels), |x, window, y| {
            winograd::forward_image(g, &layout, x, window, &transformed, bias, relu, y);
        })
    })
}

/// Runs `image(x, padded, y)` for every image `x` of the batch, with this thread's buffer of
/// `padded_len` values for its padded copy (the direct kernels) or its window of padded rows
/// (Winograd's) and its part `y` of the result.
///
/// # Safety
///
/// `image` writes every value of its `y` (which is not initialised first).
unsafe fn forward_padded(
    g: &ConvGeometry,
    x: &[f32],
    padded_len: usize,
    image: impl Fn(&[f32], &mut [f32], &mut [MaybeUninit<f32>]) + Send + Sync,
) -> Vec<f32> {
    let plane = g.input_plane();
    let len = g.batch * g.out_channels * g.output_plane();
    let mut y = Vec::with_capacity(len);
    for_each_image(g.batch, &mut y.spare_capacity_mut()[..len], |n, y| {
        let x = &x[n * g.in_channels * plane..][..g.in_channels * plane];
        with_lowered_buffer(padded_len, |padded| image(x, padded, y));
    });
    // SAFETY: `image` wrote all `len` values, image by image (the caller's promise).
    unsafe { y.set_len(len) };
    y
}

/// The gradient of the forward convolution's input, `dx[n] = raise(Wᵀ · dy[n])`, NCHW,
/// `[batch, in_channels, input]`, plus `bias[c]` on every pixel of channel `c` when given: also
/// the forward pass of the transposed convolution whose adjoint is `g` (with `dy` its input).
/// Stride 1: the forward pass of the turned kernel; larger strides: one stride-1 convolution per
/// class of positions ([`crate::geometry::Axis::gradient_phases`]); else (dilated axes, classes
/// that would need negative padding) a product and col2im.
pub fn input_gradient(
    g: &ConvGeometry,
    weight: &[f32],
    dy: &[f32],
    bias: Option<&[f32]>,
) -> Vec<f32> {
    let (taps, plane, out_plane) = (g.taps(), g.input_plane(), g.output_plane());
    assert_eq!(
        dy.len(),
        g.batch * g.out_channels * out_plane,
        "output gradient size"
    );
    assert_eq!(weight.len(), g.out_channels * taps, "weight size");
    if let Some(adjoint) = g.input_gradient_as_convolution() {
        let (rows, columns) = g.flipped_taps();
        let flipped = gathered_weight(g, weight, &rows, &columns);
        if let Some(dx) = forward_by_winograd(&adjoint, dy, &flipped, bias, false) {
            return dx;
        }
        if let Some(layout) = PaddedLayout::of(&adjoint) {
            let packed = packed_weight(&flipped, adjoint.out_channels, adjoint.taps());
            return forward_direct(&adjoint, &layout, dy, &packed, bias, false);
        }
    }
    if g.height.stride * g.width.stride > 1
        && let (Some(rows), Some(columns)) = (g.height.gradient_phases(), g.width.gradient_phases())
    {
        return input_gradient_by_phases(g, &rows, &columns, weight, dy, bias);
    }
    let weight_t = MatrixView::row_major(weight, g.out_channels, taps).transposed();
    let mut dx = vec![0.0; g.batch * g.in_channels * plane];
    for_each_image(g.batch, &mut dx, |n, dx| {
        let dy = &dy[n * g.out_channels * out_plane..][..g.out_channels * out_plane];
        let dy = MatrixView::row_major(dy, g.out_channels, out_plane);
        if g.is_pointwise() {
            gemm_product(dx, false, weight_t, dy, threads(g.batch));
        } else {
            with_lowered_buffer(taps * out_plane, |lowered| {
                gemm_product(lowered, false, weight_t, dy, threads(g.batch));
                raise_adding(g, lowered, dx);
            });
        }
    });
    if let Some(bias) = bias {
        add_per_channel(&mut dx, bias, plane);
    }
    dx
}

/// One class of a strided input gradient's positions ([`input_gradient_by_phases`]): its row and
/// column classes and its values, `[batch, in_channels, plane]` with rows `width` apart (the
/// columns past the class's count dropped when written).
struct PhaseValues<'a> {
    row: &'a AxisPhase,
    column: &'a AxisPhase,
    /// Values per channel plane.
    plane: usize,
    /// Values per row of a plane.
    width: usize,
    values: Vec<f32>,
}

impl PhaseValues<'_> {
    /// Image `n`'s planes (`channels` of them).
    fn image(&self, n: usize, channels: usize) -> &[f32] {
        &self.values[n * channels * self.plane..][..channels * self.plane]
    }
}

/// The input gradient of a strided convolution (a transposed convolution's forward pass) class
/// by class of the input positions, its transposed convolution's output positions
/// ([`crate::geometry::Axis::gradient_phases`]): each class of rows and class of columns is a
/// stride-1 convolution of `dy` with the taps that reach it, computed by [`forward`] (the direct
/// kernels, or the pointwise product for a class with one tap and no padding) and written into
/// its positions of `dx`. No lowered matrix, no col2im.
fn input_gradient_by_phases(
    g: &ConvGeometry,
    rows: &[AxisPhase],
    columns: &[AxisPhase],
    weight: &[f32],
    dy: &[f32],
    bias: Option<&[f32]>,
) -> Vec<f32> {
    let (in_h, in_w) = (g.height.input, g.width.input);
    // The bias goes into the classes' stores when they cover every position.
    let covered = rows.iter().chain(columns).all(|class| class.axis.is_some());
    let class_bias = bias.filter(|_| covered);
    let mut classes = Vec::with_capacity(rows.len() * columns.len());
    for row in rows {
        for column in columns {
            let (Some(height), Some(width)) = (row.axis, column.axis) else {
                continue;
            };
            // dy's space onto this class of dx's: the taps that reach it, channels swapped.
            let phase = ConvGeometry {
                batch: g.batch,
                in_channels: g.out_channels,
                out_channels: g.in_channels,
                height,
                width,
            };
            let phase_weight = gathered_weight(g, weight, &row.taps, &column.taps);
            // The scatter below reads `count` rows and columns of each class's planes.
            assert!(height.output >= row.count && width.output >= column.count);
            let values = forward(&phase, dy, &phase_weight, class_bias, false);
            classes.push(PhaseValues {
                row,
                column,
                plane: phase.output_plane(),
                width: width.output,
                values,
            });
        }
    }
    let len = g.batch * g.in_channels * in_h * in_w;
    let mut dx = Vec::with_capacity(len);
    let slots = &mut dx.spare_capacity_mut()[..len];
    // The classes cover every position of dx when each has a tap; else the rest is 0 (plus the
    // bias).
    if !covered {
        slots.fill(MaybeUninit::new(0.0));
    }
    // One class's values of image `n` into its positions of dx, every channel.
    let scatter = |n: usize, class: &PhaseValues, dx: &mut [MaybeUninit<f32>]| {
        let planes = class.image(n, g.in_channels);
        for (dx, values) in dx
            .chunks_exact_mut(in_h * in_w)
            .zip(planes.chunks_exact(class.plane))
        {
            for m in 0..class.row.count {
                let target = &mut dx[(class.row.first + m * g.height.stride) * in_w..][..in_w];
                let source = &values[m * class.width..][..class.column.count];
                for (j, &value) in source.iter().enumerate() {
                    target[class.column.first + j * g.width.stride].write(value);
                }
            }
        }
    };
    // Two classes of one row class, the even and the odd columns of stride 2 (H-Net's
    // upsampling), into their rows of dx at once: whole rows written in order, where scattering
    // each class on its own wrote every other value twice over the same cache lines.
    let interleaves = |even: &PhaseValues, odd: &PhaseValues| {
        core::ptr::eq(even.row, odd.row)
            && g.width.stride == 2
            && (even.column.first, odd.column.first) == (0, 1)
            && (even.column.count, odd.column.count) == (in_w.div_ceil(2), in_w / 2)
    };
    let interleave =
        |n: usize, even: &PhaseValues, odd: &PhaseValues, dx: &mut [MaybeUninit<f32>]| {
            let row = even.row;
            let (even_planes, odd_planes) =
                (even.image(n, g.in_channels), odd.image(n, g.in_channels));
            for (c, dx) in dx.chunks_exact_mut(in_h * in_w).enumerate() {
                let even_plane = &even_planes[c * even.plane..][..even.plane];
                let odd_plane = &odd_planes[c * odd.plane..][..odd.plane];
                for m in 0..row.count {
                    let target = &mut dx[(row.first + m * g.height.stride) * in_w..][..in_w];
                    let evens = &even_plane[m * even.width..][..even.column.count];
                    let odds = &odd_plane[m * odd.width..][..odd.column.count];
                    for (pair, (&e, &o)) in target.chunks_exact_mut(2).zip(evens.iter().zip(odds)) {
                        pair[0].write(e);
                        pair[1].write(o);
                    }
                    if in_w % 2 == 1 {
                        target[in_w - 1].write(evens[in_w / 2]);
                    }
                }
            }
        };
    let write = |n: usize, dx: &mut [MaybeUninit<f32>]| {
        let mut rest = &classes[..];
        while let Some((class, tail)) = rest.split_first() {
            match tail.first() {
                Some(next) if interleaves(class, next) => {
                    interleave(n, class, next, dx);
                    rest = &tail[1..];
                }
                _ => {
                    scatter(n, class, dx);
                    rest = tail;
                }
            }
        }
    };
    for_each_image(g.batch, slots, write);
    // SAFETY: every value is written: the classes partition dx's positions
    // (`Axis::gradient_phases`) and each wrote its positions of every image and channel, or
    // they were all zeroed first.
    unsafe { dx.set_len(len) };
    if let Some(bias) = bias.filter(|_| !covered) {
        add_per_channel(&mut dx, bias, in_h * in_w);
    }
    dx
}

/// The gradient of the weight: `dW = Σₙ dy[n] · lower(x[n])ᵀ`, OIHW.
pub fn weight_gradient(g: &ConvGeometry, x: &[f32], dy: &[f32]) -> Vec<f32> {
    let (taps, plane, out_plane) = (g.taps(), g.input_plane(), g.output_plane());
    assert_eq!(x.len(), g.batch * g.in_channels * plane, "input size");
    assert_eq!(
        dy.len(),
        g.batch * g.out_channels * out_plane,
        "output gradient size"
    );
    let weight_len = g.out_channels * taps;
    // One partial sum per group of consecutive images, each group on its own thread.
    let groups = parallel_groups(g.batch);
    let per_group = g.batch.div_ceil(groups);
    let mut partials = vec![0.0; groups * weight_len];
    // Direct for rows of at least two vectors; narrower rows (H-Net's 4 x 4 bottleneck) would
    // spend their time on the zero-extended row tails, and their lowered matrices are small.
    let layout = PaddedLayout::of(g).filter(|_| g.width.output >= DIRECT_GRADIENT_MIN_WIDTH);
    for_each_image(groups, &mut partials, |group, dw| {
        let images = group * per_group..((group + 1) * per_group).min(g.batch);
        for (i, n) in images.enumerate() {
            let x = &x[n * g.in_channels * plane..][..g.in_channels * plane];
            let dy = &dy[n * g.out_channels * out_plane..][..g.out_channels * out_plane];
            if let Some(layout) = &layout {
                with_lowered_buffer(layout.len(g.in_channels), |padded| {
                    layout.pad(g, x, padded);
                    direct::add_weight_gradient(g, layout, padded, dy, dw);
                });
                continue;
            }
            let dy = MatrixView::row_major(dy, g.out_channels, out_plane);
            with_lowered_image(g, x, |lowered| {
                let lowered_t = MatrixView::row_major(lowered, taps, out_plane).transposed();
                gemm_product(dw, i > 0, dy, lowered_t, threads(groups));
            });
        }
    });
    let (first, rest) = partials.split_at_mut(weight_len);
    for partial in rest.chunks_exact(weight_len) {
        for (sum, p) in first.iter_mut().zip(partial) {
            *sum += p;
        }
    }
    partials.truncate(weight_len);
    partials
}

/// Narrowest output row, pixels, whose weight gradient the direct kernel computes.
const DIRECT_GRADIENT_MIN_WIDTH: usize = 16;

/// The gradient of a bias over NCHW values `dy` with `plane` pixels per channel: each channel's
/// sum over the batch and its pixels.
pub fn channel_sums(dy: &[f32], channels: usize, plane: usize) -> Vec<f32> {
    let mut sums = vec![0.0f32; channels];
    if channels * plane == 0 {
        return sums;
    }
    for image in dy.chunks_exact(channels * plane) {
        for (sum, row) in sums.iter_mut().zip(image.chunks_exact(plane)) {
            // Eight running sums (one vector), so that the compiler may vectorise the loop (a
            // single running sum must be added in order).
            let mut lanes = [0.0f32; 8];
            let chunks = row.chunks_exact(8);
            let tail: f32 = chunks.remainder().iter().sum();
            for chunk in chunks {
                for (lane, value) in lanes.iter_mut().zip(chunk) {
                    *lane += value;
                }
            }
            *sum += lanes.iter().sum::<f32>() + tail;
        }
    }
    sums
}

/// Adds `bias[c]` to every pixel of channel `c` of NCHW values `y` (`plane` pixels per channel).
pub fn add_per_channel(y: &mut [f32], bias: &[f32], plane: usize) {
    if plane == 0 || bias.is_empty() {
        return;
    }
    for (row, b) in y.chunks_exact_mut(plane).zip(bias.iter().cycle()) {
        row.iter_mut().for_each(|v| *v += b);
    }
}

/// The threads one image's product may use: all of them when there is only one image (or
/// group), else one (the images already run in parallel).
fn threads(images: usize) -> Threads {
    if images > 1 {
        Threads::One
    } else {
        Threads::All
    }
}

/// How many groups to split `batch` images into for the weight gradient: one per thread.
fn parallel_groups(batch: usize) -> usize {
    #[cfg(feature = "rayon")]
    let threads = rayon::current_num_threads();
    #[cfg(not(feature = "rayon"))]
    let threads = 1;
    threads.clamp(1, batch.max(1))
}
