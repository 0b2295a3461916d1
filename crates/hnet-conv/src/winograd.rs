//! Winograd's minimal filtering F(2x2, 3x3) (Lavin and Gray, "Fast Algorithms for Convolutional
//! Neural Networks", CVPR 2016) for the forward pass of stride-1, undilated 3x3 convolutions with
//! an even output at least one strip wide ([`WinogradLayout::of`]): H-Net's double convolutions
//! but the narrow ones near the bottleneck, and their input gradients (the forward pass of the
//! turned kernel).
//!
//! Each 2 x 2 block of output pixels (a *tile*) of output channel `o` is
//! `Y = Aᵀ [Σ_c (G g_oc Gᵀ) ⊙ (Bᵀ d_c B)] A`, where `d_c` is the 4 x 4 patch of input channel `c`
//! the tile reads and `g_oc` the 3 x 3 kernel. The sum over channels is, for each of the 16 points
//! of the transformed domain, one matrix product `(out x in) · (in x tiles)`: 16 multiply-adds
//! per tile and channel pair where the direct kernel ([`crate::direct`]) needs 36, 2.25x fewer.
//! The transforms only add and subtract (and halve, for the weight), so for finite inputs well
//! below `f32::MAX` the result is the direct convolution's up to f32 rounding, and each output
//! depends on exactly the inputs of its 3 x 3 window: a NaN reaches the same outputs as in the
//! direct kernel. An infinite input is another matter: the transforms take differences of
//! neighbours, and `inf - inf` makes NaN where the direct kernel gives an infinity.
//!
//! The work goes by strips of [`STRIP_TILES`] tiles along one row of tiles: the strip's input is
//! transformed into `V[point][channel][tile]`, multiplied by each point's transformed weight
//! with the direct kernel's register tile (output channels by two vectors of tiles), and
//! transformed back into the output, with the bias and the ReLU, while it is in cache. Each row
//! of tiles reads four padded input rows per channel: they are copied, zero-padded and split into
//! their even and odd columns (so that the tiles of a strip, two columns apart, load as whole
//! vectors), into a window of [`WINDOW_ROWS`] rows per channel that each row of tiles advances
//! by two ([`WinogradLayout::pad_rows`]). The window stays in cache; a padded copy of the whole
//! image did not (reading it back was a fifth of a 224 px pass).

use alloc::vec;
use alloc::vec::Vec;
use core::mem::MaybeUninit;

use crate::direct::{forward_blocks, with_block_rows};
use crate::geometry::ConvGeometry;
use crate::products::Lanes;

/// Tiles per strip: two vectors of tiles (AVX2: 2 x 8; WebAssembly SIMD128: 2 x 4).
pub const STRIP_TILES: usize = if cfg!(target_arch = "wasm32") { 8 } else { 16 };

/// Points of the transformed domain per tile (4 x 4).
const POINTS: usize = 16;

/// Padded rows per channel in the window: the four a row of tiles reads, padded row `r` in slot
/// `r % WINDOW_ROWS`.
const WINDOW_ROWS: usize = 4;

/// Where a convolution's zero-padded input rows lie in their window, for the Winograd kernel.
#[derive(Debug, Clone)]
pub struct WinogradLayout {
    /// Rows of tiles (output height / 2).
    tiles_h: usize,
    /// Tiles per row (output width / 2).
    tiles_w: usize,
    /// Strips per row of tiles; the last one may hold fewer than [`STRIP_TILES`] real tiles.
    strips: usize,
    /// Values per half row (the even padded columns, then as many odd ones): one more than the
    /// strips' tiles, so that every strip loads whole vectors inside its row.
    half: usize,
    /// Padded rows per plane (output height + 2).
    rows: usize,
}

impl WinogradLayout {
    /// The layout of `g`, or `None` when the Winograd kernel does not serve it: anything but a
    /// stride-1, undilated 3 x 3 kernel, an odd output height or width, or rows narrower than
    /// one strip (H-Net's small bottleneck layers, where a strip would be mostly empty).
    pub fn of(g: &ConvGeometry) -> Option<Self> {
        let (h, w) = (&g.height, &g.width);
        let served = |a: &crate::geometry::Axis| {
            a.stride == 1 && a.kernel == 3 && a.dilation == 1 && a.output.is_multiple_of(2)
        };
        if !served(h) || !served(w) || w.output / 2 < STRIP_TILES || h.output == 0 {
            return None;
        }
        let tiles_w = w.output / 2;
        let strips = tiles_w.div_ceil(STRIP_TILES);
        Some(Self {
            tiles_h: h.output / 2,
            tiles_w,
            strips,
            half: strips * STRIP_TILES + 1,
            rows: h.output + 2,
        })
    }

