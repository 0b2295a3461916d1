//! Stride-1 convolutions computed straight from the zero-padded image (a *direct*, or
//! implicit-GEMM, convolution): no lowered matrix is written and read back.
//!
//! Each image is first copied into a buffer that makes its zero padding explicit
//! ([`PaddedLayout`]): `in_channels` planes of `rows x row` pixels, where `row`, the padded row
//! length, is `output width + (kernel width - 1) · dilation`. With a stride of one, the pixel
//! that tap `(i, j)` reads for output pixel `(oh, ow)` lies at offset
//! `oh · row + ow + tap_offset(i, j)` of its channel's plane, with
//! `tap_offset(i, j) = i · dilation_h · row + j · dilation_w`: consecutive output pixels of a row
//! read consecutive addresses. So
//!
//! - the forward pass computes its outputs over the flat position `p = oh · row + ow`, loading
//!   vectors of consecutive positions straight from the padded planes; the `row - output width`
//!   positions per row past the output's right edge are computed and dropped (2 of 66 on a
//!   64-pixel row with a 3x3 kernel);
//! - the weight gradient sums `dy[o](oh, ow) · padded[c](oh · row + ow + tap_offset)` over the
//!   output pixels, row by row (it must not see the dropped positions).
//!
//! Both keep a tile of accumulators in registers over the whole reduction: up to
//! [`FORWARD_ROWS`] output channels by 2 vectors of positions (forward, [`forward_blocks`]), 3
//! output channels by 3 taps (weight gradient).

use alloc::vec::Vec;
use core::mem::MaybeUninit;

use crate::geometry::ConvGeometry;
use crate::products::Lanes;

/// Output channels per register tile of the weight gradient: 3 channels by 3 taps keep nine
/// accumulators, three loaded input vectors and one output-gradient vector in registers (4 x 3
/// would need all sixteen on x86-64, and the compiler then spills).
const R: usize = 3;

/// Most output channels per register tile of the forward pass: natively, 6 channels by 2 vectors
/// keep twelve accumulators (enough to hide the FMA latency) and leave registers for the loads (on
/// x86-64, 4 x 3 would need all sixteen, and the compiler then spills). In WebAssembly, 5: the
/// browser's compiler keeps one of the sixteen vector registers for itself, and 5 x 2 measured
/// about 10 % faster in Chromium than 6 x 2 (4 x 2 the same as 5 x 2; docs/benchmarks.md).
pub(crate) const FORWARD_ROWS: usize = if cfg!(target_arch = "wasm32") { 5 } else { 6 };

/// The forward pass's blocks of output channels, `(first channel, channels)`: as few as tiles of
/// at most [`FORWARD_ROWS`] allow, and as even as possible, so that no tile computes channels
/// that do not exist (natively, 32 channels: 6, 6, 5, 5, 5, 5, where six tiles of 6 would compute
/// 36).
pub fn forward_blocks(out_channels: usize) -> impl Iterator<Item = (usize, usize)> {
    let blocks = out_channels.div_ceil(FORWARD_ROWS);
    let (base, extra) = (out_channels / blocks.max(1), out_channels % blocks.max(1));
    (0..blocks).map(move |b| (b * base + b.min(extra), base + usize::from(b < extra)))
}

/// `$call` with the const `$rows` bound to `$channels`, a block's height from [`forward_blocks`]
/// (1 to [`FORWARD_ROWS`]): each height is its own compiled register tile.
macro_rules! with_block_rows {
    ($channels:expr, $rows:ident => $call:expr) => {{
        const { assert!(crate::direct::FORWARD_ROWS <= 6, "tiles of 1 to 6 channels") };
        match $channels {
            6 => {
                const $rows: usize = 6;
                $call
            }
            5 => {
                const $rows: usize = 5;
                $call
            }
            4 => {
                const $rows: usize = 4;
                $call
            }
            3 => {
                const $rows: usize = 3;
                $call
            }
            2 => {
                const $rows: usize = 2;
                $call
            }
            1 => {
                const $rows: usize = 1;
                $call
            }
            _ => unreachable!("blocks hold 1 to {} channels", crate::direct::FORWARD_ROWS),
        }
    }};
}
pub(crate) use with_block_rows;

