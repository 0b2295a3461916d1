//! 2 x 2 max pooling with stride 2, no padding (H-Net's and U-Net's downsampling): each output
//! pixel `(oh, ow)` is the largest of input pixels `(2·oh + i, 2·ow + j)`, `i, j ∈ {0, 1}`; an odd
//! last row or column is dropped. NCHW, f32.
//!
//! Burn 0.22's flex computes every max pooling as a general 3-D one with i64 indices, even for
//! inference; on H-Net at 128 x 128 that was 11 % of the inference time. Here the window is
//! fixed, and the backward pass finds each window's winner again from the input instead of
//! keeping indices.
//!
//! The winner is chosen exactly as Burn's flex chooses it: the window is scanned row by row, a
//! later pixel wins only when it is strictly larger or NaN. So ties go to the first pixel (which
//! decides where the gradient goes) and a NaN anywhere makes the output NaN.

use alloc::vec;
use alloc::vec::Vec;

/// The shape of a pooling: `planes` (batch x channels) input planes of `height x width` pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PoolShape {
    /// Images in the batch.
    pub batch: usize,
    /// Channels per image.
    pub channels: usize,
    /// Input height, pixels.
    pub height: usize,
    /// Input width, pixels.
    pub width: usize,
}

impl PoolShape {
    /// The shape of an NCHW tensor's dimensions.
    pub fn of(dims: [usize; 4]) -> Self {
        let [batch, channels, height, width] = dims;
        Self {
            batch,
            channels,
            height,
            width,
        }
    }

    /// The input's dimensions, NCHW.
    pub fn input_dims(&self) -> [usize; 4] {
        [self.batch, self.channels, self.height, self.width]
    }

    /// The output's dimensions, NCHW: half the height and width, rounded down.
    pub fn output_dims(&self) -> [usize; 4] {
        [self.batch, self.channels, self.height / 2, self.width / 2]
    }

    fn input_plane(&self) -> usize {
        self.height * self.width
    }

    fn output_plane(&self) -> usize {
        (self.height / 2) * (self.width / 2)
    }
}

/// True when `candidate`, met after `best` in the window's scan, takes its place.
#[inline(always)]
fn wins(candidate: f32, best: f32) -> bool {
    candidate > best || candidate.is_nan()
}

/// The winner of the window whose top-left pixel is `top[2·ow]`, `bottom` being the next row:
/// its value and its position in the window (0..4, row-major).
#[inline(always)]
fn winner(top: &[f32], bottom: &[f32], ow: usize) -> (f32, usize) {
    let candidates = [
        top[2 * ow],
        top[2 * ow + 1],
        bottom[2 * ow],
        bottom[2 * ow + 1],
    ];
    let mut best = (candidates[0], 0);
    for (k, &c) in candidates.iter().enumerate().skip(1) {
        if wins(c, best.0) {
            best = (c, k);
        }
    }
    best
}

/// The pooled values of NCHW `x` ([`PoolShape::output_dims`]), plane by plane in parallel.
pub fn max_pool2x2(shape: &PoolShape, x: &[f32]) -> Vec<f32> {
    assert_eq!(
        x.len(),
        shape.batch * shape.channels * shape.input_plane(),
        "max pool: input size"
    );
    let out_w = shape.width / 2;
    let mut y = vec![0.0f32; shape.batch * shape.channels * shape.output_plane()];
    crate::kernels::for_each_image(shape.batch * shape.channels, &mut y, |plane, y| {
        let x = &x[plane * shape.input_plane()..][..shape.input_plane()];
        for (oh, y) in y.chunks_exact_mut(out_w).enumerate() {
            let top = &x[2 * oh * shape.width..][..shape.width];
            let bottom = &x[(2 * oh + 1) * shape.width..][..shape.width];
            for (ow, out) in y.iter_mut().enumerate() {
                *out = winner(top, bottom, ow).0;
            }
        }
    });
    y
}

/// The gradient of the input of [`max_pool2x2`]: each output pixel's gradient `dy` goes to its
/// window's winner in `x` (added to 0, as Burn's flex adds it: a gradient of -0 arrives as 0),
/// every other input pixel gets 0.
pub fn max_pool2x2_backward(shape: &PoolShape, x: &[f32], dy: &[f32]) -> Vec<f32> {
    assert_eq!(
        x.len(),
        shape.batch * shape.channels * shape.input_plane(),
        "max pool: input size"
    );
    assert_eq!(
        dy.len(),
        shape.batch * shape.channels * shape.output_plane(),
        "max pool: gradient size"
    );
    let (out_w, out_plane) = (shape.width / 2, shape.output_plane());
    let mut dx = vec![0.0f32; x.len()];
    let planes = shape.batch * shape.channels;
    if out_plane == 0 {
        return dx;
    }
    crate::kernels::for_each_image(planes, &mut dx, |plane, dx| {
        let x = &x[plane * shape.input_plane()..][..shape.input_plane()];
        let dy = &dy[plane * out_plane..][..out_plane];
        for (oh, dy) in dy.chunks_exact(out_w).enumerate() {
            let top = &x[2 * oh * shape.width..][..shape.width];
            let bottom = &x[(2 * oh + 1) * shape.width..][..shape.width];
            for (ow, &d) in dy.iter().enumerate() {
                let k = winner(top, bottom, ow).1;
                dx[(2 * oh + k / 2) * shape.width + 2 * ow + k % 2] = 0.0 + d;
            }
        }
    });
    dx
}