    /// Values per padded row (both halves).
    fn row(&self) -> usize {
        2 * self.half
    }

    /// Values per channel in the window.
    fn window_plane(&self) -> usize {
        WINDOW_ROWS * self.row()
    }

    /// Length of the window for one image of `channels` channels.
    pub fn len(&self, channels: usize) -> usize {
        channels * self.window_plane()
    }

    /// Offset in the window of padded row `r` of channel `c`.
    fn window_row(&self, c: usize, r: usize) -> usize {
        c * self.window_plane() + (r % WINDOW_ROWS) * self.row()
    }

    /// Writes padded rows `rows` (at most [`WINDOW_ROWS`] of them, each below the padded height)
    /// of image `image` (`in_channels` planes of the input) into `window` ([`Self::len`] long):
    /// padded row `r` of channel `c` holds the padded image's even columns `0, 2, 4, ...` then
    /// its odd columns `1, 3, 5, ...`, zero outside the image, every value of it written.
    pub fn pad_rows(
        &self,
        g: &ConvGeometry,
        image: &[f32],
        rows: core::ops::Range<usize>,
        window: &mut [f32],
    ) {
        let (in_h, in_w) = (g.height.input, g.width.input);
        let (top, left) = (g.height.padding, g.width.padding.min(self.row()));
        debug_assert_eq!(image.len(), g.in_channels * in_h * in_w);
        debug_assert_eq!(window.len(), self.len(g.in_channels));
        debug_assert!(rows.len() <= WINDOW_ROWS && rows.end <= self.rows);
        // Padded column `p` is image column `p - left`: pairs of padded columns `(2k, 2k + 1)`
        // read image columns `2k - left` and `2k + 1 - left`. `inside` are the pairs with both
        // in the image; the rest are written one by one.
        let first = left.div_ceil(2);
        let inside = first..(in_w + left) / 2;
        let inside = inside.start.min(self.half)..inside.end.clamp(inside.start, self.half);
        let half = self.half;
        for c in 0..g.in_channels {
            let channel = &image[c * in_h * in_w..][..in_h * in_w];
            for r in rows.clone() {
                let at = self.window_row(c, r);
                let (even, odd) = window[at..][..2 * half].split_at_mut(half);
                let Some(i) = r.checked_sub(top).filter(|&i| i < in_h) else {
                    even.fill(0.0);
                    odd.fill(0.0);
                    continue;
                };
                let line = &channel[i * in_w..][..in_w];
                let pixel = |p: usize| {
                    p.checked_sub(left)
                        .and_then(|column| line.get(column))
                        .copied()
                        .unwrap_or(0.0)
                };
                for k in (0..inside.start).chain(inside.end..half) {
                    even[k] = pixel(2 * k);
                    odd[k] = pixel(2 * k + 1);
                }
                if inside.is_empty() {
                    continue;
                }
                let pairs = &line[2 * inside.start - left..][..2 * inside.len()];
                for (pair, (even, odd)) in pairs.chunks_exact(2).zip(
                    even[inside.clone()]
                        .iter_mut()
                        .zip(&mut odd[inside.clone()]),
                ) {
                    *even = pair[0];
                    *odd = pair[1];
                }
            }
        }
    }
}

/// The OIHW weight (`out_channels x in_channels x 3 x 3`) in the transformed domain,
/// `U = G g Gᵀ` per channel pair, packed for the products: per point, per block of
/// [`forward_blocks`], per input channel, the block's output channels.
pub fn transform_weight(weight: &[f32], out_channels: usize, in_channels: usize) -> Vec<f32> {
    assert_eq!(
        weight.len(),
        out_channels * in_channels * 9,
        "3x3 weight size"
    );
    // G = [[1, 0, 0], [½, ½, ½], [½, -½, ½], [0, 0, 1]] applied to three values.
    let g_times = |v: [f32; 3]| {
        [
            v[0],
            0.5 * (v[0] + v[1] + v[2]),
            0.5 * (v[0] - v[1] + v[2]),
            v[2],
        ]
    };
    // U per (output, input) channel pair, 16 points each.
    let mut transformed = vec![0.0f32; out_channels * in_channels * POINTS];
    for (kernel, u) in weight
        .chunks_exact(9)
        .zip(transformed.chunks_exact_mut(POINTS))
    {
        // G g: 4 x 3, column by column.
        let columns: [[f32; 4]; 3] =
            core::array::from_fn(|j| g_times([kernel[j], kernel[3 + j], kernel[6 + j]]));
        for a in 0..4 {
            let row = g_times([columns[0][a], columns[1][a], columns[2][a]]);
            u[a * 4..][..4].copy_from_slice(&row);
        }
    }
    let mut packed = Vec::with_capacity(transformed.len());
    for point in 0..POINTS {
        for (first, channels) in forward_blocks(out_channels) {
            for c in 0..in_channels {
                packed.extend(
                    (first..first + channels)
                        .map(|o| transformed[(o * in_channels + c) * POINTS + point]),
                );
            }
        }
    }
    packed
}