/// Positions the buffer holds past the last plane, so that the forward pass's last strip may
/// read whole vectors (at least the widest strip, `V · WIDTH`).
const SLACK: usize = 64;

/// Output pixels per band of the weight gradient: its `dy` rows (4 channels) stay in L1 while
/// every input channel and tap passes over them.
const BAND_PIXELS: usize = 512;

/// Where a stride-1 convolution's zero-padded image lies in its buffer.
#[derive(Debug, Clone)]
pub struct PaddedLayout {
    /// Padded row length, pixels.
    row: usize,
    /// Rows of a padded plane.
    rows: usize,
    /// Offset of each kernel tap (row-major over the kernel) from its output position.
    tap_offsets: Vec<usize>,
    /// Flat positions the forward pass computes: `(output height - 1) · row + output width`.
    positions: usize,
}

impl PaddedLayout {
    /// The layout of `g`, or `None` when the direct kernels do not serve it: a stride other than
    /// one, or a pointwise convolution (which needs no padding and no taps).
    pub fn of(g: &ConvGeometry) -> Option<Self> {
        if g.height.stride != 1 || g.width.stride != 1 || g.is_pointwise() {
            return None;
        }
        let (h, w) = (&g.height, &g.width);
        let row = w.output + (w.kernel - 1) * w.dilation;
        let rows = h.output + (h.kernel - 1) * h.dilation;
        let tap_offsets = (0..h.kernel)
            .flat_map(|i| (0..w.kernel).map(move |j| i * h.dilation * row + j * w.dilation))
            .collect();
        Some(Self {
            row,
            rows,
            tap_offsets,
            positions: (h.output - 1) * row + w.output,
        })
    }

    /// Pixels of one padded plane.
    fn plane(&self) -> usize {
        self.rows * self.row
    }

    /// Length of the buffer for one image of `channels` channels.
    pub fn len(&self, channels: usize) -> usize {
        channels * self.plane() + SLACK
    }

    /// Writes image `image` (`in_channels` planes of the input) into `buffer`
    /// ([`Self::len`] long) with its padding made explicit. Every element is written.
    pub fn pad(&self, g: &ConvGeometry, image: &[f32], buffer: &mut [f32]) {
        let (in_h, in_w) = (g.height.input, g.width.input);
        debug_assert_eq!(image.len(), g.in_channels * in_h * in_w);
        debug_assert_eq!(buffer.len(), self.len(g.in_channels));
        // Input pixels the convolution reads: those inside the padded plane.
        let columns = in_w.min(self.row.saturating_sub(g.width.padding));
        let image_rows = in_h.min(self.rows.saturating_sub(g.height.padding));
        let (planes, slack) = buffer.split_at_mut(g.in_channels * self.plane());
        slack.fill(0.0);
        for (channel, plane) in image
            .chunks_exact(in_h * in_w)
            .zip(planes.chunks_exact_mut(self.plane()))
        {
            // Only the padding is zeroed: the image's pixels are written once.
            let (top, rest) = plane.split_at_mut(g.height.padding.min(self.rows) * self.row);
            top.fill(0.0);
            let (middle, bottom) = rest.split_at_mut(image_rows * self.row);
            bottom.fill(0.0);
            for (line, source) in middle
                .chunks_exact_mut(self.row)
                .zip(channel.chunks_exact(in_w))
            {
                let (left, rest) = line.split_at_mut(g.width.padding.min(self.row));
                left.fill(0.0);
                let (pixels, right) = rest.split_at_mut(columns);
                pixels.copy_from_slice(&source[..columns]);
                right.fill(0.0);
            }
        }
    }
}

/// The OIHW weight (`out_channels x taps` row-major) packed for the forward micro-kernel: per
/// block of [`forward_blocks`], its channels' values for each tap in turn (`taps x channels`).
pub fn pack_weight(weight: &[f32], out_channels: usize, taps: usize) -> Vec<f32> {
    debug_assert_eq!(weight.len(), out_channels * taps);
    let mut packed = Vec::with_capacity(out_channels * taps);
    for (first, channels) in forward_blocks(out_channels) {
        for tap in 0..taps {
            packed.extend((first..first + channels).map(|o| weight[o * taps + tap]));
        }
    }
    packed
}

