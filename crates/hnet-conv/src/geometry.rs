//! The shape of one 2-D convolution as the kernels see it, and which convolutions they cover.
//!
//! Tensors are NCHW (batch, channels, height, width), row-major. A convolution maps an *input*
//! space (`in_channels` planes of `height.input x width.input` pixels) to an *output* space
//! (`out_channels` planes of `height.output x width.output`), with an OIHW weight
//! `[out_channels, in_channels, kernel_h, kernel_w]`.
//!
//! A transposed convolution is described by its adjoint: the ordinary convolution that maps the
//! transposed convolution's *output* back onto its input. Its weight `[in_t, out_t, kh, kw]` is
//! exactly that convolution's OIHW weight, so one geometry and three kernels (forward, input
//! gradient, weight gradient) serve both.

use burn::tensor::ops::{ConvOptions, ConvTransposeOptions};

/// One spatial axis of a convolution, in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Axis {
    /// Length of the input along this axis.
    pub input: usize,
    /// Length of the output along this axis.
    pub output: usize,
    /// Kernel taps along this axis.
    pub kernel: usize,
    /// Step between output positions, in input pixels.
    pub stride: usize,
    /// Zero padding before the first input pixel (the padding after only sets `output`).
    pub padding: usize,
    /// Step between kernel taps, in input pixels.
    pub dilation: usize,
}

impl Axis {
    /// The axis of a convolution with `padding = (before, after)`; `None` when no output fits.
    fn of_convolution(
        input: usize,
        kernel: usize,
        stride: usize,
        (before, after): (usize, usize),
        dilation: usize,
    ) -> Option<Self> {
        let reach = dilation.checked_mul(kernel.checked_sub(1)?)? + 1;
        let padded = input.checked_add(before)?.checked_add(after)?;
        let output = padded.checked_sub(reach)? / stride + 1;
        (input > 0 && stride > 0 && dilation > 0).then_some(Self {
            input,
            output,
            kernel,
            stride,
            padding: before,
            dilation,
        })
    }

    /// The input pixel that output position `out` reads through tap `tap`, when it is inside the
    /// image (not in the padding).
    #[inline]
    pub fn input_index(&self, out: usize, tap: usize) -> Option<usize> {
        (out * self.stride + tap * self.dilation)
            .checked_sub(self.padding)
            .filter(|&i| i < self.input)
    }

    /// The output positions whose tap `tap` reads an input pixel (not padding): a contiguous range.
    #[inline]
    pub fn outputs_inside(&self, tap: usize) -> core::ops::Range<usize> {
        let offset = tap * self.dilation;
        // out * stride + offset >= padding
        let first = self.padding.saturating_sub(offset).div_ceil(self.stride);
        // out * stride + offset - padding <= input - 1
        let last_plus_one = match (self.input - 1 + self.padding).checked_sub(offset) {
            Some(reach) => reach / self.stride + 1,
            None => 0,
        };
        let end = last_plus_one.min(self.output);
        first.min(end)..end
    }
}

/// One class of input positions of a strided axis, `first + stride · m` for `m < count`, and the
/// stride-1 convolution over the output positions that gives the input gradient there: the
/// taps of the original kernel that reach these positions, in the order of their output
/// offset (a polyphase, or sub-pixel, decomposition of the transposed convolution).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AxisPhase {
    /// The class's first input position (below the stride).
    pub first: usize,
    /// Positions in the class.
    pub count: usize,
    /// The stride-1 axis from the output positions onto the class, `None` when no tap reaches
    /// the class (its gradient is zero); its outputs past `count` are not used.
    pub axis: Option<Axis>,
    /// For each tap of `axis`, the original kernel's tap.
    pub taps: alloc::vec::Vec<usize>,
}

impl Axis {
    /// The input positions' classes (one per residue modulo the stride) of an axis with dilation
    /// 1, each with its stride-1 gradient axis; `None` for a dilated axis, or when a class's
    /// taps would need negative padding.
    ///
    /// Input position `i = first + stride · m` receives `dy[o] · w[k]` wherever
    /// `o · stride + k - padding = i`, that is for the taps `k ≡ first + padding (mod stride)`,
    /// at output `o = m + d(k)` with `d(k) = (first + padding - k) / stride`: consecutive offsets,
    /// so a stride-1 convolution of `dy` with those taps (largest `k` first) padded by `-min d`.
    pub fn gradient_phases(&self) -> Option<alloc::vec::Vec<AxisPhase>> {
        if self.dilation != 1 {
            return None;
        }
        let (stride, padding) = (self.stride as i64, self.padding as i64);
        (0..self.stride.min(self.input))
            .map(|first| {
                let count = (self.input - first).div_ceil(self.stride);
                let reach = first as i64 + padding;
                let taps: alloc::vec::Vec<usize> = (0..self.kernel)
                    .rev()
                    .filter(|&k| (reach - k as i64).rem_euclid(stride) == 0)
                    .collect();
                let Some(&last) = taps.first() else {
                    return Some(AxisPhase {
                        first,
                        count,
                        axis: None,
                        taps,
                    });
                };
                let lowest_offset = (reach - last as i64) / stride;
                let before = usize::try_from(-lowest_offset).ok()?;
                let after = (count + taps.len()).saturating_sub(1 + self.output + before);
                let axis = Self::of_convolution(self.output, taps.len(), 1, (before, after), 1)?;
                Some(AxisPhase {
                    first,
                    count,
                    axis: Some(axis),
                    taps,
                })
            })
            .collect()
    }
}