/// One image's forward convolution `y = W ⋆ x (+ b)`, NCHW, followed by a ReLU when `relu`, from
/// the image `image` (`in_channels` planes), with `window` ([`WinogradLayout::len`] values,
/// overwritten) for its padded rows, and the weight transformed by [`transform_weight`]. Every
/// element of `y` (`out_channels x output plane`) is written.
#[allow(clippy::too_many_arguments)]
pub fn forward_image(
    g: &ConvGeometry,
    layout: &WinogradLayout,
    image: &[f32],
    window: &mut [f32],
    weight: &[f32],
    bias: Option<&[f32]>,
    relu: bool,
    y: &mut [MaybeUninit<f32>],
) {
    assert!(
        window.len() == layout.len(g.in_channels)
            && image.len() == g.in_channels * g.input_plane()
            && weight.len() == g.out_channels * g.in_channels * POINTS
            && y.len() == g.out_channels * g.output_plane()
            && bias.is_none_or(|b| b.len() == g.out_channels)
            && layout.tiles_w * 2 == g.width.output
            && layout.tiles_h * 2 == g.height.output,
        "Winograd forward: buffer sizes"
    );
    let run = Run {
        g,
        layout,
        image,
        weight,
        bias,
        relu,
    };
    #[cfg(target_arch = "x86_64")]
    if crate::products::has_avx2() {
        // SAFETY: this CPU has AVX2 and FMA.
        return unsafe { run.strips::<avx2::Avx2Phases>(window, y) };
    }
    #[cfg(all(target_arch = "wasm32", feature = "relaxed-simd"))]
    // SAFETY: a module built with `relaxed-simd` only compiles where the browser has it.
    return unsafe { run.strips::<fused::FusedPhases>(window, y) };
    #[cfg(all(target_arch = "wasm32", not(feature = "relaxed-simd")))]
    // SAFETY: wasm32 builds enable SIMD128 for the whole crate (.cargo/config.toml).
    return unsafe { run.strips::<Generic<crate::products::simd128::Simd128, 2>>(window, y) };
    #[allow(unreachable_code)]
    // SAFETY: the portable lanes need no instruction set.
    unsafe {
        run.strips::<Generic<f32, STRIP_TILES>>(window, y)
    }
}

/// The three phases of a strip, for one instruction set.
///
/// # Safety
///
/// Every method may only be called on a CPU that has the implementation's instruction set.
trait Phases {
    unsafe fn transform_input(
        run: &Run,
        window: &[f32],
        tile_row: usize,
        first_tile: usize,
        out: &mut [f32],
    );
    unsafe fn multiply(run: &Run, transformed: &[f32], products: &mut [f32]);
    unsafe fn transform_output(
        run: &Run,
        tile_row: usize,
        first_tile: usize,
        products: &[f32],
        y: &mut [MaybeUninit<f32>],
    );
}

/// The phases over [`Lanes`] `L`, `V` vectors per strip, where `L`'s instructions are always
/// available (SIMD128 in a module built with it, and the portable `f32`).
struct Generic<L, const V: usize>(core::marker::PhantomData<L>);

impl<L: Lanes, const V: usize> Phases for Generic<L, V> {
    unsafe fn transform_input(
        run: &Run,
        window: &[f32],
        tile_row: usize,
        first_tile: usize,
        out: &mut [f32],
    ) {
        run.transform_input::<L, V>(window, tile_row, first_tile, out);
    }
    unsafe fn multiply(run: &Run, transformed: &[f32], products: &mut [f32]) {
        run.multiply::<L, V>(transformed, products);
    }
    unsafe fn transform_output(
        run: &Run,
        tile_row: usize,
        first_tile: usize,
        products: &[f32],
        y: &mut [MaybeUninit<f32>],
    ) {
        run.transform_output::<L, V>(tile_row, first_tile, products, y);
    }
}

