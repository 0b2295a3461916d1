//! Lowering a convolution to a matrix product (im2col) and back (col2im), one image at a time.
//!
//! The lowered input of one image is a `taps x output_plane` row-major matrix: row
//! `(c * kh + i) * kw + j` holds, for every output pixel, the input pixel that kernel tap
//! `(i, j)` of channel `c` reads there, or zero where it reads the padding. With it, the
//! convolution of that image is `weight (out_channels x taps) · lowered`.

use crate::geometry::ConvGeometry;

/// Writes the lowered `input` (one image, `in_channels x input_plane`) into `lowered`
/// (`taps x output_plane`). Every element of `lowered` is written.
pub fn lower(g: &ConvGeometry, input: &[f32], lowered: &mut [f32]) {
    lower_band(g, input, 0..g.height.output, lowered);
}

/// [`lower`] for a band of output rows only: `lowered` is `taps x (rows.len() * output width)`,
/// the columns of those output pixels.
pub fn lower_band(
    g: &ConvGeometry,
    input: &[f32],
    rows: core::ops::Range<usize>,
    lowered: &mut [f32],
) {
    let plane = g.input_plane();
    let (out_w, in_w) = (g.width.output, g.width.input);
    let out_plane = rows.len() * out_w;
    debug_assert_eq!(input.len(), g.in_channels * plane);
    debug_assert_eq!(lowered.len(), g.taps() * out_plane);
    let first_row = rows.start;
    let mut rows = lowered.chunks_exact_mut(out_plane);
    for channel in input.chunks_exact(plane) {
        for i in 0..g.height.kernel {
            for j in 0..g.width.kernel {
                let row = rows.next().expect("one row per tap");
                let inside = g.width.outputs_inside(j);
                for (band_row, line) in row.chunks_exact_mut(out_w).enumerate() {
                    let Some(ih) = g.height.input_index(first_row + band_row, i) else {
                        line.fill(0.0);
                        continue;
                    };
                    let source = &channel[ih * in_w..(ih + 1) * in_w];
                    line[..inside.start].fill(0.0);
                    line[inside.end..].fill(0.0);
                    if inside.is_empty() {
                        continue;
                    }
                    let first = g.width.input_index(inside.start, j).expect("inside");
                    let line = &mut line[inside.clone()];
                    if g.width.stride == 1 {
                        line.copy_from_slice(&source[first..first + line.len()]);
                    } else {
                        let step = g.width.stride;
                        for (k, value) in line.iter_mut().enumerate() {
                            *value = source[first + k * step];
                        }
                    }
                }
            }
        }
    }
}

/// Adds the lowered matrix `lowered` (`taps x output_plane`) back onto the image it was lowered
/// from (`in_channels x input_plane`): the adjoint of [`lower`]. `image` is accumulated into, not
/// overwritten.
pub fn raise_adding(g: &ConvGeometry, lowered: &[f32], image: &mut [f32]) {
    let (plane, out_plane) = (g.input_plane(), g.output_plane());
    let (out_w, in_w) = (g.width.output, g.width.input);
    debug_assert_eq!(image.len(), g.in_channels * plane);
    debug_assert_eq!(lowered.len(), g.taps() * out_plane);
    let mut rows = lowered.chunks_exact(out_plane);
    for channel in image.chunks_exact_mut(plane) {
        for i in 0..g.height.kernel {
            for j in 0..g.width.kernel {
                let row = rows.next().expect("one row per tap");
                let inside = g.width.outputs_inside(j);
                if inside.is_empty() {
                    continue;
                }
                let first = g.width.input_index(inside.start, j).expect("inside");
                for oh in g.height.outputs_inside(i) {
                    let ih = g.height.input_index(oh, i).expect("inside");
                    let target = &mut channel[ih * in_w..(ih + 1) * in_w];
                    let line = &row[oh * out_w..][inside.clone()];
                    if g.width.stride == 1 {
                        let target = &mut target[first..first + line.len()];
                        for (t, v) in target.iter_mut().zip(line) {
                            *t += v;
                        }
                    } else {
                        let step = g.width.stride;
                        for (k, v) in line.iter().enumerate() {
                            target[first + k * step] += v;
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::ConvGeometry;
    use burn::tensor::ops::ConvOptions;

    /// `<lower(x), y> == <x, raise(y)>`: raising is lowering's adjoint, whatever the geometry.
    #[test]
    fn raising_is_the_adjoint_of_lowering() {
        let value = |k: usize| ((k * 7919) % 13) as f32 - 6.0;
        for (shape, kernel, stride, padding) in [
            ([1, 2, 5, 7], [3, 3], [1, 1], [(1, 1), (1, 1)]),
            ([1, 3, 6, 5], [3, 2], [2, 1], [(0, 1), (2, 0)]),
            ([1, 1, 4, 4], [1, 1], [2, 2], [(0, 0), (0, 0)]),
        ] {
            let options = ConvOptions {
                stride,
                padding,
                dilation: [1, 1],
                groups: 1,
            };
            let g = ConvGeometry::of_conv2d(shape, [2, shape[1], kernel[0], kernel[1]], &options)
                .unwrap();
            let x: Vec<f32> = (0..g.in_channels * g.input_plane()).map(value).collect();
            let y: Vec<f32> = (0..g.taps() * g.output_plane())
                .map(|k| value(k + 3))
                .collect();
            let mut lowered = vec![f32::NAN; y.len()];
            lower(&g, &x, &mut lowered);
            let mut raised = vec![0.0; x.len()];
            raise_adding(&g, &y, &mut raised);
            let dot = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(a, b)| a * b).sum::<f32>();
            assert_eq!(dot(&lowered, &y), dot(&x, &raised), "{g:?}");
        }
    }
}