/// One image's forward convolution `y = W · x (+ b)`, NCHW, followed by a ReLU when `relu`, from
/// its padded buffer `padded` ([`PaddedLayout::pad`]) and the weight packed by [`pack_weight`].
/// Every element of `y` (`out_channels x output plane`) is written (it need not be initialised).
pub fn forward_image(
    g: &ConvGeometry,
    layout: &PaddedLayout,
    padded: &[f32],
    packed_weight: &[f32],
    bias: Option<&[f32]>,
    relu: bool,
    y: &mut [MaybeUninit<f32>],
) {
    assert!(
        padded.len() >= layout.len(g.in_channels)
            && packed_weight.len() == g.out_channels * g.taps()
            && y.len() == g.out_channels * g.output_plane()
            && bias.is_none_or(|b| b.len() == g.out_channels),
        "direct forward: buffer sizes"
    );
    #[cfg(target_arch = "x86_64")]
    if crate::products::has_avx512() {
        // SAFETY: this CPU has AVX-512F, AVX2 and FMA (checked just above).
        unsafe { forward_avx512(g, layout, padded, packed_weight, bias, relu, y) };
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if crate::products::has_avx2() {
        // SAFETY: this CPU has AVX2 and FMA (checked just above).
        unsafe { forward_avx2(g, layout, padded, packed_weight, bias, relu, y) };
        return;
    }
    #[cfg(all(target_arch = "wasm32", feature = "relaxed-simd"))]
    return forward_fused(g, layout, padded, packed_weight, bias, relu, y);
    #[cfg(all(target_arch = "wasm32", not(feature = "relaxed-simd")))]
    return forward_body::<crate::products::simd128::Simd128, 2>(
        g,
        layout,
        padded,
        packed_weight,
        bias,
        relu,
        y,
    );
    #[allow(unreachable_code)]
    forward_body::<f32, 8>(g, layout, padded, packed_weight, bias, relu, y)
}

/// `$name`: [`forward_body`] over `$vectors` vectors of lanes `$lanes`, compiled with
/// `$features` (only callable where the CPU or module has them).
macro_rules! forward_compiled_for {
    ($(#[$attr:meta])* $name:ident, $lanes:path, $vectors:literal, $features:literal) => {
        $(#[$attr])*
        #[target_feature(enable = $features)]
        fn $name(
            g: &ConvGeometry,
            layout: &PaddedLayout,
            padded: &[f32],
            packed_weight: &[f32],
            bias: Option<&[f32]>,
            relu: bool,
            y: &mut [MaybeUninit<f32>],
        ) {
            forward_body::<$lanes, $vectors>(g, layout, padded, packed_weight, bias, relu, y)
        }
    };
}

forward_compiled_for!(
    /// Up to 6 channels x 2 vectors of 8: twelve accumulators, two loaded vectors and a
    /// broadcast.
    #[cfg(target_arch = "x86_64")]
    forward_avx2,
    crate::products::avx2::Avx2,
    2,
    "avx2,fma"
);

forward_compiled_for!(
    /// Up to 6 channels x 1 vector of 16: the strip AVX2 takes in two vectors, in half the
    /// multiply-adds.
    #[cfg(target_arch = "x86_64")]
    forward_avx512,
    crate::products::avx512::Avx512,
    1,
    "avx512f,avx2,fma"
);

forward_compiled_for!(
    /// With relaxed SIMD's fused multiply-adds (the crate's `relaxed-simd` feature).
    #[cfg(all(target_arch = "wasm32", feature = "relaxed-simd"))]
    forward_fused,
    crate::products::simd128::FusedSimd128,
    2,
    "simd128,relaxed-simd"
);

/// The body of [`forward_image`]: strips of `V · WIDTH` flat positions, each multiplied by every
/// block of output channels ([`forward_blocks`]) while it is in cache.
#[inline(always)]
fn forward_body<L: Lanes, const V: usize>(
    g: &ConvGeometry,
    layout: &PaddedLayout,
    padded: &[f32],
    packed_weight: &[f32],
    bias: Option<&[f32]>,
    relu: bool,
    y: &mut [MaybeUninit<f32>],
) {
    let strip = V * L::WIDTH;
    debug_assert!(strip <= SLACK);
    let (plane, row) = (layout.plane(), layout.row);
    let (out_w, out_plane) = (g.width.output, g.output_plane());
    let taps = g.taps();
    let mut tile = [[0.0f32; SLACK]; FORWARD_ROWS];
    // Offset of every (input channel, tap), in the order of the packed weight's steps.
    let offsets: Vec<usize> = (0..g.in_channels)
        .flat_map(|channel| layout.tap_offsets.iter().map(move |t| channel * plane + t))
        .collect();
    // (tile offset, output offset, length) of each run of a strip's positions that are output
    // pixels.
    let mut runs: Vec<(usize, usize, usize)> = Vec::new();
    for p0 in (0..layout.positions).step_by(strip) {
        let end = (p0 + strip).min(layout.positions);
        runs.clear();
        let mut p = p0;
        while p < end {
            let (oh, ow) = (p / row, p % row);
            if ow < out_w {
                let len = (out_w - ow).min(end - p);
                runs.push((p - p0, oh * out_w + ow, len));
                p += len;
            } else {
                p += row - ow;
            }
        }
        prefetch_next_strip(layout, g, p0 + strip, padded);
        let at = Strip {
            p0,
            runs: &runs,
            offsets: &offsets,
            padded,
            out_plane,
        };
        let mut rest = packed_weight;
        for (first, channels) in forward_blocks(g.out_channels) {
            let (panel, later) = rest.split_at(taps * channels);
            rest = later;
            let out = Outputs {
                first,
                bias,
                relu,
                y: &mut *y,
                tile: &mut tile,
            };
            with_block_rows!(channels, R => at.multiply::<L, V, R>(panel, out));
        }
    }
}

/// One strip of the forward pass: `V · WIDTH` flat positions from `p0`, and where they go.
struct Strip<'a> {
    p0: usize,
    /// (tile offset, output offset, length) of each run of the strip's positions that are output
    /// pixels.
    runs: &'a [(usize, usize, usize)],
    /// Offset of every (input channel, tap), in the order of the packed weight's steps.
    offsets: &'a [usize],
    padded: &'a [f32],
    out_plane: usize,
}

/// Where one block's results are stored: channels `first ..`, plus their bias, then a ReLU.
struct Outputs<'a> {
    first: usize,
    bias: Option<&'a [f32]>,
    relu: bool,
    y: &'a mut [MaybeUninit<f32>],
    /// Scratch for a strip that spans output rows.
    tile: &'a mut [[f32; SLACK]; FORWARD_ROWS],
}

impl Strip<'_> {
    /// The strip times `R` output channels' panel (`taps x R`, [`pack_weight`]), stored.
    #[inline(always)]
    fn multiply<L: Lanes, const V: usize, const R: usize>(&self, panel: &[f32], out: Outputs) {
        let strip = V * L::WIDTH;
        // Every channel of the block is stored (`tile` holds FORWARD_ROWS), so every value of
        // `y` is written, as `forward_image` promises.
        assert!(R <= FORWARD_ROWS && panel.len() == R * self.offsets.len());
        debug_assert!(
            self.offsets
                .last()
                .is_none_or(|&last| self.p0 + last + strip <= self.padded.len())
        );
        let mut acc = [[L::zero(); V]; R];
        // One loop over every (input channel, tap): a single level of loop-carried accumulators,
        // which the register allocator keeps in registers.
        for (&offset, a) in self.offsets.iter().zip(panel.chunks_exact(R)) {
            // SAFETY: positions `p0 .. p0 + strip` plus an offset stay below
            // `(channel + 1) · plane + SLACK` (`positions + max tap offset = plane`, and
            // `strip <= SLACK`), inside `padded` (checked in `forward_image`).
            unsafe {
                let pb = self.padded.as_ptr().add(self.p0 + offset);
                let bv: [L; V] = L::load_vectors(pb);
                for r in 0..R {
                    let a = L::splat(a[r]);
                    for v in 0..V {
                        acc[r][v] = acc[r][v].multiply_add(a, bv[v]);
                    }
                }
            }
        }
        let Outputs {
            first,
            bias,
            relu,
            y,
            tile,
        } = out;
        let out_plane = self.out_plane;
        if let [(0, o, len)] = self.runs[..]
            && len == strip
        {
            // The strip lies inside one output row: stored straight from the registers.
            for (r, acc) in acc.iter().enumerate() {
                let b = L::splat(bias.map_or(0.0, |bias| bias[first + r]));
                let out = &mut y[(first + r) * out_plane + o..][..strip];
                for (v, value) in acc.iter().enumerate() {
                    let value = value.multiply_add(b, L::splat(1.0));
                    let value = if relu { value.relu() } else { value };
                    // SAFETY: `out` holds `strip = V · WIDTH` values.
                    unsafe { value.store(out.as_mut_ptr().cast::<f32>().add(v * L::WIDTH)) };
                }
            }
            return;
        }
        for (r, (acc, tile)) in acc.iter().zip(tile.iter_mut()).enumerate() {
            for (v, value) in acc.iter().enumerate() {
                // SAFETY: `tile` holds SLACK >= V · WIDTH values.
                unsafe { value.store(tile.as_mut_ptr().add(v * L::WIDTH)) };
            }
            let out = &mut y[(first + r) * out_plane..][..out_plane];
            let b = bias.map_or(0.0, |bias| bias[first + r]);
            for &(t, o, len) in self.runs {
                for (out, value) in out[o..o + len].iter_mut().zip(&tile[t..t + len]) {
                    let value = value + b;
                    out.write(if relu { Lanes::relu(value) } else { value });
                }
            }
        }
    }
}

