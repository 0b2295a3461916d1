//! The matrix products of a convolution:
//!
//! - [`broadcast_product`], the forward pass: `C (m x n) = A · B` with `B` row-major (`k x n`,
//!   rows along the pixels) and `A` small (the weight, packed once per call). A register-blocked
//!   micro-kernel broadcasts a few elements of `A` against a strip of `B`'s columns, copied
//!   contiguous first (its rows are a whole image apart, which would make them collide in the same
//!   cache sets).
//! - [`gemm_product`], the input and weight gradients: the `gemm` crate (the one flex's own
//!   matmul uses). Which product serves which pass was chosen from timings during development
//!   (docs/benchmarks.md, "The project's convolution kernels"); `hnet bench layers` shows the
//!   result layer by layer.
//!
//! Each product is one body written over a small vector type ([`Lanes`]): AVX2 with FMA on
//! x86-64 (chosen at run time), SIMD128 on wasm32, one value at a time elsewhere.

/// The vector operations the micro-kernels use, for one instruction set.
///
/// # Safety
/// Implementations use target-specific instructions: call them only where the target has them
/// (the `*_avx2` entry points are only called after run-time detection).
pub(crate) trait Lanes: Copy {
    /// `f32` values per vector.
    const WIDTH: usize;
    fn zero() -> Self;
    fn splat(x: f32) -> Self;
    /// Loads `WIDTH` values from `from`.
    ///
    /// # Safety
    /// `from .. from + WIDTH` must be readable.
    unsafe fn load(from: *const f32) -> Self;
    /// `N` consecutive vectors from `from` (`N · WIDTH` values). A loop, not `array::from_fn`:
    /// inside its closure the compiler left the load intrinsic as a call (`perf`, AVX2).
    ///
    /// # Safety
    /// `from .. from + N · WIDTH` must be readable.
    #[inline(always)]
    unsafe fn load_vectors<const N: usize>(from: *const f32) -> [Self; N] {
        let mut vectors = [Self::zero(); N];
        for (v, vector) in vectors.iter_mut().enumerate() {
            // SAFETY: inside the `N · WIDTH` readable values (the caller's guarantee).
            *vector = unsafe { Self::load(from.add(v * Self::WIDTH)) };
        }
        vectors
    }
    /// Stores `WIDTH` values at `to`.
    ///
    /// # Safety
    /// `to .. to + WIDTH` must be writable.
    unsafe fn store(self, to: *mut f32);
    /// `self + a * b`.
    fn multiply_add(self, a: Self, b: Self) -> Self;
    /// `self + other`, lane by lane.
    fn add(self, other: Self) -> Self;
    /// `self - other`, lane by lane.
    fn sub(self, other: Self) -> Self;
    /// The lanes of `self` and `other` alternated, `(s0, o0, s1, o1, ...)`, as two vectors.
    fn interleave(self, other: Self) -> (Self, Self);
    /// The larger of each lane and zero (ReLU); NaN stays NaN, as in Burn's and PyTorch's ReLU
    /// (a diverged network must not look finite).
    fn relu(self) -> Self;
}

/// One value: the portable fallback (compilers vectorise some of it).
impl Lanes for f32 {
    const WIDTH: usize = 1;
    #[inline(always)]
    fn zero() -> Self {
        0.0
    }
    #[inline(always)]
    fn splat(x: f32) -> Self {
        x
    }
    #[inline(always)]
    unsafe fn load(from: *const f32) -> Self {
        // SAFETY: the caller guarantees one readable value.
        unsafe { *from }
    }
    #[inline(always)]
    unsafe fn store(self, to: *mut f32) {
        // SAFETY: the caller guarantees one writable value.
        unsafe { *to = self }
    }
    #[inline(always)]
    fn multiply_add(self, a: Self, b: Self) -> Self {
        self + a * b
    }
    #[inline(always)]
    fn add(self, other: Self) -> Self {
        self + other
    }
    #[inline(always)]
    fn sub(self, other: Self) -> Self {
        self - other
    }
    #[inline(always)]
    fn interleave(self, other: Self) -> (Self, Self) {
        (self, other)
    }
    #[inline(always)]
    fn relu(self) -> Self {
        if self.is_nan() || self > 0.0 {
            self
        } else {
            0.0
        }
    }
}