/// A 2-D convolution over a batch, with one group (every output channel sees every input channel).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConvGeometry {
    /// Images in the batch.
    pub batch: usize,
    /// Channels of the input space.
    pub in_channels: usize,
    /// Channels of the output space.
    pub out_channels: usize,
    /// The vertical axis.
    pub height: Axis,
    /// The horizontal axis.
    pub width: Axis,
}

impl ConvGeometry {
    /// The geometry of `conv2d(x, weight, bias, options)` for `x: [n, c, h, w]` and
    /// `weight: [o, c, kh, kw]`, or `None` when the kernels do not cover it (groups, empty
    /// tensors, channels that do not match, no output).
    pub fn of_conv2d(x: [usize; 4], weight: [usize; 4], options: &ConvOptions<2>) -> Option<Self> {
        let [batch, in_channels, h, w] = x;
        let [out_channels, weight_in, kh, kw] = weight;
        if options.groups != 1 || weight_in != in_channels {
            return None;
        }
        Self {
            batch,
            in_channels,
            out_channels,
            height: Axis::of_convolution(
                h,
                kh,
                options.stride[0],
                options.padding[0],
                options.dilation[0],
            )?,
            width: Axis::of_convolution(
                w,
                kw,
                options.stride[1],
                options.padding[1],
                options.dilation[1],
            )?,
        }
        .non_empty()
    }

    /// The adjoint geometry of `conv_transpose2d(x, weight, bias, options)` for `x: [n, c, h, w]`
    /// and `weight: [c, o, kh, kw]`: a convolution from the transposed convolution's output
    /// (`o` channels) back onto `x`'s space (`c` channels). `None` when not covered (groups, an
    /// output padding that is not smaller than the stride, empty tensors).
    pub fn of_conv_transpose2d(
        x: [usize; 4],
        weight: [usize; 4],
        options: &ConvTransposeOptions<2>,
    ) -> Option<Self> {
        let [batch, in_t, h, w] = x;
        let [weight_in, out_t, kh, kw] = weight;
        if options.groups != 1 || weight_in != in_t {
            return None;
        }
        let axis = |input: usize, i: usize, kernel: usize| {
            let (stride, padding, dilation) =
                (options.stride[i], options.padding[i], options.dilation[i]);
            if options.padding_out[i] >= stride.max(dilation) || input == 0 {
                return None;
            }
            // Burn's (and PyTorch's) size of a transposed convolution's output.
            let output = ((input - 1) * stride
                + dilation * kernel.checked_sub(1)?
                + 1
                + options.padding_out[i])
                .checked_sub(2 * padding)?;
            let adjoint =
                Axis::of_convolution(output, kernel, stride, (padding, padding), dilation)?;
            (adjoint.output == input).then_some(adjoint)
        };
        Self {
            batch,
            in_channels: out_t,
            out_channels: in_t,
            height: axis(h, 0, kh)?,
            width: axis(w, 1, kw)?,
        }
        .non_empty()
    }

    fn non_empty(self) -> Option<Self> {
        let sizes = [
            self.batch,
            self.in_channels,
            self.out_channels,
            self.height.kernel,
            self.width.kernel,
            self.height.output,
            self.width.output,
        ];
        sizes.iter().all(|&s| s > 0).then_some(self)
    }

    /// Pixels of one input plane.
    pub fn input_plane(&self) -> usize {
        self.height.input * self.width.input
    }

    /// Pixels of one output plane.
    pub fn output_plane(&self) -> usize {
        self.height.output * self.width.output
    }

    /// Rows of the lowered input (im2col): one per input channel and kernel tap, the columns of
    /// the weight seen as an `out_channels x taps` matrix.
    pub fn taps(&self) -> usize {
        self.in_channels * self.height.kernel * self.width.kernel
    }

    /// True when the lowered input is the input itself (1x1 kernel, stride 1, no padding).
    pub fn is_pointwise(&self) -> bool {
        let plain = |a: &Axis| a.kernel == 1 && a.stride == 1 && a.padding == 0;
        plain(&self.height) && plain(&self.width) && self.output_plane() == self.input_plane()
    }

    /// Shape of the input space, NCHW.
    pub fn input_shape(&self) -> [usize; 4] {
        [
            self.batch,
            self.in_channels,
            self.height.input,
            self.width.input,
        ]
    }

    /// Shape of the output space, NCHW.
    pub fn output_shape(&self) -> [usize; 4] {
        [
            self.batch,
            self.out_channels,
            self.height.output,
            self.width.output,
        ]
    }

