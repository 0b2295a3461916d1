//! One call of [`super::forward_image`]: its strips of tiles, each transformed in, multiplied
//! and transformed back while in cache, on the best instruction set the CPU (or module) has.

use super::*;

/// One call of [`forward_image`].
pub(super) struct Run<'a> {
    pub(super) g: &'a ConvGeometry,
    pub(super) layout: &'a WinogradLayout,
    pub(super) image: &'a [f32],
    pub(super) weight: &'a [f32],
    pub(super) bias: Option<&'a [f32]>,
    pub(super) relu: bool,
}

impl Run<'_> {
    /// [`Self::strips`] with the phases of the best instruction set this CPU (or module) has.
    ///
    /// # Safety
    ///
    /// `M` is the layout's tile side.
    pub(super) unsafe fn strips_for_this_cpu<const M: usize>(
        &self,
        window: &mut [f32],
        y: &mut [MaybeUninit<f32>],
    ) {
        debug_assert_eq!(M, self.layout.tile.side());
        #[cfg(target_arch = "x86_64")]
        if crate::products::has_avx512() {
            // SAFETY: this CPU has AVX-512F, AVX2 and FMA.
            return unsafe { self.strips::<avx512::Avx512Phases, M>(window, y) };
        }
        #[cfg(target_arch = "x86_64")]
        if crate::products::has_avx2() {
            // SAFETY: this CPU has AVX2 and FMA.
            return unsafe { self.strips::<avx2::Avx2Phases, M>(window, y) };
        }
        #[cfg(all(target_arch = "wasm32", feature = "relaxed-simd"))]
        // SAFETY: a module built with `relaxed-simd` only compiles where the browser has it.
        return unsafe { self.strips::<fused::FusedPhases, M>(window, y) };
        #[cfg(all(target_arch = "wasm32", not(feature = "relaxed-simd")))]
        // SAFETY: wasm32 builds enable SIMD128 for the whole crate (.cargo/config.toml).
        return unsafe {
            self.strips::<Generic<crate::products::simd128::Simd128, 2>, M>(window, y)
        };
        #[allow(unreachable_code)]
        // SAFETY: the portable lanes need no instruction set.
        unsafe {
            self.strips::<Generic<f32, STRIP_TILES>, M>(window, y)
        }
    }

    /// Every strip: input transform, products, output transform.
    ///
    /// # Safety
    ///
    /// This CPU has `P`'s instruction set ([`Phases`]), and `M` is the layout's tile side.
    pub(super) unsafe fn strips<P: Phases, const M: usize>(
        &self,
        window: &mut [f32],
        y: &mut [MaybeUninit<f32>],
    ) {
        let (cin, cout) = (self.g.in_channels, self.g.out_channels);
        let mut transformed = vec![0.0f32; points(M) * point_stride(cin)];
        let mut products = vec![0.0f32; cout * points(M) * STRIP_TILES];
        for tile_row in 0..self.layout.tiles_h {
            // Padded rows `m · tile_row .. + m + 2`; the first two are in the window already but
            // for the first row of tiles.
            let rows = if tile_row == 0 {
                0..patch(M)
            } else {
                M * tile_row + 2..M * tile_row + patch(M)
            };
            self.layout.pad_rows(self.g, self.image, rows, window);
            self.prefetch_next::<M>(tile_row + 1, y);
            for strip in 0..self.layout.strips {
                let first_tile = strip * STRIP_TILES;
                // SAFETY: the caller's promise ([`Self::strips`]).
                unsafe {
                    P::transform_input::<M>(self, window, tile_row, first_tile, &mut transformed);
                    P::multiply::<M>(self, &transformed, &mut products);
                    P::transform_output::<M>(self, tile_row, first_tile, &products, y);
                }
            }
        }
    }

    /// Asks the cache for what row of tiles `tile_row` will read and write, one row of tiles
    /// ahead: its m new image rows of every input channel and its m output rows of every output
    /// channel. Spread over a channel each, these are too many streams for the hardware's
    /// prefetcher, and their misses were most of the padding's and the output's time.
    /// Nothing when the image and its output fit in 1 MiB ([`PREFETCH_MIN_VALUES`]).
    pub(super) fn prefetch_next<const M: usize>(&self, tile_row: usize, y: &[MaybeUninit<f32>]) {
        if tile_row >= self.layout.tiles_h || self.image.len() + y.len() < PREFETCH_MIN_VALUES {
            return;
        }
        let g = self.g;
        let (in_h, in_w) = (g.height.input, g.width.input);
        let (out_w, out_plane) = (g.width.output, g.output_plane());
        for padded_row in M * tile_row + 2..M * tile_row + patch(M) {
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
                &y[o * out_plane + M * tile_row * out_w..][..M * out_w],
                true,
            );
        }
    }

    /// `V[point][channel][tile] = (Bᵀ d B)[point]` for the strip's tiles, every input channel;
    /// the points [`point_stride`] apart.
    #[inline(always)]
    pub(super) fn transform_input<L: Lanes, const V: usize, const M: usize>(
        &self,
        window: &[f32],
        tile_row: usize,
        first_tile: usize,
        out: &mut [f32],
    ) {
        const { assert!(V * L::WIDTH == STRIP_TILES, "a strip is V vectors") };
        let layout = self.layout;
        let phase = layout.phase;
        let cin = self.g.in_channels;
        let stride = point_stride(cin);
        debug_assert_eq!(out.len(), points(M) * stride);
        // Each strip reads values `first_tile ..= first_tile + STRIP_TILES` of every phase of
        // m + 2 rows: inside each row (`phase = strips · STRIP_TILES + 1`).
        let row_len = (M - 1) * phase + STRIP_TILES + 1;
        for c in 0..cin {
            for v in 0..V {
                let at = v * L::WIDTH;
                // Bᵀ on each row: patch column `j` of the strip's tiles is phase `j % m` from
                // tile `j / m` on.
                let mut w = [[L::zero(); MAX_PATCH]; MAX_PATCH];
                for (r, w) in w.iter_mut().enumerate().take(patch(M)) {
                    let start = layout.window_row(c, M * tile_row + r) + first_tile;
                    let line = window[start..][..row_len].as_ptr();
                    let mut d = [L::zero(); MAX_PATCH];
                    for (j, d) in d.iter_mut().enumerate().take(patch(M)) {
                        // SAFETY: `(j % m) · phase + at + j / m + WIDTH <= (m - 1) · phase +
                        // STRIP_TILES + 1`, so every load lies in `line`.
                        *d = unsafe { L::load(line.add((j % M) * phase + at + j / M)) };
                    }
                    *w = input_transform::<L, M>(d);
                }
                // Then on each column.
                for k in 0..patch(M) {
                    let mut column = [L::zero(); MAX_PATCH];
                    for (value, w) in column.iter_mut().zip(&w).take(patch(M)) {
                        *value = w[k];
                    }
                    let column = input_transform::<L, M>(column);
                    for (i, value) in column.into_iter().enumerate().take(patch(M)) {
                        let to = &mut out[(i * patch(M) + k) * stride + c * STRIP_TILES + at..]
                            [..L::WIDTH];
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
    pub(super) fn multiply<L: Lanes, const V: usize, const M: usize>(
        &self,
        transformed: &[f32],
        products: &mut [f32],
    ) {
        const { assert!(V * L::WIDTH == STRIP_TILES, "a strip is V vectors") };
        let (cin, cout) = (self.g.in_channels, self.g.out_channels);
        let row = points(M) * STRIP_TILES;
        for point in 0..points(M) {
            let input = &transformed[point * point_stride(cin)..][..cin * STRIP_TILES];
            let weight = &self.weight[point * cout * cin..][..cout * cin];
            for (first, channels) in forward_blocks(cout) {
                let panel = &weight[first * cin..][..channels * cin];
                let out = &mut products[(first * points(M) + point) * STRIP_TILES..];
                with_block_rows!(channels, R => block_product::<L, V, R>(panel, input, out, row));
            }
        }
    }

    /// `Y = Aᵀ M A (+ b)`, then the ReLU, for every output channel of the strip, stored in `y`.
    #[inline(always)]
    pub(super) fn transform_output<L: Lanes, const V: usize, const M: usize>(
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
        // A partial strip's m output rows of one channel.
        let mut lines = [[0.0f32; 4 * STRIP_TILES]; 4];
        for o in 0..cout {
            let plane = y[o * out_plane..][..out_plane].as_mut_ptr().cast::<f32>();
            let b = L::splat(self.bias.map_or(0.0, |bias| bias[o]));
            for v in 0..V {
                let at = v * L::WIDTH;
                // Aᵀ on each row of the products (its m + 2 points), then on each column. No
                // closures here (`array::from_fn`): the vector operations inside them were left
                // as calls.
                let mut t = [[L::zero(); 4]; MAX_PATCH];
                for (i, t) in t.iter_mut().enumerate().take(patch(M)) {
                    let mut row = [L::zero(); MAX_PATCH];
                    for (k, value) in row.iter_mut().enumerate().take(patch(M)) {
                        let point = i * patch(M) + k;
                        let from =
                            &products[(o * points(M) + point) * STRIP_TILES + at..][..L::WIDTH];
                        // SAFETY: `from` holds WIDTH values.
                        *value = unsafe { L::load(from.as_ptr()) };
                    }
                    *t = output_transform::<L, M>(&row);
                }
                // `outputs[r][j]`: output row `r`, column `j` of each tile.
                let mut outputs = [[L::zero(); 4]; 4];
                for j in 0..M {
                    let mut column = [L::zero(); MAX_PATCH];
                    for (value, t) in column.iter_mut().zip(&t).take(patch(M)) {
                        *value = t[j];
                    }
                    let column = output_transform::<L, M>(&column);
                    for (r, value) in column.into_iter().enumerate().take(M) {
                        let value = value.add(b);
                        outputs[r][j] = if self.relu { value.relu() } else { value };
                    }
                }
                // Each output row of the strip: its tiles' pixels in order, stored straight
                // into the channel's plane when the strip is whole (the copy through `lines` was
                // a tenth of a 224 px pass), else through `lines`.
                for (r, columns) in outputs.into_iter().enumerate().take(M) {
                    let to = if whole {
                        // SAFETY: a whole strip's row holds `m · STRIP_TILES` values from
                        // `m · first_tile`, inside the output row (`m · tiles_w = out_w`), and
                        // `m · at + m · WIDTH` is at most `m · STRIP_TILES`; `MaybeUninit<f32>`
                        // has `f32`'s layout, and a store initialises.
                        unsafe { plane.add((M * tile_row + r) * out_w + M * first_tile) }
                    } else {
                        lines[r].as_mut_ptr()
                    };
                    for (q, value) in interleave_tiles::<L, M>(columns)
                        .into_iter()
                        .enumerate()
                        .take(M)
                    {
                        // SAFETY: `to` holds `m · STRIP_TILES` values (above, or `lines`).
                        unsafe { value.store(to.add(M * at + q * L::WIDTH)) };
                    }
                }
            }
            if !whole {
                let plane = &mut y[o * out_plane..][..out_plane];
                for (r, line) in lines.iter().enumerate().take(M) {
                    let out =
                        &mut plane[(M * tile_row + r) * out_w + M * first_tile..][..M * tiles];
                    for (out, &value) in out.iter_mut().zip(line) {
                        out.write(value);
                    }
                }
            }
        }
    }
}