#[cfg(target_arch = "x86_64")]
pub(crate) mod avx2 {
    use core::arch::x86_64::*;

    /// Eight lanes of AVX, with FMA.
    #[derive(Clone, Copy)]
    pub struct Avx2(__m256);

    impl super::Lanes for Avx2 {
        const WIDTH: usize = 8;
        #[inline(always)]
        fn zero() -> Self {
            // SAFETY (all methods): only reached from `#[target_feature(enable = "avx2,fma")]`
            // functions called after run-time detection; loads and stores check their slices.
            Self(unsafe { _mm256_setzero_ps() })
        }
        #[inline(always)]
        fn splat(x: f32) -> Self {
            Self(unsafe { _mm256_set1_ps(x) })
        }
        #[inline(always)]
        unsafe fn load(from: *const f32) -> Self {
            Self(unsafe { _mm256_loadu_ps(from) })
        }
        #[inline(always)]
        unsafe fn store(self, to: *mut f32) {
            unsafe { _mm256_storeu_ps(to, self.0) }
        }
        #[inline(always)]
        fn multiply_add(self, a: Self, b: Self) -> Self {
            Self(unsafe { _mm256_fmadd_ps(a.0, b.0, self.0) })
        }
        #[inline(always)]
        fn add(self, other: Self) -> Self {
            Self(unsafe { _mm256_add_ps(self.0, other.0) })
        }
        #[inline(always)]
        fn sub(self, other: Self) -> Self {
            Self(unsafe { _mm256_sub_ps(self.0, other.0) })
        }
        #[inline(always)]
        fn interleave(self, other: Self) -> (Self, Self) {
            // unpack interleaves within each 128-bit half; the permutes put the halves in order.
            unsafe {
                let low = _mm256_unpacklo_ps(self.0, other.0);
                let high = _mm256_unpackhi_ps(self.0, other.0);
                (
                    Self(_mm256_permute2f128_ps::<0x20>(low, high)),
                    Self(_mm256_permute2f128_ps::<0x31>(low, high)),
                )
            }
        }
        #[inline(always)]
        fn relu(self) -> Self {
            // maxps returns its second operand when either is NaN: NaN propagates.
            Self(unsafe { _mm256_max_ps(_mm256_setzero_ps(), self.0) })
        }
    }
}

/// Sixteen lanes of AVX-512 (the Winograd kernel's products and transforms, on CPUs that have
/// it: its 512-bit multiply-adds take a strip's 16 tiles in one instruction where AVX2 takes two).
#[cfg(target_arch = "x86_64")]
pub(crate) mod avx512 {
    use core::arch::x86_64::*;

    /// Sixteen lanes of AVX-512F.
    #[derive(Clone, Copy)]
    pub struct Avx512(__m512);

    /// Lane indices of `_mm512_permutex2var_ps` that alternate two vectors' first halves
    /// (`0..8` of the first, `16..24` the second's), then their second halves.
    const LOW: [i32; 16] = [0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23];
    const HIGH: [i32; 16] = [8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31];

