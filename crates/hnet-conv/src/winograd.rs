//! Winograd's minimal filtering F(m x m, 3x3) (Lavin and Gray, "Fast Algorithms for Convolutional
//! Neural Networks", CVPR 2016), with tiles of m = 2 or m = 4 output pixels a side ([`Tile`]), for
//! the forward pass of stride-1, undilated 3x3 convolutions whose output is a whole number of
//! tiles and at least one strip wide ([`WinogradLayout::of`]): H-Net's double convolutions but the
//! narrow ones near the bottleneck, and their input gradients (the forward pass of the turned
//! kernel).
//!
//! Each m x m block of output pixels (a *tile*) of output channel `o` is
//! `Y = Aᵀ [Σ_c (G g_oc Gᵀ) ⊙ (Bᵀ d_c B)] A`, where `d_c` is the (m + 2)² patch of input channel
//! `c` the tile reads and `g_oc` the 3 x 3 kernel. The sum over channels is, for each of the
//! (m + 2)² points of the transformed domain, one matrix product `(out x in) · (in x tiles)`:
//! per output pixel and channel pair, 4 multiply-adds for F(2x2, 3x3) and 2.25 for F(4x4, 3x3),
//! where the direct kernel ([`crate::direct`]) needs 9. F(2x2, 3x3)'s transforms only add and
//! subtract (and halve, for the weight); F(4x4, 3x3)'s scale by 2, 4, 5 and 8 (the points 0, ±1,
//! ±2 and infinity), so its f32 rounding is about ten times F(2x2, 3x3)'s: up to 1e-6 of the sum
//! of the window's magnitudes against 1e-7 (the tests bound both against the direct kernel).
//! For finite inputs well below `f32::MAX` each output depends on exactly the inputs of its
//! 3 x 3 window: a NaN reaches the same outputs as in the direct kernel. An infinite input is
//! another matter: the transforms take differences of neighbours, and `inf - inf` makes NaN where
//! the direct kernel gives an infinity.
//!
//! The work goes by strips of [`STRIP_TILES`] tiles along one row of tiles: the strip's input is
//! transformed into `V[point][channel][tile]`, multiplied by each point's transformed weight
//! with the direct kernel's register tile (output channels by two vectors of tiles), and
//! transformed back into the output, with the bias and the ReLU, while it is in cache. Each row
//! of tiles reads m + 2 padded input rows per channel: they are copied, zero-padded and split by
//! their column modulo m into m *phases* (so that the tiles of a strip, m columns apart, load as
//! whole vectors), into a window of 2m rows per channel that each row of tiles advances by m
//! ([`WinogradLayout::pad_rows`]). The window stays in cache; a padded copy of the whole image
//! did not (reading it back was a fifth of a 224 px pass).

use alloc::vec;
use alloc::vec::Vec;
use core::mem::MaybeUninit;

use crate::direct::{forward_blocks, with_block_rows};
use crate::geometry::ConvGeometry;
use crate::products::Lanes;

mod strips;
use strips::Run;

/// Tiles per strip: two vectors of tiles (AVX2: 2 x 8; WebAssembly SIMD128: 2 x 4), or one of
/// AVX-512's 16.
pub const STRIP_TILES: usize = if cfg!(target_arch = "wasm32") { 8 } else { 16 };

/// Output pixels a side of a tile: Winograd's F(2x2, 3x3) or F(4x4, 3x3), ordered by side
/// ([`WinogradLayout::of`] takes the largest allowed).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Tile {
    /// F(2x2, 3x3): 16 points per 4 output pixels.
    Two,
    /// F(4x4, 3x3): 36 points per 16 output pixels, 44 % fewer products than [`Tile::Two`].
    Four,
}

impl Tile {
    /// Output pixels a side (m).
    pub const fn side(self) -> usize {
        match self {
            Tile::Two => 2,
            Tile::Four => 4,
        }
    }