/// A module `$module` with `$phases`, the three phases over lanes `$lanes`, each compiled with
/// `$features` on its own: inlined into one function, the compiler left the vector intrinsics as
/// calls (a third of the time in `perf`, AVX2). One definition for every instruction set that needs
/// its features enabled per function.
#[cfg(any(
    target_arch = "x86_64",
    all(target_arch = "wasm32", feature = "relaxed-simd")
))]
macro_rules! phases_compiled_for {
    ($(#[$doc:meta])* $module:ident, $phases:ident, $lanes:path, $features:literal) => {
        mod $module {
            use core::mem::MaybeUninit;

            use super::Run;

            $(#[$doc])*
            pub(super) struct $phases;

            // `unsafe` calls: a target-feature function is unsafe to call on x86-64 and safe on
            // wasm32 (where the module would not compile without the features).
            #[allow(unused_unsafe)]
            impl super::Phases for $phases {
                unsafe fn transform_input(
                    run: &Run,
                    window: &[f32],
                    tile_row: usize,
                    first_tile: usize,
                    out: &mut [f32],
                ) {
                    // SAFETY: this CPU has the features (the trait's contract).
                    unsafe { transform_input(run, window, tile_row, first_tile, out) }
                }
                unsafe fn multiply(run: &Run, transformed: &[f32], products: &mut [f32]) {
                    // SAFETY: as above.
                    unsafe { multiply(run, transformed, products) }
                }
                unsafe fn transform_output(
                    run: &Run,
                    tile_row: usize,
                    first_tile: usize,
                    products: &[f32],
                    y: &mut [MaybeUninit<f32>],
                ) {
                    // SAFETY: as above.
                    unsafe { transform_output(run, tile_row, first_tile, products, y) }
                }
            }

            #[target_feature(enable = $features)]
            fn transform_input(
                run: &Run,
                window: &[f32],
                tile_row: usize,
                first_tile: usize,
                out: &mut [f32],
            ) {
                run.transform_input::<$lanes, 2>(window, tile_row, first_tile, out);
            }

            #[target_feature(enable = $features)]
            fn multiply(run: &Run, transformed: &[f32], products: &mut [f32]) {
                run.multiply::<$lanes, 2>(transformed, products);
            }

            #[target_feature(enable = $features)]
            fn transform_output(
                run: &Run,
                tile_row: usize,
                first_tile: usize,
                products: &[f32],
                y: &mut [MaybeUninit<f32>],
            ) {
                run.transform_output::<$lanes, 2>(tile_row, first_tile, products, y);
            }
        }
    };
}

#[cfg(target_arch = "x86_64")]
phases_compiled_for!(
    /// The phases for AVX2 and FMA (the trait's contract: only on CPUs that have them).
    avx2,
    Avx2Phases,
    crate::products::avx2::Avx2,
    "avx2,fma"
);

// The crate's `relaxed-simd` feature: relaxed SIMD's fused multiply-adds.
#[cfg(all(target_arch = "wasm32", feature = "relaxed-simd"))]
phases_compiled_for!(
    /// The phases for SIMD128 with relaxed SIMD (the trait's contract: only in a module the
    /// browser compiled, which it does only where it has relaxed SIMD).
    fused,
    FusedPhases,
    crate::products::simd128::FusedSimd128,
    "simd128,relaxed-simd"
);

/// Values between consecutive points of the transformed input: one strip row more than the
/// channels need, so that the 16 points of one channel (written together by the input transform)
/// do not fall into the same cache set, as they would a power of two apart.
fn point_stride(in_channels: usize) -> usize {
    (in_channels + 1) * STRIP_TILES
}

/// One call of [`forward_image`].
struct Run<'a> {
    g: &'a ConvGeometry,
    layout: &'a WinogradLayout,
    image: &'a [f32],
    weight: &'a [f32],
    bias: Option<&'a [f32]>,
    relu: bool,
}

impl Run<'_> {
    /// Every strip: input transform, products, output transform.
    ///
    /// # Safety
    ///
    /// This CPU has `P`'s instruction set ([`Phases`]).
    unsafe fn strips<P: Phases>(&self, window: &mut [f32], y: &mut [MaybeUninit<f32>]) {
        let (cin, cout) = (self.g.in_channels, self.g.out_channels);
        let mut transformed = vec![0.0f32; POINTS * point_stride(cin)];
        let mut products = vec![0.0f32; cout * POINTS * STRIP_TILES];
        for tile_row in 0..self.layout.tiles_h {
            // Padded rows `2 · tile_row .. + 4`; the first two are in the window already but
            // for the first row of tiles.
            let rows = if tile_row == 0 {
                0..4
            } else {
                2 * tile_row + 2..2 * tile_row + 4
            };
            self.layout.pad_rows(self.g, self.image, rows, window);
            self.prefetch_next(tile_row + 1, y);
            for strip in 0..self.layout.strips {
                let first_tile = strip * STRIP_TILES;
                // SAFETY: the caller's promise ([`Self::strips`]).
                unsafe {
                    P::transform_input(self, window, tile_row, first_tile, &mut transformed);
                    P::multiply(self, &transformed, &mut products);
                    P::transform_output(self, tile_row, first_tile, &products, y);
                }
            }
        }
    }

    /// Asks the cache for what row of tiles `tile_row` will read and write, one row of tiles
    /// ahead: its two new image rows of every input channel and its two output rows of every
    /// output channel. Spread over a channel each, these are too many streams for the hardware's
    /// prefetcher, and their misses were most of the padding's and the output's time.
    /// Nothing when the image and its output fit in 1 MiB ([`PREFETCH_MIN_VALUES`]).
    fn prefetch_next(&self, tile_row: usize, y: &[MaybeUninit<f32>]) {
        if tile_row >= self.layout.tiles_h || self.image.len() + y.len() < PREFETCH_MIN_VALUES {
            return;
        }
        let g = self.g;
        let (in_h, in_w) = (g.height.input, g.width.input);
        let (out_w, out_plane) = (g.width.output, g.output_plane());
        for padded_row in 2 * tile_row + 2..2 * tile_row + 4 {
            let Some(i) = padded_row
                .checked_sub(g.height.padding)
                .filter(|&i| i < in_h)
            else {
                continue;
            };
            for c in 0..g.in_channels {
                prefetch(&self.image[(c * in_h + i) * in_w..][..in_w], false);
            }
        }
        for o in 0..g.out_channels {
            prefetch(
                &y[o * out_plane + 2 * tile_row * out_w..][..2 * out_w],
                true,
            );
        }
    }

    /// `V[point][channel][tile] = (Bᵀ d B)[point]` for the strip's tiles, every input channel;
    /// the points [`point_stride`] apart.
    #[inline(always)]
    fn transform_input<L: Lanes, const V: usize>(
        &self,
        window: &[f32],
        tile_row: usize,
        first_tile: usize,
        out: &mut [f32],
    ) {
        const { assert!(V * L::WIDTH == STRIP_TILES, "a strip is V vectors") };
        let layout = self.layout;
        let half = layout.half;
        let cin = self.g.in_channels;
        let stride = point_stride(cin);
        debug_assert_eq!(out.len(), POINTS * stride);
        for c in 0..cin {
            // Each strip reads values `first_tile ..= first_tile + STRIP_TILES` of both halves
            // of four rows: inside each row (`half = strips · STRIP_TILES + 1`).
            let rows: [&[f32]; 4] = core::array::from_fn(|r| {
                let at = layout.window_row(c, 2 * tile_row + r) + first_tile;
                &window[at..][..half + STRIP_TILES + 1]
            });
            for v in 0..V {
                let at = v * L::WIDTH;
                // Column combinations of each row: with e, o the even and odd columns,
                // (d0 - d2, d1 + d2, d2 - d1, d1 - d3) = (e0 - e1, o0 + e1, e1 - o0, o0 - o1).
                let mut w = [[L::zero(); 4]; 4];
                for (w, line) in w.iter_mut().zip(&rows) {
                    let line = line.as_ptr();
                    // SAFETY: `at + WIDTH <= STRIP_TILES`, so every load lies in `line`
                    // (`half + STRIP_TILES + 1` values).
                    let (e0, e1, o0, o1) = unsafe {
                        (
                            L::load(line.add(at)),
                            L::load(line.add(at + 1)),
                            L::load(line.add(half + at)),
                            L::load(line.add(half + at + 1)),
                        )
                    };
                    *w = [e0.sub(e1), o0.add(e1), e1.sub(o0), o0.sub(o1)];
                }
                for k in 0..4 {
                    let points = [
                        w[0][k].sub(w[2][k]),
                        w[1][k].add(w[2][k]),
                        w[2][k].sub(w[1][k]),
                        w[1][k].sub(w[3][k]),
                    ];
                    for (i, value) in points.into_iter().enumerate() {
                        let to =
                            &mut out[(i * 4 + k) * stride + c * STRIP_TILES + at..][..L::WIDTH];
                        // SAFETY: `to` holds WIDTH values.
                        unsafe { value.store(to.as_mut_ptr()) };
                    }
                }
            }
        }
    }

    /// `M[point] = U[point] · V[point]` for every point, stored as `M[out channel][point][tile]`
    /// (so that the output transform reads one channel's points together).
    #[inline(always)]
    fn multiply<L: Lanes, const V: usize>(&self, transformed: &[f32], products: &mut [f32]) {
        const { assert!(V * L::WIDTH == STRIP_TILES, "a strip is V vectors") };
        let (cin, cout) = (self.g.in_channels, self.g.out_channels);
        for point in 0..POINTS {
            let input = &transformed[point * point_stride(cin)..][..cin * STRIP_TILES];
            let weight = &self.weight[point * cout * cin..][..cout * cin];
            for (first, channels) in forward_blocks(cout) {
                let panel = &weight[first * cin..][..channels * cin];
                let out = &mut products[(first * POINTS + point) * STRIP_TILES..];
                with_block_rows!(channels, R => block_product::<L, V, R>(panel, input, out));
            }
        }
    }

    /// `Y = Aᵀ M A (+ b)`, then the ReLU, for every output channel of the strip, stored in `y`.
    #[inline(always)]
    fn transform_output<L: Lanes, const V: usize>(
        &self,
        tile_row: usize,
        first_tile: usize,
        products: &[f32],
        y: &mut [MaybeUninit<f32>],
    ) {
        const { assert!(V * L::WIDTH == STRIP_TILES, "a strip is V vectors") };
        let cout = self.g.out_channels;
        let (out_w, out_plane) = (self.g.width.output, self.g.output_plane());
        let tiles = STRIP_TILES.min(self.layout.tiles_w - first_tile);
        let whole = tiles == STRIP_TILES;
        // A partial strip's two output rows of one channel.
        let mut lines = [[0.0f32; 2 * STRIP_TILES]; 2];
        for o in 0..cout {
            let plane = y[o * out_plane..][..out_plane].as_mut_ptr().cast::<f32>();
            let b = L::splat(self.bias.map_or(0.0, |bias| bias[o]));
            for v in 0..V {
                let at = v * L::WIDTH;
                // No closures here (`array::from_fn`): the vector operations inside them were
                // left as calls.
                let mut m = [L::zero(); POINTS];
                for (point, m) in m.iter_mut().enumerate() {
                    let from = &products[(o * POINTS + point) * STRIP_TILES + at..][..L::WIDTH];
                    // SAFETY: `from` holds WIDTH values.
                    *m = unsafe { L::load(from.as_ptr()) };
                }
                // Aᵀ = [[1, 1, 1, 0], [0, 1, -1, -1]], on the rows, then on the columns.
                let (mut top, mut bottom) = ([L::zero(); 4], [L::zero(); 4]);
                for k in 0..4 {
                    top[k] = m[k].add(m[4 + k]).add(m[8 + k]);
                    bottom[k] = m[4 + k].sub(m[8 + k]).sub(m[12 + k]);
                }
                let mut outputs = [
                    top[0].add(top[1]).add(top[2]),
                    top[1].sub(top[2]).sub(top[3]),
                    bottom[0].add(bottom[1]).add(bottom[2]),
                    bottom[1].sub(bottom[2]).sub(bottom[3]),
                ];
                for value in &mut outputs {
                    *value = value.add(b);
                    if self.relu {
                        *value = value.relu();
                    }
                }
                // Each output row of the strip: its tiles' left and right pixels alternated,
                // stored straight into the channel's plane when the strip is whole (the copy
                // through `lines` was a tenth of a 224 px pass), else through `lines`.
                for (dr, pair) in outputs.chunks_exact(2).enumerate() {
                    let (first, second) = pair[0].interleave(pair[1]);
                    let to = if whole {
                        // SAFETY: a whole strip's row holds `2 · STRIP_TILES` values from
                        // `2 · first_tile`, inside the output row (`2 · tiles_w = out_w`), and
                        // `2 · at + 2 · WIDTH` is at most `2 · STRIP_TILES`; `MaybeUninit<f32>` has
                        // `f32`'s layout, and a store initialises.
                        unsafe { plane.add((2 * tile_row + dr) * out_w + 2 * first_tile) }
                    } else {
                        lines[dr].as_mut_ptr()
                    };
                    // SAFETY: `to` holds `2 · STRIP_TILES` values (above, or `lines`).
                    unsafe {
                        first.store(to.add(2 * at));
                        second.store(to.add(2 * at + L::WIDTH));
                    }
                }
            }
            if !whole {
                let plane = &mut y[o * out_plane..][..out_plane];
                for (dr, line) in lines.iter().enumerate() {
                    let out =
                        &mut plane[(2 * tile_row + dr) * out_w + 2 * first_tile..][..2 * tiles];
                    for (out, &value) in out.iter_mut().zip(line) {
                        out.write(value);
                    }
                }
            }
        }
    }
}