    impl super::Lanes for Avx512 {
        const WIDTH: usize = 16;
        #[inline(always)]
        fn zero() -> Self {
            // SAFETY (all methods): only reached from `#[target_feature(enable = "avx512f")]`
            // functions called after run-time detection; loads and stores check their slices.
            Self(unsafe { _mm512_setzero_ps() })
        }
        #[inline(always)]
        fn splat(x: f32) -> Self {
            Self(unsafe { _mm512_set1_ps(x) })
        }
        #[inline(always)]
        unsafe fn load(from: *const f32) -> Self {
            Self(unsafe { _mm512_loadu_ps(from) })
        }
        #[inline(always)]
        unsafe fn store(self, to: *mut f32) {
            unsafe { _mm512_storeu_ps(to, self.0) }
        }
        #[inline(always)]
        fn multiply_add(self, a: Self, b: Self) -> Self {
            Self(unsafe { _mm512_fmadd_ps(a.0, b.0, self.0) })
        }
        #[inline(always)]
        fn add(self, other: Self) -> Self {
            Self(unsafe { _mm512_add_ps(self.0, other.0) })
        }
        #[inline(always)]
        fn sub(self, other: Self) -> Self {
            Self(unsafe { _mm512_sub_ps(self.0, other.0) })
        }
        #[inline(always)]
        fn interleave(self, other: Self) -> (Self, Self) {
            // SAFETY: `[i32; 16]` and `__m512i` have the same size, and every bit pattern is valid.
            unsafe {
                let (low, high) = (
                    core::mem::transmute::<[i32; 16], __m512i>(LOW),
                    core::mem::transmute::<[i32; 16], __m512i>(HIGH),
                );
                (
                    Self(_mm512_permutex2var_ps(self.0, low, other.0)),
                    Self(_mm512_permutex2var_ps(self.0, high, other.0)),
                )
            }
        }
        #[inline(always)]
        fn relu(self) -> Self {
            // maxps returns its second operand when either is NaN: NaN propagates.
            Self(unsafe { _mm512_max_ps(_mm512_setzero_ps(), self.0) })
        }
    }
}

#[cfg(target_arch = "wasm32")]
pub(crate) mod simd128 {
    use core::arch::wasm32::*;

    /// Four lanes of WebAssembly SIMD128. Plain SIMD128 has no fused multiply-add, so
    /// [`multiply_add`](super::Lanes::multiply_add) is a multiply and an add; with `FUSED` (the
    /// crate's `relaxed-simd` feature) it is relaxed SIMD's `f32x4.relaxed_madd`, one
    /// instruction that the browser compiles to the CPU's FMA where it has one (then one
    /// rounding, else two). `FUSED` lanes are only used inside functions compiled with
    /// `relaxed-simd` (`products::fused`), where the instruction is inlined.
    #[derive(Clone, Copy)]
    pub struct Simd128<const FUSED: bool = false>(v128);

    /// SIMD128 with relaxed SIMD's fused multiply-add.
    #[cfg(feature = "relaxed-simd")]
    pub type FusedSimd128 = Simd128<true>;

    impl<const FUSED: bool> super::Lanes for Simd128<FUSED> {
        const WIDTH: usize = 4;
        #[inline(always)]
        fn zero() -> Self {
            Self(f32x4_splat(0.0))
        }
        #[inline(always)]
        fn splat(x: f32) -> Self {
            Self(f32x4_splat(x))
        }
        #[inline(always)]
        unsafe fn load(from: *const f32) -> Self {
            // SAFETY: the caller guarantees four readable values; v128_load is unaligned.
            Self(unsafe { v128_load(from.cast()) })
        }
        #[inline(always)]
        unsafe fn store(self, to: *mut f32) {
            // SAFETY: the caller guarantees four writable values.
            unsafe { v128_store(to.cast(), self.0) }
        }
        #[inline(always)]
        fn multiply_add(self, a: Self, b: Self) -> Self {
            #[cfg(feature = "relaxed-simd")]
            if FUSED {
                return Self(f32x4_relaxed_madd(a.0, b.0, self.0));
            }
            Self(f32x4_add(self.0, f32x4_mul(a.0, b.0)))
        }
        #[inline(always)]
        fn add(self, other: Self) -> Self {
            Self(f32x4_add(self.0, other.0))
        }
        #[inline(always)]
        fn sub(self, other: Self) -> Self {
            Self(f32x4_sub(self.0, other.0))
        }
        #[inline(always)]
        fn interleave(self, other: Self) -> (Self, Self) {
            (
                Self(i32x4_shuffle::<0, 4, 1, 5>(self.0, other.0)),
                Self(i32x4_shuffle::<2, 6, 3, 7>(self.0, other.0)),
            )
        }
        #[inline(always)]
        fn relu(self) -> Self {
            // f32x4.max returns NaN when either lane is NaN.
            Self(f32x4_max(self.0, f32x4_splat(0.0)))
        }
    }
}