    /// Points of the transformed domain per tile, (m + 2)².
    pub const fn points(self) -> usize {
        points(self.side())
    }
}

/// Input pixels a side of the patch a tile of side `m` reads.
const fn patch(m: usize) -> usize {
    m + 2
}

/// Points of the transformed domain of a tile of side `m`.
const fn points(m: usize) -> usize {
    patch(m) * patch(m)
}

/// The largest patch side ([`Tile::Four`]), for arrays shared by both tiles.
const MAX_PATCH: usize = patch(4);

/// Where a convolution's zero-padded input rows lie in their window, for the Winograd kernel.
#[derive(Debug, Clone)]
pub struct WinogradLayout {
    /// The tile the kernel uses.
    tile: Tile,
    /// Rows of tiles (output height / m).
    tiles_h: usize,
    /// Tiles per row (output width / m).
    tiles_w: usize,
    /// Strips per row of tiles; the last one may hold fewer than [`STRIP_TILES`] real tiles.
    strips: usize,
    /// Values per phase of a padded row (the columns `p` with `p % m` the same): one more than the
    /// strips' tiles, so that every strip loads whole vectors inside its row.
    phase: usize,
    /// Padded rows per plane (output height + 2).
    rows: usize,
}

impl WinogradLayout {
    /// The layout of `g` with the largest tile up to `largest` that serves it, or `None` when
    /// none does: anything but a stride-1, undilated 3 x 3 kernel, an output that is not a whole
    /// number of tiles, or rows of tiles narrower than one strip (H-Net's small bottleneck
    /// layers, where a strip would be mostly empty).
    pub fn of(g: &ConvGeometry, largest: Tile) -> Option<Self> {
        [Tile::Four, Tile::Two]
            .into_iter()
            .filter(|&tile| tile <= largest)
            .find_map(|tile| Self::of_tile(g, tile))
    }

    /// The layout of `g` with tiles of `tile`, or `None` when they do not serve it.
    pub fn of_tile(g: &ConvGeometry, tile: Tile) -> Option<Self> {
        let m = tile.side();
        let (h, w) = (&g.height, &g.width);
        let served = |a: &crate::geometry::Axis| {
            a.stride == 1 && a.kernel == 3 && a.dilation == 1 && a.output.is_multiple_of(m)
        };
        if !served(h) || !served(w) || w.output / m < STRIP_TILES || h.output == 0 {
            return None;
        }
        let tiles_w = w.output / m;
        let strips = tiles_w.div_ceil(STRIP_TILES);
        Some(Self {
            tile,
            tiles_h: h.output / m,
            tiles_w,
            strips,
            phase: strips * STRIP_TILES + 1,
            rows: h.output + 2,
        })
    }

    /// The tile the kernel uses for this layout.
    pub fn tile(&self) -> Tile {
        self.tile
    }

    /// Values per padded row (every phase).
    fn row(&self) -> usize {
        self.tile.side() * self.phase
    }

    /// Padded rows per channel in the window: the m + 2 a row of tiles reads, padded row `r` in
    /// slot `r % (2m)`.
    fn window_rows(&self) -> usize {
        2 * self.tile.side()
    }

    /// Values per channel in the window.
    fn window_plane(&self) -> usize {
        self.window_rows() * self.row()
    }

    /// Length of the window for one image of `channels` channels.
    pub fn len(&self, channels: usize) -> usize {
        channels * self.window_plane()
    }

    /// Offset in the window of padded row `r` of channel `c`.
    fn window_row(&self, c: usize, r: usize) -> usize {
        c * self.window_plane() + (r % self.window_rows()) * self.row()
    }