    /// For a stride-1 convolution, the convolution whose forward pass is this one's input
    /// gradient: from the output space back onto the input space, with the kernel turned by 180
    /// degrees and its two channel axes swapped ([`Self::flipped_weight`]), padded by
    /// `(kernel - 1) · dilation - padding` before. `None` for other strides, or when this
    /// convolution pads by more than its kernel reaches (the adjoint would need negative
    /// padding).
    pub fn input_gradient_as_convolution(&self) -> Option<Self> {
        let axis = |a: &Axis| {
            let reach = (a.kernel - 1) * a.dilation;
            (a.stride == 1 && a.padding <= reach).then_some(Axis {
                input: a.output,
                output: a.input,
                kernel: a.kernel,
                stride: 1,
                padding: reach - a.padding,
                dilation: a.dilation,
            })
        };
        Some(Self {
            batch: self.batch,
            in_channels: self.out_channels,
            out_channels: self.in_channels,
            height: axis(&self.height)?,
            width: axis(&self.width)?,
        })
    }

    /// This convolution's OIHW weight turned by 180 degrees with its channel axes swapped: the
    /// weight of [`Self::input_gradient_as_convolution`].
    pub fn flipped_weight(&self, weight: &[f32]) -> alloc::vec::Vec<f32> {
        let (rows, columns) = self.flipped_taps();
        self.gathered_weight(weight, &rows, &columns)
    }

    /// The kernel rows and columns of [`Self::flipped_weight`], in its order: both reversed.
    pub fn flipped_taps(&self) -> (alloc::vec::Vec<usize>, alloc::vec::Vec<usize>) {
        (
            (0..self.height.kernel).rev().collect(),
            (0..self.width.kernel).rev().collect(),
        )
    }

    /// The weight of a convolution from this one's output space back onto its input space that
    /// uses kernel rows `rows` and columns `columns` of this one's OIHW `weight`, in that order:
    /// `[in_channels, out_channels, rows.len(), columns.len()]`.
    pub fn gathered_weight(
        &self,
        weight: &[f32],
        rows: &[usize],
        columns: &[usize],
    ) -> alloc::vec::Vec<f32> {
        let (kh, kw) = (self.height.kernel, self.width.kernel);
        debug_assert_eq!(weight.len(), self.out_channels * self.in_channels * kh * kw);
        let mut gathered =
            alloc::vec::Vec::with_capacity(weight.len() / (kh * kw) * rows.len() * columns.len());
        for c in 0..self.in_channels {
            for o in 0..self.out_channels {
                let kernel = &weight[(o * self.in_channels + c) * kh * kw..][..kh * kw];
                for &i in rows {
                    gathered.extend(columns.iter().map(|&j| kernel[i * kw + j]));
                }
            }
        }
        gathered
    }

    /// Shape of the weight, OIHW.
    pub fn weight_shape(&self) -> [usize; 4] {
        [
            self.out_channels,
            self.in_channels,
            self.height.kernel,
            self.width.kernel,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_inside_match_input_index() {
        for input in 1..7 {
            for kernel in 1..4 {
                for stride in 1..4 {
                    for dilation in 1..3 {
                        for before in 0..3 {
                            for after in 0..3 {
                                let Some(axis) = Axis::of_convolution(
                                    input,
                                    kernel,
                                    stride,
                                    (before, after),
                                    dilation,
                                ) else {
                                    continue;
                                };
                                for tap in 0..kernel {
                                    let inside: Vec<usize> = (0..axis.output)
                                        .filter(|&o| axis.input_index(o, tap).is_some())
                                        .collect();
                                    let range: Vec<usize> = axis.outputs_inside(tap).collect();
                                    assert_eq!(inside, range, "{axis:?} tap {tap}");
                                }
                            }
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn h_net_upsampling_is_the_adjoint_of_a_stride_2_convolution() {
        // decoder.up: 3x3, stride 2, padding 1, output padding 1: 8 x 8 -> 16 x 16.
        let options = ConvTransposeOptions::new([2, 2], [1, 1], [1, 1], [1, 1], 1);
        let g = ConvGeometry::of_conv_transpose2d([4, 32, 8, 8], [32, 16, 3, 3], &options)
            .expect("covered");
        assert_eq!(g.input_shape(), [4, 16, 16, 16]);
        assert_eq!(g.output_shape(), [4, 32, 8, 8]);
        assert_eq!(g.weight_shape(), [32, 16, 3, 3]);
        // Its forward pass by classes: even positions take the middle tap, odd ones the two
        // outer taps (the later one first), padded by one after.
        let phases = g
            .height
            .gradient_phases()
            .expect("dilation 1, no negative padding");
        let summary: Vec<_> = phases
            .iter()
            .map(|p| {
                (
                    p.first,
                    p.count,
                    p.taps.clone(),
                    p.axis.map(|a| (a.padding, a.output)),
                )
            })
            .collect();
        assert_eq!(
            summary,
            [
                (0, 8, vec![1], Some((0, 8))),
                (1, 8, vec![2, 0], Some((0, 8)))
            ]
        );
    }
}