/// The kernels' WebAssembly entry points compiled with relaxed SIMD (the crate's `relaxed-simd`
/// feature), so that [`simd128::FusedSimd128`]'s `f32x4.relaxed_madd` is inlined into their
/// loops. A module built with the feature does not compile in a browser without relaxed SIMD:
/// the page builds its CPU workers both ways and picks one (src/cpu_pool.rs).
#[cfg(all(target_arch = "wasm32", feature = "relaxed-simd"))]
pub(crate) mod fused {
    use super::simd128::FusedSimd128;

    /// [`super::broadcast_product`]'s body with fused multiply-adds.
    #[target_feature(enable = "simd128,relaxed-simd")]
    pub(crate) fn broadcast(
        c: (&mut [f32], usize),
        accumulate: bool,
        shape: (usize, usize, usize),
        a: &[f32],
        a_strides: (usize, usize),
        b: &[f32],
    ) {
        super::broadcast_body::<FusedSimd128, 4, 3>(c, accumulate, shape, a, a_strides, b)
    }
}

/// True when this x86-64 CPU has AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
pub(crate) fn has_avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
}

/// True when this x86-64 CPU has AVX-512F (and AVX2 and FMA, which every such CPU has).
#[cfg(target_arch = "x86_64")]
pub(crate) fn has_avx512() -> bool {
    std::arch::is_x86_feature_detected!("avx512f") && has_avx2()
}