    /// Writes padded rows `rows` (at most 2m of them, each below the padded height) of image
    /// `image` (`in_channels` planes of the input) into `window` ([`Self::len`] long): padded row
    /// `r` of channel `c` holds the padded image's columns `0, m, 2m, ...`, then `1, m + 1, ...`,
    /// up to phase `m - 1`, zero outside the image, every value of it written.
    pub fn pad_rows(
        &self,
        g: &ConvGeometry,
        image: &[f32],
        rows: core::ops::Range<usize>,
        window: &mut [f32],
    ) {
        let m = self.tile.side();
        let (in_h, in_w) = (g.height.input, g.width.input);
        let (top, left) = (g.height.padding, g.width.padding.min(self.row()));
        debug_assert_eq!(image.len(), g.in_channels * in_h * in_w);
        debug_assert_eq!(window.len(), self.len(g.in_channels));
        debug_assert!(rows.len() <= self.window_rows() && rows.end <= self.rows);
        // Padded column `p` is image column `p - left`: the groups of padded columns
        // `m k .. m k + m` read image columns `m k - left ..`. `inside` are the groups wholly in
        // the image; the rest are written one by one.
        let first = left.div_ceil(m);
        let inside = first..(in_w + left) / m;
        let inside = inside.start.min(self.phase)..inside.end.clamp(inside.start, self.phase);
        let phase = self.phase;
        for c in 0..g.in_channels {
            let channel = &image[c * in_h * in_w..][..in_h * in_w];
            for r in rows.clone() {
                let at = self.window_row(c, r);
                let padded = &mut window[at..][..m * phase];
                let Some(i) = r.checked_sub(top).filter(|&i| i < in_h) else {
                    padded.fill(0.0);
                    continue;
                };
                let line = &channel[i * in_w..][..in_w];
                let pixel = |p: usize| {
                    p.checked_sub(left)
                        .and_then(|column| line.get(column))
                        .copied()
                        .unwrap_or(0.0)
                };
                for k in (0..inside.start).chain(inside.end..phase) {
                    for j in 0..m {
                        padded[j * phase + k] = pixel(m * k + j);
                    }
                }
                if inside.is_empty() {
                    continue;
                }
                let groups = &line[m * inside.start - left..][..m * inside.len()];
                if m == 2 {
                    let (even, odd) = padded.split_at_mut(phase);
                    for (pair, (even, odd)) in groups.chunks_exact(2).zip(
                        even[inside.clone()]
                            .iter_mut()
                            .zip(&mut odd[inside.clone()]),
                    ) {
                        *even = pair[0];
                        *odd = pair[1];
                    }
                } else {
                    for (k, group) in inside.clone().zip(groups.chunks_exact(m)) {
                        for (j, &value) in group.iter().enumerate() {
                            padded[j * phase + k] = value;
                        }
                    }
                }
            }
        }
    }
}

/// `G v` for the three taps `v` of a kernel's row or column: the first m + 2 values.
fn g_times(m: usize, v: [f32; 3]) -> [f32; MAX_PATCH] {
    if m == 2 {
        // G = [[1, 0, 0], [½, ½, ½], [½, -½, ½], [0, 0, 1]].
        [
            v[0],
            0.5 * (v[0] + v[1] + v[2]),
            0.5 * (v[0] - v[1] + v[2]),
            v[2],
            0.0,
            0.0,
        ]
    } else {
        // G = [[¼, 0, 0], [-⅙, -⅙, -⅙], [-⅙, ⅙, -⅙], [1/24, 1/12, ⅙], [1/24, -1/12, ⅙], [0, 0, 1]].
        let (even, odd) = (v[0] + v[2], v[1]);
        let (quarter, twice) = (v[0] / 24.0 + v[2] / 6.0, v[1] / 12.0);
        [
            v[0] / 4.0,
            -(even + odd) / 6.0,
            -(even - odd) / 6.0,
            quarter + twice,
            quarter - twice,
            v[2],
        ]
    }
}