/// Values of an image and its output (1 MiB) under which [`Run::prefetch_next`] asks for nothing:
/// they stay in a level-2 cache of 1 MiB or more (2 MiB here) from one row of tiles to the next.
const PREFETCH_MIN_VALUES: usize = 1 << 18;

/// Asks for `values` in the level-2 cache, to be written when `write`; nothing where the target
/// has no prefetch instruction (WebAssembly).
#[inline(always)]
fn prefetch<T>(values: &[T], write: bool) {
    #[cfg(target_arch = "x86_64")]
    {
        use core::arch::x86_64::{_MM_HINT_ET1, _MM_HINT_T1, _mm_prefetch};
        const LINE: usize = 64;
        let bytes = core::mem::size_of_val(values);
        let start = values.as_ptr().cast::<i8>();
        for offset in (0..bytes).step_by(LINE) {
            // SAFETY: a prefetch has no effect on memory; the address lies in `values`.
            unsafe {
                let at = start.add(offset);
                if write {
                    _mm_prefetch::<_MM_HINT_ET1>(at);
                } else {
                    _mm_prefetch::<_MM_HINT_T1>(at);
                }
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (values, write);
}

/// `out (R x STRIP_TILES) = panel (in_channels steps of R) · input (in_channels x STRIP_TILES)`,
/// with an `R` channels by `V` vectors tile of accumulators in registers; the rows of `out` are
/// `POINTS · STRIP_TILES` apart.
#[inline(always)]
fn block_product<L: Lanes, const V: usize, const R: usize>(
    panel: &[f32],
    input: &[f32],
    out: &mut [f32],
) {
    const { assert!(V * L::WIDTH == STRIP_TILES, "a strip is V vectors") };
    let steps = input.len() / STRIP_TILES;
    let row = POINTS * STRIP_TILES;
    assert!(panel.len() == steps * R && out.len() >= (R - 1) * row + STRIP_TILES);
    let mut acc = [[L::zero(); V]; R];
    for (weights, values) in panel.chunks_exact(R).zip(input.chunks_exact(STRIP_TILES)) {
        // SAFETY: `values` holds STRIP_TILES = V · WIDTH values.
        let bv: [L; V] = unsafe { L::load_vectors(values.as_ptr()) };
        for r in 0..R {
            let a = L::splat(weights[r]);
            for v in 0..V {
                acc[r][v] = acc[r][v].multiply_add(a, bv[v]);
            }
        }
    }
    for (r, acc) in acc.iter().enumerate() {
        for (v, value) in acc.iter().enumerate() {
            // SAFETY: row `r` of `out` holds STRIP_TILES values (asserted above).
            unsafe { value.store(out.as_mut_ptr().add(r * row + v * L::WIDTH)) };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::direct::{self, PaddedLayout};

    /// Deterministic values in [-1, 1].
    fn values(count: usize, salt: u32) -> Vec<f32> {
        (0..count as u32)
            .map(|i| {
                let h = (i ^ salt).wrapping_mul(2_654_435_761).rotate_left(13);
                (h % 2001) as f32 / 1000.0 - 1.0
            })
            .collect()
    }

    /// The direct kernel's result for the same convolution.
    fn direct_forward(
        g: &ConvGeometry,
        x: &[f32],
        w: &[f32],
        bias: Option<&[f32]>,
        relu: bool,
    ) -> Vec<f32> {
        let layout = PaddedLayout::of(g).unwrap();
        let mut padded = vec![0.0; layout.len(g.in_channels)];
        layout.pad(g, x, &mut padded);
        let packed = direct::pack_weight(w, g.out_channels, g.taps());
        let mut y = vec![MaybeUninit::uninit(); g.out_channels * g.output_plane()];
        direct::forward_image(g, &layout, &padded, &packed, bias, relu, &mut y);
        y.into_iter().map(|v| unsafe { v.assume_init() }).collect()
    }

    /// The Winograd kernel's result for the same convolution: by `forward_image` (the path this
    /// machine runs) when `portable` is false, else by the portable f32 lanes.
    fn winograd_forward(
        g: &ConvGeometry,
        x: &[f32],
        w: &[f32],
        bias: Option<&[f32]>,
        relu: bool,
        portable: bool,
    ) -> Vec<f32> {
        let layout = WinogradLayout::of(g).unwrap();
        // NaN where the pad writes nothing: a read outside the padded rows would show.
        let mut window = vec![f32::NAN; layout.len(g.in_channels)];
        let weight = transform_weight(w, g.out_channels, g.in_channels);
        let mut y = vec![MaybeUninit::uninit(); g.out_channels * g.output_plane()];
        if portable {
            let run = Run {
                g,
                layout: &layout,
                image: x,
                weight: &weight,
                bias,
                relu,
            };
            // SAFETY: the portable lanes need no instruction set.
            unsafe { run.strips::<Generic<f32, STRIP_TILES>>(&mut window, &mut y) };
        } else {
            forward_image(g, &layout, x, &mut window, &weight, bias, relu, &mut y);
        }
        y.into_iter().map(|v| unsafe { v.assume_init() }).collect()
    }

    /// Both the SIMD path this machine runs and the portable one agree with the direct kernel,
    /// over paddings of 0, 1 and 2, a partial last strip and channel counts that leave uneven
    /// register tiles (one-sided paddings: `tests/against_burn.rs`).
    #[test]
    fn winograd_matches_the_direct_kernel() {
        use burn::tensor::ops::ConvOptions;
        for (size, padding, channels) in [
            ([6, 34], [1, 1], (5, 7)),
            ([10, 2 * STRIP_TILES + 2], [0, 0], (3, 13)),
            ([4, 2 * STRIP_TILES + 20], [2, 2], (8, 32)),
        ] {
            let (cin, cout) = channels;
            let options = ConvOptions::new([1, 1], padding, [1, 1], 1);
            let g =
                ConvGeometry::of_conv2d([1, cin, size[0], size[1]], [cout, cin, 3, 3], &options)
                    .unwrap();
            let x = values(cin * size[0] * size[1], 1);
            let w = values(cout * cin * 9, 2);
            let bias = values(cout, 3);
            for relu in [false, true] {
                let expected = direct_forward(&g, &x, &w, Some(&bias), relu);
                let simd = winograd_forward(&g, &x, &w, Some(&bias), relu, false);
                let portable = winograd_forward(&g, &x, &w, Some(&bias), relu, true);
                for (ours, name) in [(&simd, "SIMD"), (&portable, "portable")] {
                    let error = ours
                        .iter()
                        .zip(&expected)
                        .map(|(a, b)| (a - b).abs())
                        .fold(0.0f32, f32::max);
                    assert!(error < 1e-4, "{name} {size:?} {padding:?}: {error:e}");
                }
            }
        }
    }

    /// Shapes the kernel does not serve get no layout.
    #[test]
    fn only_stride_1_undilated_3x3_with_even_wide_outputs() {
        use burn::tensor::ops::ConvOptions;
        let wide = 2 * STRIP_TILES;
        let layout = |size: [usize; 2], kernel: usize, stride: usize, dilation: usize| {
            let options = ConvOptions::new([stride; 2], [kernel / 2; 2], [dilation; 2], 1);
            let g =
                ConvGeometry::of_conv2d([1, 2, size[0], size[1]], [2, 2, kernel, kernel], &options)
                    .unwrap();
            WinogradLayout::of(&g).is_some()
        };
        assert!(layout([8, wide], 3, 1, 1));
        assert!(!layout([7, wide], 3, 1, 1), "odd height");
        assert!(!layout([8, wide + 1], 3, 1, 1), "odd width");
        assert!(!layout([8, wide - 2], 3, 1, 1), "narrower than a strip");
        assert!(!layout([8, wide], 3, 2, 1), "stride 2");
        assert!(!layout([8, wide], 5, 1, 1), "5x5");
        assert!(!layout([8, wide], 3, 1, 2), "dilated");
    }
}