/// `C (m x n) = A · B` (or `+=` when `accumulate`), where row `i` of `C` starts at
/// `c[i * c_stride]`, `A(i, kk)` is `a[i * a_row + kk * a_col]` and `B` is `k x n` row-major.
pub fn broadcast_product(
    (c, c_stride): (&mut [f32], usize),
    accumulate: bool,
    (m, n, k): (usize, usize, usize),
    a: &[f32],
    (a_row, a_col): (usize, usize),
    b: &[f32],
) {
    assert!(b.len() == k * n && c_stride >= n, "product shapes");
    if m == 0 || n == 0 {
        return;
    }
    assert!(c.len() >= (m - 1) * c_stride + n, "C outside its slice");
    assert!(
        k == 0 || (m - 1) * a_row + (k - 1) * a_col < a.len(),
        "A outside its slice"
    );
    let shape = (m, n, k);
    #[cfg(target_arch = "x86_64")]
    if has_avx2() {
        // SAFETY: this CPU has AVX2 and FMA (checked just above).
        unsafe { broadcast_avx2((c, c_stride), accumulate, shape, a, (a_row, a_col), b) };
        return;
    }
    #[cfg(all(target_arch = "wasm32", feature = "relaxed-simd"))]
    return fused::broadcast((c, c_stride), accumulate, shape, a, (a_row, a_col), b);
    #[cfg(all(target_arch = "wasm32", not(feature = "relaxed-simd")))]
    return broadcast_body::<simd128::Simd128, 4, 3>(
        (c, c_stride),
        accumulate,
        shape,
        a,
        (a_row, a_col),
        b,
    );
    #[allow(unreachable_code)]
    broadcast_body::<f32, 4, 8>((c, c_stride), accumulate, shape, a, (a_row, a_col), b)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn broadcast_avx2(
    c: (&mut [f32], usize),
    accumulate: bool,
    shape: (usize, usize, usize),
    a: &[f32],
    a_strides: (usize, usize),
    b: &[f32],
) {
    // 3 rows x 4 vectors of 8: twelve of the sixteen AVX registers hold the tile.
    broadcast_body::<avx2::Avx2, 3, 4>(c, accumulate, shape, a, a_strides, b)
}

/// The body of [`broadcast_product`]: tiles of `R` rows of `A` (packed in blocks of `R`) by
/// `VECTORS` vectors of `B`'s columns.
#[inline(always)]
fn broadcast_body<L: Lanes, const R: usize, const VECTORS: usize>(
    (c, c_stride): (&mut [f32], usize),
    accumulate: bool,
    (m, n, k): (usize, usize, usize),
    a: &[f32],
    (a_row, a_col): (usize, usize),
    b: &[f32],
) {
    // A packed once: per block of R rows, R consecutive values per step (rows past m are 0).
    let blocks = m.div_ceil(R);
    let mut packed = vec![0.0f32; blocks * k * R];
    for (block, panel) in packed.chunks_exact_mut(k * R).enumerate() {
        for (kk, step) in panel.chunks_exact_mut(R).enumerate() {
            for (i, value) in step.iter_mut().enumerate() {
                let row = block * R + i;
                if row < m {
                    *value = a[row * a_row + kk * a_col];
                }
            }
        }
    }
    let strip = VECTORS * L::WIDTH;
    // B's strip of `strip` columns, copied contiguous (zero-padded at the right edge): its rows
    // are a whole image row apart in B, which would make them collide in the same cache sets.
    let mut panel_b = vec![0.0f32; k * strip];
    for j0 in (0..n).step_by(strip) {
        let width = strip.min(n - j0);
        let full = width == strip;
        for (kk, row) in panel_b.chunks_exact_mut(strip).enumerate() {
            let from = &b[kk * n + j0..][..width];
            if full {
                // Whole vectors, inlined: a memcpy call per short row would cost more.
                for v in 0..VECTORS {
                    // SAFETY: both slices hold `strip = VECTORS * WIDTH` values.
                    unsafe {
                        let x = L::load(from.as_ptr().add(v * L::WIDTH));
                        x.store(row.as_mut_ptr().add(v * L::WIDTH));
                    }
                }
            } else {
                row[..width].copy_from_slice(from);
                row[width..].fill(0.0);
            }
        }
        // The strip stays in L1 while every block of A passes over it.
        for (block, panel_a) in packed.chunks_exact(k * R).enumerate() {
            let rows = R.min(m - block * R);
            let mut acc = [[L::zero(); VECTORS]; R];
            if accumulate && full {
                for (i, acc) in acc.iter_mut().enumerate().take(rows) {
                    let from = &c[(block * R + i) * c_stride + j0..][..strip];
                    for (v, acc) in acc.iter_mut().enumerate() {
                        // SAFETY: `from` holds `strip` values.
                        *acc = unsafe { L::load(from.as_ptr().add(v * L::WIDTH)) };
                    }
                }
            }
            let (mut pa, mut pb) = (panel_a.as_ptr(), panel_b.as_ptr());
            for _ in 0..k {
                // SAFETY: `panel_a` holds k steps of R values and `panel_b` k rows of `strip`
                // values; each pass reads one step and one row and advances past them.
                unsafe {
                    let bv: [L; VECTORS] = L::load_vectors(pb);
                    for (i, acc) in acc.iter_mut().enumerate() {
                        let a = L::splat(*pa.add(i));
                        for (acc, b) in acc.iter_mut().zip(bv) {
                            *acc = acc.multiply_add(a, b);
                        }
                    }
                    pa = pa.add(R);
                    pb = pb.add(strip);
                }
            }
            let mut tile = [0.0f32; 128];
            for (i, acc) in acc.iter().enumerate().take(rows) {
                let out = &mut c[(block * R + i) * c_stride + j0..][..width];
                if full {
                    for (v, value) in acc.iter().enumerate() {
                        // SAFETY: `out` holds `strip` values.
                        unsafe { value.store(out.as_mut_ptr().add(v * L::WIDTH)) };
                    }
                    continue;
                }
                for (v, value) in acc.iter().enumerate() {
                    // SAFETY: `tile` holds 128 >= VECTORS * WIDTH values.
                    unsafe { value.store(tile.as_mut_ptr().add(v * L::WIDTH)) };
                }
                if accumulate {
                    out.iter_mut().zip(&tile).for_each(|(o, t)| *o += t);
                } else {
                    out.copy_from_slice(&tile[..width]);
                }
            }
        }
    }
}

/// A read-only matrix view: element `(r, c)` is `data[r * row_stride + c * col_stride]`.
#[derive(Clone, Copy)]
pub struct MatrixView<'a> {
    data: &'a [f32],
    rows: usize,
    cols: usize,
    row_stride: usize,
    col_stride: usize,
}

impl<'a> MatrixView<'a> {
    /// A row-major `rows x cols` matrix.
    pub fn row_major(data: &'a [f32], rows: usize, cols: usize) -> Self {
        Self {
            data,
            rows,
            cols,
            row_stride: cols,
            col_stride: 1,
        }
    }