/// The OIHW weight (`out_channels x in_channels x 3 x 3`) in the transformed domain of `tile`,
/// `U = G g Gᵀ` per channel pair, packed for the products: per point, per block of
/// [`forward_blocks`], per input channel, the block's output channels.
pub fn transform_weight(
    weight: &[f32],
    out_channels: usize,
    in_channels: usize,
    tile: Tile,
) -> Vec<f32> {
    assert_eq!(
        weight.len(),
        out_channels * in_channels * 9,
        "3x3 weight size"
    );
    match tile {
        Tile::Two => transform_weight_for::<2>(weight, out_channels, in_channels),
        Tile::Four => transform_weight_for::<4>(weight, out_channels, in_channels),
    }
}

/// [`transform_weight`] for tiles of side `M`: with the side a constant, each row of `U` is
/// copied in registers (with the side a variable, a call to `memcpy` per row of six values was
/// 7 % of a 64 px pass, `perf`).
fn transform_weight_for<const M: usize>(
    weight: &[f32],
    out_channels: usize,
    in_channels: usize,
) -> Vec<f32> {
    let (points, side) = (points(M), patch(M));
    // U per (output, input) channel pair, `points` each.
    let mut transformed = vec![0.0f32; out_channels * in_channels * points];
    for (kernel, u) in weight
        .chunks_exact(9)
        .zip(transformed.chunks_exact_mut(points))
    {
        // G g: (m + 2) x 3, column by column.
        let columns: [[f32; MAX_PATCH]; 3] =
            core::array::from_fn(|j| g_times(M, [kernel[j], kernel[3 + j], kernel[6 + j]]));
        for (a, u) in u.chunks_exact_mut(side).enumerate() {
            let row = g_times(M, [columns[0][a], columns[1][a], columns[2][a]]);
            u.copy_from_slice(&row[..side]);
        }
    }
    let mut packed = Vec::with_capacity(transformed.len());
    for point in 0..points {
        for (first, channels) in forward_blocks(out_channels) {
            for c in 0..in_channels {
                packed.extend(
                    (first..first + channels)
                        .map(|o| transformed[(o * in_channels + c) * points + point]),
                );
            }
        }
    }
    packed
}

/// One image's forward convolution `y = W ⋆ x (+ b)`, NCHW, followed by a ReLU when `relu`, from
/// the image `image` (`in_channels` planes), with `window` ([`WinogradLayout::len`] values,
/// overwritten) for its padded rows, and the weight transformed by [`transform_weight`] for the
/// layout's tile. Every element of `y` (`out_channels x output plane`) is written.
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
    let m = layout.tile.side();
    assert!(
        window.len() == layout.len(g.in_channels)
            && image.len() == g.in_channels * g.input_plane()
            && weight.len() == g.out_channels * g.in_channels * layout.tile.points()
            && y.len() == g.out_channels * g.output_plane()
            && bias.is_none_or(|b| b.len() == g.out_channels)
            && layout.tiles_w * m == g.width.output
            && layout.tiles_h * m == g.height.output,
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
    match layout.tile {
        // SAFETY: `strips_for_this_cpu`'s contract is the dispatch below.
        Tile::Two => unsafe { run.strips_for_this_cpu::<2>(window, y) },
        Tile::Four => unsafe { run.strips_for_this_cpu::<4>(window, y) },
    }
}