/// Asks the CPU to fetch the cache lines the strip at `p0` reads, while the current strip is
/// multiplied: each of its (channel, kernel row) streams starts a line apart from the last
/// strip's, more streams than the hardware prefetcher follows when there are many channels.
#[inline(always)]
fn prefetch_next_strip(layout: &PaddedLayout, g: &ConvGeometry, p0: usize, padded: &[f32]) {
    #[cfg(target_arch = "x86_64")]
    {
        use core::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        if p0 >= layout.positions {
            return;
        }
        for channel in 0..g.in_channels {
            for i in 0..g.height.kernel {
                let at = channel * layout.plane() + layout.tap_offsets[i * g.width.kernel] + p0;
                // SAFETY: a prefetch reads nothing and cannot fault; the address is inside
                // `padded` (a strip's first position plus a tap offset).
                unsafe { _mm_prefetch::<_MM_HINT_T0>(padded.as_ptr().add(at).cast()) };
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (layout, g, p0, padded);
}

/// Adds one image's weight gradient `Σ dy[o](oh, ow) · x[c](oh + i, ow + j)` to `dw`
/// (OIHW, `out_channels x taps`), from its padded buffer `padded` ([`PaddedLayout::pad`]) and
/// its output gradient `dy` (`out_channels x output plane`).
pub fn add_weight_gradient(
    g: &ConvGeometry,
    layout: &PaddedLayout,
    padded: &[f32],
    dy: &[f32],
    dw: &mut [f32],
) {
    assert!(
        padded.len() >= layout.len(g.in_channels)
            && dy.len() == g.out_channels * g.output_plane()
            && dw.len() == g.out_channels * g.taps(),
        "direct weight gradient: buffer sizes"
    );
    #[cfg(target_arch = "x86_64")]
    if crate::products::has_avx2() {
        // SAFETY: this CPU has AVX2 and FMA (checked just above).
        unsafe { weight_gradient_avx2(g, layout, padded, dy, dw) };
        return;
    }
    #[cfg(target_arch = "wasm32")]
    return weight_gradient_body::<crate::products::simd128::Simd128>(g, layout, padded, dy, dw);
    #[allow(unreachable_code)]
    weight_gradient_body::<f32>(g, layout, padded, dy, dw)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn weight_gradient_avx2(
    g: &ConvGeometry,
    layout: &PaddedLayout,
    padded: &[f32],
    dy: &[f32],
    dw: &mut [f32],
) {
    weight_gradient_body::<crate::products::avx2::Avx2>(g, layout, padded, dy, dw)
}

/// The body of [`add_weight_gradient`]: per band of output rows, block of [`R`] output channels,
/// input channel and group of `J` taps, `R x J` vector accumulators run along the band's rows.
#[inline(always)]
fn weight_gradient_body<L: Lanes>(
    g: &ConvGeometry,
    layout: &PaddedLayout,
    padded: &[f32],
    dy: &[f32],
    dw: &mut [f32],
) {
    const J: usize = 3;
    let (plane, row) = (layout.plane(), layout.row);
    let (out_h, out_w, out_plane) = (g.height.output, g.width.output, g.output_plane());
    let taps_per_channel = layout.tap_offsets.len();
    let taps = g.taps();
    let whole = out_w - out_w % L::WIDTH;
    let band_rows = (BAND_PIXELS / out_w).clamp(1, out_h);
    for first in (0..out_h).step_by(band_rows) {
        let rows = first..(first + band_rows).min(out_h);
        for block in 0..g.out_channels.div_ceil(R) {
            let channels = R.min(g.out_channels - block * R);
            // Absent channels of the last block repeat its last one; their sums are dropped.
            let dy_planes: [usize; R] =
                core::array::from_fn(|r| (block * R + r.min(channels - 1)) * out_plane);
            for channel in 0..g.in_channels {
                for t0 in (0..taps_per_channel).step_by(J) {
                    let group = J.min(taps_per_channel - t0);
                    let offsets: [usize; J] = core::array::from_fn(|jj| {
                        channel * plane + layout.tap_offsets[t0 + jj.min(group - 1)]
                    });
                    let mut acc = [[L::zero(); J]; R];
                    for oh in rows.clone() {
                        let (dy_row, x_row) = (oh * out_w, oh * row);
                        for ow in (0..whole).step_by(L::WIDTH) {
                            // SAFETY: `x_row + offset + ow + WIDTH <= (channel + 1) · plane`
                            // (the last output pixel's last tap is its plane's last pixel) and
                            // `dy_plane + dy_row + ow + WIDTH <= dy.len()`, both checked in
                            // `add_weight_gradient`.
                            unsafe {
                                // A loop, not `array::from_fn` (see `Lanes::load_vectors`).
                                let mut xv = [L::zero(); J];
                                for (x, offset) in xv.iter_mut().zip(offsets) {
                                    *x = L::load(padded.as_ptr().add(offset + x_row + ow));
                                }
                                for (acc, &dy_plane) in acc.iter_mut().zip(&dy_planes) {
                                    let d = L::load(dy.as_ptr().add(dy_plane + dy_row + ow));
                                    for (acc, x) in acc.iter_mut().zip(xv) {
                                        *acc = acc.multiply_add(d, x);
                                    }
                                }
                            }
                        }
                        if whole < out_w {
                            // The row's last pixels, zero-extended to one vector each (both
                            // operands, so that nothing outside the row enters the sum).
                            let tail = out_w - whole;
                            let mut xs = [[0.0f32; SLACK]; J];
                            for (xs, &offset) in xs.iter_mut().zip(&offsets) {
                                let from = offset + x_row + whole;
                                xs[..tail].copy_from_slice(&padded[from..from + tail]);
                            }
                            for (acc, &dy_plane) in acc.iter_mut().zip(&dy_planes) {
                                let mut ds = [0.0f32; SLACK];
                                let from = dy_plane + dy_row + whole;
                                ds[..tail].copy_from_slice(&dy[from..from + tail]);
                                // SAFETY: `ds` and `xs` hold SLACK >= WIDTH values each.
                                unsafe {
                                    let d = L::load(ds.as_ptr());
                                    for (acc, xs) in acc.iter_mut().zip(&xs) {
                                        *acc = acc.multiply_add(d, L::load(xs.as_ptr()));
                                    }
                                }
                            }
                        }
                    }
                    let mut lanes = [0.0f32; SLACK];
                    for r in 0..channels {
                        let dw_row = &mut dw[(block * R + r) * taps + channel * taps_per_channel..];
                        for jj in 0..group {
                            // SAFETY: `lanes` holds SLACK >= WIDTH values.
                            unsafe { acc[r][jj].store(lanes.as_mut_ptr()) };
                            let sum: f32 = lanes[..L::WIDTH].iter().sum();
                            dw_row[t0 + jj] += sum;
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{FORWARD_ROWS, forward_blocks};

    /// On a CPU with AVX-512, the AVX2 forward pass (the one CPUs without it run) agrees with
    /// the AVX-512 one `forward_image` takes: H-Net's 3 x 3 layer on a 16 px image, with 5 and 7
    /// channels (uneven register tiles), bias and ReLU.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_and_avx512_forward_passes_agree() {
        use super::{PaddedLayout, forward_avx2, forward_image, pack_weight};
        use crate::geometry::ConvGeometry;
        use burn::tensor::ops::ConvOptions;
        use core::mem::MaybeUninit;
        if !crate::products::has_avx512() {
            return;
        }
        let options = ConvOptions::new([1, 1], [1, 1], [1, 1], 1);
        let g = ConvGeometry::of_conv2d([1, 5, 16, 16], [7, 5, 3, 3], &options).unwrap();
        let value = |i: usize| ((i * 2_654_435_761) % 2001) as f32 / 1000.0 - 1.0;
        let x: alloc::vec::Vec<f32> = (0..5 * 16 * 16).map(value).collect();
        let w: alloc::vec::Vec<f32> = (0..7 * 5 * 9).map(|i| value(i + 7)).collect();
        let bias: alloc::vec::Vec<f32> = (0..7).map(|i| value(i + 3)).collect();
        let layout = PaddedLayout::of(&g).unwrap();
        let mut padded = alloc::vec![0.0; layout.len(5)];
        layout.pad(&g, &x, &mut padded);
        let packed = pack_weight(&w, 7, g.taps());
        let run = |avx2: bool| {
            let mut y = alloc::vec![MaybeUninit::uninit(); 7 * g.output_plane()];
            if avx2 {
                // SAFETY: a CPU with AVX-512F has AVX2 and FMA (`has_avx512`).
                unsafe { forward_avx2(&g, &layout, &padded, &packed, Some(&bias), true, &mut y) };
            } else {
                forward_image(&g, &layout, &padded, &packed, Some(&bias), true, &mut y);
            }
            // SAFETY: both write every value.
            y.into_iter()
                .map(|v| unsafe { v.assume_init() })
                .collect::<alloc::vec::Vec<f32>>()
        };
        let (avx2, avx512) = (run(true), run(false));
        let error = avx2
            .iter()
            .zip(&avx512)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(error < 1e-5, "{error:e}");
    }

    #[test]
    fn forward_blocks_cover_every_channel_once_in_even_tiles() {
        for channels in 1..=70 {
            let blocks: alloc::vec::Vec<_> = forward_blocks(channels).collect();
            assert_eq!(blocks.len(), channels.div_ceil(FORWARD_ROWS), "{channels}");
            let mut next = 0;
            for &(first, rows) in &blocks {
                assert_eq!(first, next, "{channels}: contiguous");
                assert!(
                    (1..=FORWARD_ROWS).contains(&rows),
                    "{channels}: {rows} rows"
                );
                next += rows;
            }
            assert_eq!(next, channels);
            let (least, most) = blocks
                .iter()
                .fold((usize::MAX, 0), |(l, m), &(_, r)| (l.min(r), m.max(r)));
            assert!(most - least <= 1, "{channels}: uneven {blocks:?}");
        }
        assert_eq!(
            forward_blocks(32)
                .map(|(_, rows)| rows)
                .collect::<alloc::vec::Vec<_>>(),
            [6, 6, 5, 5, 5, 5]
        );
    }
}