    /// The transpose of this matrix, without moving any element.
    pub fn transposed(self) -> Self {
        Self {
            rows: self.cols,
            cols: self.rows,
            row_stride: self.col_stride,
            col_stride: self.row_stride,
            ..self
        }
    }

    /// True when every element this view names lies inside `data`.
    fn in_bounds(&self) -> bool {
        self.rows == 0
            || self.cols == 0
            || (self.rows - 1) * self.row_stride + (self.cols - 1) * self.col_stride
                < self.data.len()
    }
}

/// Whether a product may use several threads itself.
#[derive(Clone, Copy)]
pub enum Threads {
    /// The calling thread only (images already run in parallel).
    One,
    /// Every rayon worker (a batch of one image).
    All,
}

/// `dst = lhs · rhs`, or `dst += lhs · rhs` when `accumulate`; `dst` is row-major.
pub fn gemm_product(
    dst: &mut [f32],
    accumulate: bool,
    lhs: MatrixView,
    rhs: MatrixView,
    threads: Threads,
) {
    let (m, k, n) = (lhs.rows, lhs.cols, rhs.cols);
    assert!(
        rhs.rows == k && dst.len() == m * n && lhs.in_bounds() && rhs.in_bounds(),
        "matrix product of mismatched shapes"
    );
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            dst.fill(0.0);
        }
        return;
    }
    let parallelism = match threads {
        #[cfg(feature = "rayon")]
        Threads::All => gemm::Parallelism::Rayon(0),
        _ => gemm::Parallelism::None,
    };
    // SAFETY: `dst` holds `m x n` elements, row-major (checked above), and is borrowed mutably;
    // every element either operand view names is inside its slice (`in_bounds`, checked above).
    // gemm only reads `dst` when `read_dst` is true.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            accumulate,
            lhs.data.as_ptr(),
            lhs.col_stride as isize,
            lhs.row_stride as isize,
            rhs.data.as_ptr(),
            rhs.col_stride as isize,
            rhs.row_stride as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            parallelism,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn values(count: usize, salt: usize) -> Vec<f32> {
        (0..count)
            .map(|i| ((i * 7919 + salt * 104_729) % 17) as f32 / 8.0 - 1.0)
            .collect()
    }

    /// Integer-valued operands (multiples of 1/8), so every order of summation is exact.
    #[test]
    fn both_products_equal_the_textbook_product_at_every_edge() {
        for (m, n, k) in [
            (1, 1, 1),
            (4, 24, 3),
            (5, 25, 7),
            (32, 100, 9),
            (3, 1031, 2),
            (7, 5, 600),
        ] {
            let a = values(m * k, 1);
            let b = values(k * n, 2);
            let expected: Vec<f32> = (0..m * n)
                .map(|ij| {
                    (0..k)
                        .map(|kk| a[ij / n * k + kk] * b[kk * n + ij % n])
                        .sum()
                })
                .collect();
            // A row-major, then A given as its transpose's column view.
            let mut c = vec![f32::NAN; m * n];
            broadcast_product((&mut c, n), false, (m, n, k), &a, (k, 1), &b);
            assert_eq!(c, expected, "broadcast {m}x{n}x{k}");
            let a_t: Vec<f32> = (0..k * m).map(|x| a[x % m * k + x / m]).collect();
            broadcast_product((&mut c, n), false, (m, n, k), &a_t, (1, m), &b);
            assert_eq!(c, expected, "broadcast, A transposed {m}x{n}x{k}");
            let mut doubled = c.clone();
            broadcast_product((&mut doubled, n), true, (m, n, k), &a, (k, 1), &b);
            assert_eq!(
                doubled,
                expected.iter().map(|v| 2.0 * v).collect::<Vec<_>>()
            );
            // The same through gemm, B given as its transpose (rows along k).
            let b_t: Vec<f32> = (0..n * k).map(|x| b[x % k * n + x / k]).collect();
            let mut c = vec![f32::NAN; m * n];
            let (a, b_t) = (
                MatrixView::row_major(&a, m, k),
                MatrixView::row_major(&b_t, n, k),
            );
            gemm_product(&mut c, false, a, b_t.transposed(), Threads::One);
            assert_eq!(c, expected, "gemm {m}x{n}x{k}");
        }
    }
}