/// The three phases of a strip of tiles of side `M`, for one instruction set.
///
/// # Safety
///
/// Every method may only be called on a CPU that has the implementation's instruction set.
trait Phases {
    unsafe fn transform_input<const M: usize>(
        run: &Run,
        window: &[f32],
        tile_row: usize,
        first_tile: usize,
        out: &mut [f32],
    );
    unsafe fn multiply<const M: usize>(run: &Run, transformed: &[f32], products: &mut [f32]);
    unsafe fn transform_output<const M: usize>(
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
    unsafe fn transform_input<const M: usize>(
        run: &Run,
        window: &[f32],
        tile_row: usize,
        first_tile: usize,
        out: &mut [f32],
    ) {
        run.transform_input::<L, V, M>(window, tile_row, first_tile, out);
    }
    unsafe fn multiply<const M: usize>(run: &Run, transformed: &[f32], products: &mut [f32]) {
        run.multiply::<L, V, M>(transformed, products);
    }
    unsafe fn transform_output<const M: usize>(
        run: &Run,
        tile_row: usize,
        first_tile: usize,
        products: &[f32],
        y: &mut [MaybeUninit<f32>],
    ) {
        run.transform_output::<L, V, M>(tile_row, first_tile, products, y);
    }
}

/// A module `$module` with `$phases`, the three phases over `$vectors` vectors of lanes `$lanes`
/// per strip, each compiled with `$features` on its own: inlined into one function, the compiler left the vector intrinsics as
/// calls (a third of the time in `perf`, AVX2). One definition for every instruction set that needs
/// its features enabled per function.
#[cfg(any(
    target_arch = "x86_64",
    all(target_arch = "wasm32", feature = "relaxed-simd")
))]
macro_rules! phases_compiled_for {
    ($(#[$doc:meta])* $module:ident, $phases:ident, $lanes:path, $vectors:literal, $features:literal) => {
        mod $module {
            use core::mem::MaybeUninit;

            use super::Run;

            $(#[$doc])*
            pub(super) struct $phases;

            // `unsafe` calls: a target-feature function is unsafe to call on x86-64 and safe on
            // wasm32 (where the module would not compile without the features).
            #[allow(unused_unsafe)]
            impl super::Phases for $phases {
                unsafe fn transform_input<const M: usize>(
                    run: &Run,
                    window: &[f32],
                    tile_row: usize,
                    first_tile: usize,
                    out: &mut [f32],
                ) {
                    // SAFETY: this CPU has the features (the trait's contract).
                    unsafe { transform_input::<M>(run, window, tile_row, first_tile, out) }
                }
                unsafe fn multiply<const M: usize>(
                    run: &Run,
                    transformed: &[f32],
                    products: &mut [f32],
                ) {
                    // SAFETY: as above.
                    unsafe { multiply::<M>(run, transformed, products) }
                }
                unsafe fn transform_output<const M: usize>(
                    run: &Run,
                    tile_row: usize,
                    first_tile: usize,
                    products: &[f32],
                    y: &mut [MaybeUninit<f32>],
                ) {
                    // SAFETY: as above.
                    unsafe { transform_output::<M>(run, tile_row, first_tile, products, y) }
                }
            }

            #[target_feature(enable = $features)]
            fn transform_input<const M: usize>(
                run: &Run,
                window: &[f32],
                tile_row: usize,
                first_tile: usize,
                out: &mut [f32],
            ) {
                run.transform_input::<$lanes, $vectors, M>(window, tile_row, first_tile, out);
            }

            #[target_feature(enable = $features)]
            fn multiply<const M: usize>(run: &Run, transformed: &[f32], products: &mut [f32]) {
                run.multiply::<$lanes, $vectors, M>(transformed, products);
            }

            #[target_feature(enable = $features)]
            fn transform_output<const M: usize>(
                run: &Run,
                tile_row: usize,
                first_tile: usize,
                products: &[f32],
                y: &mut [MaybeUninit<f32>],
            ) {
                run.transform_output::<$lanes, $vectors, M>(tile_row, first_tile, products, y);
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
    2,
    "avx2,fma"
);

#[cfg(target_arch = "x86_64")]
phases_compiled_for!(
    /// The phases for AVX-512F, one vector a strip (the trait's contract: only on CPUs that have
    /// it).
    avx512,
    Avx512Phases,
    crate::products::avx512::Avx512,
    1,
    "avx512f,avx2,fma"
);

// The crate's `relaxed-simd` feature: relaxed SIMD's fused multiply-adds.
#[cfg(all(target_arch = "wasm32", feature = "relaxed-simd"))]
phases_compiled_for!(
    /// The phases for SIMD128 with relaxed SIMD (the trait's contract: only in a module the
    /// browser compiled, which it does only where it has relaxed SIMD).
    fused,
    FusedPhases,
    crate::products::simd128::FusedSimd128,
    2,
    "simd128,relaxed-simd"
);

/// Values between consecutive points of the transformed input: one strip row more than the
/// channels need, so that the points of one channel (written together by the input transform)
/// do not fall into the same cache set, as they would a power of two apart.
fn point_stride(in_channels: usize) -> usize {
    (in_channels + 1) * STRIP_TILES
}

/// `Bᵀ d` for the m + 2 values `d` of a patch's row or column (the first m + 2 of each array).
#[inline(always)]
fn input_transform<L: Lanes, const M: usize>(d: [L; MAX_PATCH]) -> [L; MAX_PATCH] {
    if M == 2 {
        // Bᵀ = [[1, 0, -1, 0], [0, 1, 1, 0], [0, -1, 1, 0], [0, 1, 0, -1]].
        let z = L::zero();
        [
            d[0].sub(d[2]),
            d[1].add(d[2]),
            d[2].sub(d[1]),
            d[1].sub(d[3]),
            z,
            z,
        ]
    } else {
        // Bᵀ = [[4, 0, -5, 0, 1, 0], [0, -4, -4, 1, 1, 0], [0, 4, -4, -1, 1, 0],
        //       [0, -2, -1, 2, 1, 0], [0, 2, -1, -2, 1, 0], [0, 4, 0, -5, 0, 1]].
        let (four, minus_four, minus_five) = (L::splat(4.0), L::splat(-4.0), L::splat(-5.0));
        let a = d[4].multiply_add(minus_four, d[2]);
        let b = d[3].multiply_add(minus_four, d[1]);
        let c = d[4].sub(d[2]);
        let e = d[3].sub(d[1]);
        let e = e.add(e);
        [
            d[4].multiply_add(minus_five, d[2]).multiply_add(four, d[0]),
            a.add(b),
            a.sub(b),
            c.add(e),
            c.sub(e),
            d[5].multiply_add(minus_five, d[3]).multiply_add(four, d[1]),
        ]
    }
}

/// `Aᵀ t` for the m + 2 values `t` of a row or column of the products: m outputs (the first m).
#[inline(always)]
fn output_transform<L: Lanes, const M: usize>(t: &[L; MAX_PATCH]) -> [L; 4] {
    if M == 2 {
        // Aᵀ = [[1, 1, 1, 0], [0, 1, -1, -1]].
        let z = L::zero();
        [t[0].add(t[1]).add(t[2]), t[1].sub(t[2]).sub(t[3]), z, z]
    } else {
        // Aᵀ = [[1, 1, 1, 1, 1, 0], [0, 1, -1, 2, -2, 0], [0, 1, 1, 4, 4, 0],
        //       [0, 1, -1, 8, -8, 1]].
        let (sum12, difference12) = (t[1].add(t[2]), t[1].sub(t[2]));
        let (sum34, difference34) = (t[3].add(t[4]), t[3].sub(t[4]));
        [
            t[0].add(sum12).add(sum34),
            difference12.multiply_add(L::splat(2.0), difference34),
            sum12.multiply_add(L::splat(4.0), sum34),
            difference12
                .multiply_add(L::splat(8.0), difference34)
                .add(t[5]),
        ]
    }
}

/// The first `M` vectors of `columns` (column `j` of `WIDTH` tiles side by side) with their lanes
/// alternated, `(c0[0], c1[0], .., c0[1], c1[1], ..)`: one output row of `WIDTH` tiles in order.
#[inline(always)]
fn interleave_tiles<L: Lanes, const M: usize>(columns: [L; 4]) -> [L; 4] {
    if M == 2 {
        let (first, second) = columns[0].interleave(columns[1]);
        [first, second, L::zero(), L::zero()]
    } else {
        let (low02, high02) = columns[0].interleave(columns[2]);
        let (low13, high13) = columns[1].interleave(columns[3]);
        let (q0, q1) = low02.interleave(low13);
        let (q2, q3) = high02.interleave(high13);
        [q0, q1, q2, q3]
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
/// `row` values apart.
#[inline(always)]
fn block_product<L: Lanes, const V: usize, const R: usize>(
    panel: &[f32],
    input: &[f32],
    out: &mut [f32],
    row: usize,
) {
    const { assert!(V * L::WIDTH == STRIP_TILES, "a strip is V vectors") };
    let steps = input.len() / STRIP_TILES;
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

    /// Which phases compute a test's convolution.
    #[derive(Debug, Clone, Copy, PartialEq)]
    enum Path {
        /// `forward_image`'s: the best this machine has.
        Best,
        /// AVX2's, where this machine has it (its best may be AVX-512's).
        #[cfg(target_arch = "x86_64")]
        Avx2,
        /// The portable f32 lanes.
        Portable,
    }

    /// The paths this machine can run.
    fn paths() -> Vec<Path> {
        let mut paths = vec![Path::Best, Path::Portable];
        #[cfg(target_arch = "x86_64")]
        if crate::products::has_avx2() {
            paths.push(Path::Avx2);
        }
        paths
    }

    /// The Winograd kernel's result for the same convolution with tiles of `tile`, by `path`.
    fn winograd_forward(
        g: &ConvGeometry,
        x: &[f32],
        w: &[f32],
        bias: Option<&[f32]>,
        relu: bool,
        tile: Tile,
        path: Path,
    ) -> Vec<f32> {
        let layout = WinogradLayout::of_tile(g, tile).unwrap();
        // NaN where the pad writes nothing: a read outside the padded rows would show.
        let mut window = vec![f32::NAN; layout.len(g.in_channels)];
        let weight = transform_weight(w, g.out_channels, g.in_channels, tile);
        let mut y = vec![MaybeUninit::uninit(); g.out_channels * g.output_plane()];
        let run = Run {
            g,
            layout: &layout,
            image: x,
            weight: &weight,
            bias,
            relu,
        };
        // SAFETY: the portable lanes need no instruction set, and AVX2's path is only taken
        // where this CPU has it ([`paths`]); the sides are the layout's.
        unsafe {
            match (path, tile) {
                (Path::Best, _) => {
                    forward_image(g, &layout, x, &mut window, &weight, bias, relu, &mut y)
                }
                (Path::Portable, Tile::Two) => {
                    run.strips::<Generic<f32, STRIP_TILES>, 2>(&mut window, &mut y)
                }
                (Path::Portable, Tile::Four) => {
                    run.strips::<Generic<f32, STRIP_TILES>, 4>(&mut window, &mut y)
                }
                #[cfg(target_arch = "x86_64")]
                (Path::Avx2, Tile::Two) => run.strips::<avx2::Avx2Phases, 2>(&mut window, &mut y),
                #[cfg(target_arch = "x86_64")]
                (Path::Avx2, Tile::Four) => run.strips::<avx2::Avx2Phases, 4>(&mut window, &mut y),
            }
        }
        y.into_iter().map(|v| unsafe { v.assume_init() }).collect()
    }

    /// Both tiles, by the SIMD path this machine runs (AVX-512, AVX2, SIMD128), by AVX2's where
    /// that is not it, and by the portable one, agree with the direct kernel, over paddings of 0, 1 and 2, a partial last strip and channel counts that
    /// leave uneven register tiles (one-sided paddings: `tests/against_burn.rs`). F(4x4, 3x3)'s
    /// transforms scale by up to 8: its rounding is bounded at 2e-6 of the sum of the window's
    /// magnitudes (at most `9 · in_channels` here), F(2x2, 3x3)'s at 1e-7.
    #[test]
    fn winograd_matches_the_direct_kernel() {
        use burn::tensor::ops::ConvOptions;
        for (size, padding, channels) in [
            ([6, 34], [1, 1], (5, 7)),
            ([10, 2 * STRIP_TILES + 2], [0, 0], (3, 13)),
            ([4, 2 * STRIP_TILES + 20], [2, 2], (8, 32)),
            ([8, 4 * STRIP_TILES + 4], [1, 1], (5, 7)),
            ([10, 4 * STRIP_TILES + 2], [0, 0], (3, 13)),
            ([6, 8 * STRIP_TILES - 2], [2, 2], (32, 8)),
        ] {
            let (cin, cout) = channels;
            let options = ConvOptions::new([1, 1], padding, [1, 1], 1);
            let g =
                ConvGeometry::of_conv2d([1, cin, size[0], size[1]], [cout, cin, 3, 3], &options)
                    .unwrap();
            let x = values(cin * size[0] * size[1], 1);
            let w = values(cout * cin * 9, 2);
            let bias = values(cout, 3);
            let scale = (9 * cin) as f32;
            for (tile, bound) in [(Tile::Two, 1e-7), (Tile::Four, 2e-6)] {
                if WinogradLayout::of_tile(&g, tile).is_none() {
                    continue;
                }
                for relu in [false, true] {
                    let expected = direct_forward(&g, &x, &w, Some(&bias), relu);
                    for path in paths() {
                        let ours = winograd_forward(&g, &x, &w, Some(&bias), relu, tile, path);
                        let error = ours
                            .iter()
                            .zip(&expected)
                            .map(|(a, b)| (a - b).abs())
                            .fold(0.0f32, f32::max);
                        assert!(
                            error < bound * scale,
                            "{tile:?} {path:?} {size:?} {padding:?}: {error:e}"
                        );
                    }
                }
            }
        }
    }

    /// Shapes the kernel does not serve get no layout; F(4x4, 3x3) where it serves, else
    /// F(2x2, 3x3).
    #[test]
    fn only_stride_1_undilated_3x3_with_outputs_of_whole_tiles() {
        use burn::tensor::ops::ConvOptions;
        let wide = 2 * STRIP_TILES;
        let tile = |size: [usize; 2], kernel: usize, stride: usize, dilation: usize| {
            let options = ConvOptions::new([stride; 2], [kernel / 2; 2], [dilation; 2], 1);
            let g =
                ConvGeometry::of_conv2d([1, 2, size[0], size[1]], [2, 2, kernel, kernel], &options)
                    .unwrap();
            WinogradLayout::of(&g, Tile::Four).map(|layout| layout.tile())
        };
        assert_eq!(
            tile([8, wide], 3, 1, 1),
            Some(Tile::Two),
            "a strip of 2x2 tiles"
        );
        assert_eq!(tile([8, 2 * wide], 3, 1, 1), Some(Tile::Four));
        assert_eq!(tile([6, 2 * wide], 3, 1, 1), Some(Tile::Two), "6 rows");
        assert_eq!(tile([7, wide], 3, 1, 1), None, "odd height");
        assert_eq!(tile([8, wide + 1], 3, 1, 1), None, "odd width");
        assert_eq!(tile([8, wide - 2], 3, 1, 1), None, "narrower than a strip");
        assert_eq!(tile([8, wide], 3, 2, 1), None, "stride 2");
        assert_eq!(tile([8, wide], 5, 1, 1), None, "5x5");
        assert_eq!(tile([8, wide], 3, 1, 2), None, "dilated");
        let options = ConvOptions::new([1, 1], [1, 1], [1, 1], 1);
        let g = ConvGeometry::of_conv2d([1, 2, 8, 2 * wide], [2, 2, 3, 3], &options).unwrap();
        assert_eq!(
            WinogradLayout::of(&g, Tile::Two).map(|layout| layout.tile()),
            Some(Tile::Two),
            "the largest tile allowed"
        );
    }
}
