//! One number type for per-Gaussian code that runs on one lane (`f32`) or eight (`F32x8`).
//!
//! Per-Gaussian stages (projection, SH colour) are written once, generic over [`Lanes`], and
//! instantiated for `f32` — the reference form — and, on x86-64 with AVX2, for [`F32x8`]:
//! eight Gaussians per instruction. Every operation of the trait is an IEEE-754 operation
//! with the same rounding in both forms (add, sub, mul, div, sqrt; comparisons that are
//! false on NaN; selects), and the transcendental functions are the crate's own
//! ([`crate::math::fastexp`], [`crate::math::round`]) written operation for operation in
//! both forms, so every lane of an `F32x8` computation equals the `f32` computation bit for
//! bit (tests `lanes_match_scalar_bitwise`, `projection_simd_matches_scalar_bitwise`).
//!
//! Branches become masks: code computes both sides and [`Lanes::select`]s. NaN inputs
//! behave as in the scalar code because every comparison is ordered (false on NaN), exactly
//! like Rust's `<`, `>`, `<=`, `>=`.

use crate::math::sh::ShScalar;
use std::ops::{BitAnd, BitOr, Div, Not};

/// A vector of `N` f32 lanes with the IEEE operations the per-Gaussian code needs.
pub trait Lanes: ShScalar + Div<Output = Self> {
    /// Lanes per value.
    const N: usize;
    /// Per-lane booleans.
    type Mask: Copy
        + BitAnd<Output = Self::Mask>
        + BitOr<Output = Self::Mask>
        + Not<Output = Self::Mask>;

    fn splat(v: f32) -> Self;
    /// Lane `l` ← `f(l)` for `l < N`.
    fn gather(f: impl Fn(usize) -> f32) -> Self;
    /// Write the `N` lanes to `out[..N]`.
    fn write(self, out: &mut [f32]);
    /// Columns of `N` rows: lane `l` of `out[k]` ← `src[l·stride + k]` for every
    /// `k < out.len()` (`out.len() ≤ stride` unless `N = 1`). The values of
    /// `gather(|l| src[l·stride + k])`, loaded row by row and transposed where the lanes
    /// have a transpose (`F32x8`).
    #[inline(always)]
    fn load_columns(src: &[f32], stride: usize, out: &mut [Self]) {
        for (k, o) in out.iter_mut().enumerate() {
            *o = Self::gather(|l| src[l * stride + k]);
        }
    }
    /// The inverse of [`Lanes::load_columns`]: `dst[l·stride + k]` ← lane `l` of `cols[k]`
    /// for every `k < cols.len() ≤ stride` and `l < N`; nothing else in `dst` is written.
    #[inline(always)]
    fn store_columns(cols: &[Self], dst: &mut [f32], stride: usize) {
        let mut lanes = [0f32; 16];
        for (k, c) in cols.iter().enumerate() {
            c.write(&mut lanes);
            for l in 0..Self::N {
                dst[l * stride + k] = lanes[l];
            }
        }
    }
    /// Columns of `N` dense rows of `S ≤ 4` values (`[f32; S]` structures, as the scene's
    /// means, scales, rotations and DC colours are stored): lane `l` of column `k` ←
    /// `src[l·S + k]`, for `src` of at least `N·S` values. [`Lanes::load_columns`] with
    /// `stride = S`, done with `S` full-width loads and in-register permutes.
    #[inline(always)]
    fn load_dense<const S: usize>(src: &[f32]) -> [Self; S] {
        let src = &src[..Self::N * S];
        std::array::from_fn(|k| Self::gather(|l| src[l * S + k]))
    }
    /// `out[l] = [a, b]` of lane `l` saturated to i32 as Rust's `v.min(i32::MAX as f32) as
    /// i32` does (truncation toward zero; `≥ 2³¹` and NaN give `i32::MAX`, `≤ −2³¹`
    /// `i32::MIN`), for `l < N`.
    #[inline(always)]
    fn store_i32_pairs(a: Self, b: Self, out: &mut [[i32; 2]]) {
        let (mut x, mut y) = ([0f32; 16], [0f32; 16]);
        a.write(&mut x);
        b.write(&mut y);
        for (l, o) in out[..Self::N].iter_mut().enumerate() {
            *o = [saturate_i32(x[l]), saturate_i32(y[l])];
        }
    }
    fn lt(self, o: Self) -> Self::Mask;
    fn le(self, o: Self) -> Self::Mask;
    fn gt(self, o: Self) -> Self::Mask;
    fn ge(self, o: Self) -> Self::Mask;
    /// `m ? a : b` per lane.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
    fn all_false() -> Self::Mask;
    /// Whether every lane of `m` is true.
    fn all(m: Self::Mask) -> bool;
    /// Bit `l` set where lane `l` of `m` is true (bits `N..` clear).
    fn bits(m: Self::Mask) -> u32;
    /// Neither NaN nor ±∞.
    fn is_finite(self) -> Self::Mask;
    /// Correctly rounded square root.
    fn sqrt(self) -> Self;
    /// [`crate::math::fastexp::exp`].
    fn exp(self) -> Self;
    /// [`crate::math::fastexp::ln`].
    fn ln(self) -> Self;
    /// [`crate::math::round::ceil`].
    fn ceil(self) -> Self;

    /// `if self < lo { lo } else { self }`, then `if · > hi { hi } else { · }` (NaN kept).
    #[inline(always)]
    fn clamp_sel(self, lo: Self, hi: Self) -> Self {
        let v = Self::select(self.lt(lo), lo, self);
        Self::select(v.gt(hi), hi, v)
    }
}

/// `v.min(i32::MAX as f32) as i32`: what [`Lanes::store_i32_pairs`] stores.
#[inline(always)]
pub fn saturate_i32(v: f32) -> i32 {
    v.min(i32::MAX as f32) as i32
}

impl Lanes for f32 {
    const N: usize = 1;
    type Mask = bool;

    #[inline(always)]
    fn splat(v: f32) -> Self {
        v
    }
    #[inline(always)]
    fn gather(f: impl Fn(usize) -> f32) -> Self {
        f(0)
    }
    #[inline(always)]
    fn write(self, out: &mut [f32]) {
        out[0] = self;
    }
    #[inline(always)]
    fn lt(self, o: Self) -> bool {
        self < o
    }
    #[inline(always)]
    fn le(self, o: Self) -> bool {
        self <= o
    }
    #[inline(always)]
    fn gt(self, o: Self) -> bool {
        self > o
    }
    #[inline(always)]
    fn ge(self, o: Self) -> bool {
        self >= o
    }
    #[inline(always)]
    fn select(m: bool, a: Self, b: Self) -> Self {
        if m { a } else { b }
    }
    #[inline(always)]
    fn all_false() -> bool {
        false
    }
    #[inline(always)]
    fn all(m: bool) -> bool {
        m
    }
    #[inline(always)]
    fn bits(m: bool) -> u32 {
        u32::from(m)
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        f32::is_finite(self)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f32::sqrt(self)
    }
    #[inline(always)]
    fn exp(self) -> Self {
        crate::math::fastexp::exp(self)
    }
    #[inline(always)]
    fn ln(self) -> Self {
        crate::math::fastexp::ln(self)
    }
    #[inline(always)]
    fn ceil(self) -> Self {
        crate::math::round::ceil(self)
    }
}

#[cfg(target_arch = "x86_64")]
pub use avx2::{F32x8, M8};
#[cfg(target_arch = "x86_64")]
pub use avx512::F32x16;

#[cfg(target_arch = "x86_64")]
mod avx2 {
    //! `F32x8`: eight lanes in one AVX2 register.
    //!
    //! Values of these types exist only inside functions compiled with
    //! `#[target_feature(enable = "avx2")]` that the caller entered after
    //! `is_x86_feature_detected!("avx2")`: every method is `#[inline(always)]` so that it is
    //! compiled into such a function, and that check is what makes the intrinsics sound.

    use super::Lanes;
    use crate::math::fastexp::{exp_avx2, ln_avx2};
    use crate::math::sh::ShScalar;
    use std::arch::x86_64::*;
    use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

    /// Eight f32 lanes.
    #[derive(Clone, Copy, Debug)]
    pub struct F32x8(pub __m256);

    /// Eight lane masks (all bits set or clear per lane).
    #[derive(Clone, Copy, Debug)]
    pub struct M8(pub __m256);

    // SAFETY (every `unsafe` block below): values of these types are only created and used
    // in code running on a CPU with AVX2 (module docs), the only precondition of the
    // intrinsics; pointer-taking intrinsics are given arrays of exactly 8 lanes.

    macro_rules! binop {
        ($tr:ident, $f:ident, $intr:ident) => {
            impl $tr for F32x8 {
                type Output = F32x8;
                #[inline(always)]
                fn $f(self, o: F32x8) -> F32x8 {
                    F32x8(unsafe { $intr(self.0, o.0) })
                }
            }
        };
    }
    binop!(Add, add, _mm256_add_ps);
    binop!(Sub, sub, _mm256_sub_ps);
    binop!(Mul, mul, _mm256_mul_ps);
    binop!(Div, div, _mm256_div_ps);

    impl Neg for F32x8 {
        type Output = F32x8;
        #[inline(always)]
        fn neg(self) -> F32x8 {
            F32x8(unsafe { _mm256_xor_ps(self.0, _mm256_set1_ps(-0.0)) })
        }
    }

    impl BitAnd for M8 {
        type Output = M8;
        #[inline(always)]
        fn bitand(self, o: M8) -> M8 {
            M8(unsafe { _mm256_and_ps(self.0, o.0) })
        }
    }
    impl BitOr for M8 {
        type Output = M8;
        #[inline(always)]
        fn bitor(self, o: M8) -> M8 {
            M8(unsafe { _mm256_or_ps(self.0, o.0) })
        }
    }
    impl Not for M8 {
        type Output = M8;
        #[inline(always)]
        fn not(self) -> M8 {
            M8(unsafe { _mm256_xor_ps(self.0, _mm256_castsi256_ps(_mm256_set1_epi32(-1))) })
        }
    }

    impl ShScalar for F32x8 {
        #[inline(always)]
        fn c(v: f64) -> Self {
            // The same rounding as `<f32 as ShScalar>::c`.
            F32x8::splat(v as f32)
        }
    }

    /// The 8×8 transpose of `r` (row `i` → lane `i` of every result).
    #[inline(always)]
    fn transpose8(r: &[__m256; 8]) -> [__m256; 8] {
        unsafe {
            // Pairs of rows interleaved: lanes (a0 b0 a1 b1 | a4 b4 a5 b5) and the high halves.
            let t0 = _mm256_unpacklo_ps(r[0], r[1]);
            let t1 = _mm256_unpackhi_ps(r[0], r[1]);
            let t2 = _mm256_unpacklo_ps(r[2], r[3]);
            let t3 = _mm256_unpackhi_ps(r[2], r[3]);
            let t4 = _mm256_unpacklo_ps(r[4], r[5]);
            let t5 = _mm256_unpackhi_ps(r[4], r[5]);
            let t6 = _mm256_unpacklo_ps(r[6], r[7]);
            let t7 = _mm256_unpackhi_ps(r[6], r[7]);
            // Four rows per column: columns k (low half) and k + 4 (high half).
            let s0 = _mm256_shuffle_ps::<0x44>(t0, t2);
            let s1 = _mm256_shuffle_ps::<0xEE>(t0, t2);
            let s2 = _mm256_shuffle_ps::<0x44>(t1, t3);
            let s3 = _mm256_shuffle_ps::<0xEE>(t1, t3);
            let s4 = _mm256_shuffle_ps::<0x44>(t4, t6);
            let s5 = _mm256_shuffle_ps::<0xEE>(t4, t6);
            let s6 = _mm256_shuffle_ps::<0x44>(t5, t7);
            let s7 = _mm256_shuffle_ps::<0xEE>(t5, t7);
            [
                _mm256_permute2f128_ps::<0x20>(s0, s4),
                _mm256_permute2f128_ps::<0x20>(s1, s5),
                _mm256_permute2f128_ps::<0x20>(s2, s6),
                _mm256_permute2f128_ps::<0x20>(s3, s7),
                _mm256_permute2f128_ps::<0x31>(s0, s4),
                _mm256_permute2f128_ps::<0x31>(s1, s5),
                _mm256_permute2f128_ps::<0x31>(s2, s6),
                _mm256_permute2f128_ps::<0x31>(s3, s7),
            ]
        }
    }

    impl F32x8 {
        #[inline(always)]
        fn cmp<const P: i32>(self, o: F32x8) -> M8 {
            M8(unsafe { _mm256_cmp_ps::<P>(self.0, o.0) })
        }
    }

    impl Lanes for F32x8 {
        const N: usize = 8;
        type Mask = M8;

        #[inline(always)]
        fn splat(v: f32) -> Self {
            F32x8(unsafe { _mm256_set1_ps(v) })
        }
        #[inline(always)]
        fn gather(f: impl Fn(usize) -> f32) -> Self {
            F32x8(unsafe { _mm256_setr_ps(f(0), f(1), f(2), f(3), f(4), f(5), f(6), f(7)) })
        }
        #[inline(always)]
        fn write(self, out: &mut [f32]) {
            let out = &mut out[..8];
            unsafe { _mm256_storeu_ps(out.as_mut_ptr(), self.0) }
        }
        /// Eight columns at a time: each row's eight values in one load (copied through a
        /// zeroed buffer where `src` ends first), then an 8×8 transpose. Plain loops and
        /// no closures over vectors: those may be compiled out of line without AVX2.
        #[inline(always)]
        #[allow(clippy::needless_range_loop)] // no iterators over vectors (see above)
        fn load_columns(src: &[f32], stride: usize, out: &mut [Self]) {
            let cols = out.len();
            assert!(cols <= stride && 7 * stride + cols <= src.len());
            let mut c0 = 0;
            while c0 < cols {
                let width = (cols - c0).min(8);
                let mut rows = [unsafe { _mm256_setzero_ps() }; 8];
                for l in 0..8 {
                    let at = l * stride + c0;
                    rows[l] = if at + 8 <= src.len() {
                        // Values past the row's `cols` are loaded but never used.
                        unsafe { _mm256_loadu_ps(src[at..at + 8].as_ptr()) }
                    } else {
                        let mut t = [0f32; 8];
                        t[..width].copy_from_slice(&src[at..at + width]);
                        unsafe { _mm256_loadu_ps(t.as_ptr()) }
                    };
                }
                let t = transpose8(&rows);
                for k in 0..width {
                    out[c0 + k] = F32x8(t[k]);
                }
                c0 += 8;
            }
        }
        /// `S` loads of 8 values; each column gathered from them by one lane permute per
        /// load and blends.
        #[inline(always)]
        #[allow(clippy::needless_range_loop)] // no iterators over vectors (see above)
        fn load_dense<const S: usize>(src: &[f32]) -> [Self; S] {
            assert!((1..=4).contains(&S) && src.len() >= 8 * S);
            let mut regs = [unsafe { _mm256_setzero_ps() }; 4];
            for j in 0..S {
                regs[j] = unsafe { _mm256_loadu_ps(src[8 * j..8 * j + 8].as_ptr()) };
            }
            let mut out = [F32x8::splat(0.0); S];
            for k in 0..S {
                // Lane `l` takes flat value `S·l + k`: register `(S·l + k)/8`, lane
                // `(S·l + k) mod 8` (the permute reads the index's low three bits).
                let flat: [i32; 8] = std::array::from_fn(|l| (S * l + k) as i32);
                let idx = unsafe { _mm256_loadu_si256(flat.as_ptr().cast()) };
                let mut v = unsafe { _mm256_permutevar8x32_ps(regs[0], idx) };
                for j in 1..S {
                    let from_j: [i32; 8] =
                        std::array::from_fn(|l| if flat[l] as usize / 8 == j { -1 } else { 0 });
                    let m = unsafe { _mm256_loadu_si256(from_j.as_ptr().cast()) };
                    let p = unsafe { _mm256_permutevar8x32_ps(regs[j], idx) };
                    v = unsafe { _mm256_blendv_ps(v, p, _mm256_castsi256_ps(m)) };
                }
                out[k] = F32x8(v);
            }
            out
        }
        /// Truncating conversions (`vcvttps2dq`: out of range and NaN give `i32::MIN`),
        /// `i32::MAX` where the value is not below 2³¹, then the two interleaved.
        #[inline(always)]
        fn store_i32_pairs(a: Self, b: Self, out: &mut [[i32; 2]]) {
            let out = &mut out[..8];
            let sat = |v: F32x8| unsafe {
                let t = _mm256_cvttps_epi32(v.0);
                let big = _mm256_cmp_ps::<_CMP_NLT_UQ>(v.0, _mm256_set1_ps(2_147_483_648.0));
                _mm256_blendv_epi8(t, _mm256_set1_epi32(i32::MAX), _mm256_castps_si256(big))
            };
            let (x, y) = (sat(a), sat(b));
            unsafe {
                // Per 128-bit half: [x0 y0 x1 y1], [x2 y2 x3 y3] (and lanes 4–7 above).
                let lo = _mm256_unpacklo_epi32(x, y);
                let hi = _mm256_unpackhi_epi32(x, y);
                let p = out.as_mut_ptr().cast::<__m256i>();
                _mm256_storeu_si256(p, _mm256_permute2x128_si256::<0x20>(lo, hi));
                _mm256_storeu_si256(p.add(1), _mm256_permute2x128_si256::<0x31>(lo, hi));
            }
        }
        /// At most 16 columns (two 8×8 transposes), then one 8-wide store per row and
        /// block where the eight slots are the row's own or, rows being dense (`stride` =
        /// columns), later rows' of this call, written after; a copy elsewhere. (AVX's
        /// masked store is microcoded on AMD Zen: slower than the copy.)
        #[inline(always)]
        #[allow(clippy::needless_range_loop)] // no iterators over vectors (see above)
        fn store_columns(cols: &[Self], dst: &mut [f32], stride: usize) {
            let n = cols.len();
            assert!(n <= 16 && n <= stride && 7 * stride + n <= dst.len());
            let mut rows = [[unsafe { _mm256_setzero_ps() }; 8]; 2];
            for (b, r) in rows.iter_mut().enumerate().take(n.div_ceil(8)) {
                let mut block = [unsafe { _mm256_setzero_ps() }; 8];
                for k in 0..(n - 8 * b).min(8) {
                    block[k] = cols[8 * b + k].0;
                }
                *r = transpose8(&block);
            }
            for l in 0..8 {
                for (b, r) in rows.iter().enumerate().take(n.div_ceil(8)) {
                    let at = l * stride + 8 * b;
                    let width = (n - 8 * b).min(8);
                    if at + 8 <= l * stride + n || (stride == n && at + 8 <= 8 * stride) {
                        unsafe { _mm256_storeu_ps(dst[at..at + 8].as_mut_ptr(), r[l]) };
                    } else {
                        let mut t = [0f32; 8];
                        unsafe { _mm256_storeu_ps(t.as_mut_ptr(), r[l]) };
                        dst[at..at + width].copy_from_slice(&t[..width]);
                    }
                }
            }
        }
        // Ordered, non-signalling predicates: false when either side is NaN, like `<` on f32.
        #[inline(always)]
        fn lt(self, o: Self) -> M8 {
            self.cmp::<_CMP_LT_OQ>(o)
        }
        #[inline(always)]
        fn le(self, o: Self) -> M8 {
            self.cmp::<_CMP_LE_OQ>(o)
        }
        #[inline(always)]
        fn gt(self, o: Self) -> M8 {
            self.cmp::<_CMP_GT_OQ>(o)
        }
        #[inline(always)]
        fn ge(self, o: Self) -> M8 {
            self.cmp::<_CMP_GE_OQ>(o)
        }
        #[inline(always)]
        fn select(m: M8, a: Self, b: Self) -> Self {
            F32x8(unsafe { _mm256_blendv_ps(b.0, a.0, m.0) })
        }
        #[inline(always)]
        fn all_false() -> M8 {
            M8(unsafe { _mm256_setzero_ps() })
        }
        #[inline(always)]
        fn all(m: M8) -> bool {
            unsafe { _mm256_movemask_ps(m.0) == 0xff }
        }
        #[inline(always)]
        fn bits(m: M8) -> u32 {
            unsafe { _mm256_movemask_ps(m.0) as u32 }
        }
        #[inline(always)]
        fn is_finite(self) -> M8 {
            // |x| < ∞, ordered: false for ±∞ and NaN.
            let abs = unsafe { _mm256_andnot_ps(_mm256_set1_ps(-0.0), self.0) };
            F32x8(abs).lt(F32x8::splat(f32::INFINITY))
        }
        #[inline(always)]
        fn sqrt(self) -> Self {
            F32x8(unsafe { _mm256_sqrt_ps(self.0) })
        }
        #[inline(always)]
        fn exp(self) -> Self {
            F32x8(unsafe { exp_avx2(self.0) })
        }
        #[inline(always)]
        fn ln(self) -> Self {
            F32x8(unsafe { ln_avx2(self.0) })
        }
        #[inline(always)]
        fn ceil(self) -> Self {
            // `round::ceil` lane by lane: truncate, step up where the truncation is below x,
            // zero takes x's sign; NaN and |x| ≥ 2^23 are their own ceiling.
            let x = self;
            let abs = F32x8(unsafe { _mm256_andnot_ps(_mm256_set1_ps(-0.0), x.0) });
            let keep = !abs.lt(F32x8::splat(8_388_608.0)); // NaN or |x| ≥ 2^23
            let t = F32x8(unsafe { _mm256_cvtepi32_ps(_mm256_cvttps_epi32(x.0)) });
            let c = F32x8::select(t.lt(x), t + F32x8::splat(1.0), t);
            let signed_zero = F32x8(unsafe { _mm256_and_ps(x.0, _mm256_set1_ps(-0.0)) });
            let c = F32x8::select(c.eq0(), signed_zero, c);
            F32x8::select(keep, x, c)
        }
    }

    impl F32x8 {
        /// Lanes equal to ±0.
        #[inline(always)]
        fn eq0(self) -> M8 {
            self.cmp::<_CMP_EQ_OQ>(F32x8::splat(0.0))
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod avx512 {
    //! `F32x16`: sixteen lanes in one AVX-512F register, masks in `__mmask16`.
    //!
    //! The same contract as `F32x8` (module `avx2`): values exist only inside functions
    //! compiled with `#[target_feature(enable = "avx512f")]` that the caller entered after
    //! `is_x86_feature_detected!("avx512f")`; every method is `#[inline(always)]`. Only
    //! AVX-512F instructions are used (bitwise float operations go through the integer
    //! forms: `_mm512_and_ps` and friends are AVX512DQ).

    use super::Lanes;
    use crate::math::fastexp::{exp_avx512, ln_avx512};
    use crate::math::sh::ShScalar;
    use std::arch::x86_64::*;
    use std::ops::{Add, Div, Mul, Neg, Sub};

    /// Sixteen f32 lanes.
    #[derive(Clone, Copy, Debug)]
    pub struct F32x16(pub __m512);

    // SAFETY (every `unsafe` block below): values of this type are only created and used in
    // code running on a CPU with AVX-512F (module docs), the only precondition of the
    // intrinsics; pointer-taking intrinsics are given arrays of exactly 16 lanes.

    macro_rules! binop {
        ($tr:ident, $f:ident, $intr:ident) => {
            impl $tr for F32x16 {
                type Output = F32x16;
                #[inline(always)]
                fn $f(self, o: F32x16) -> F32x16 {
                    F32x16(unsafe { $intr(self.0, o.0) })
                }
            }
        };
    }
    binop!(Add, add, _mm512_add_ps);
    binop!(Sub, sub, _mm512_sub_ps);
    binop!(Mul, mul, _mm512_mul_ps);
    binop!(Div, div, _mm512_div_ps);

    /// `x` AND `bits` in every lane.
    #[inline(always)]
    fn and_bits(x: __m512, bits: i32) -> __m512 {
        unsafe {
            _mm512_castsi512_ps(_mm512_and_si512(
                _mm512_castps_si512(x),
                _mm512_set1_epi32(bits),
            ))
        }
    }

    impl Neg for F32x16 {
        type Output = F32x16;
        #[inline(always)]
        fn neg(self) -> F32x16 {
            F32x16(unsafe {
                _mm512_castsi512_ps(_mm512_xor_si512(
                    _mm512_castps_si512(self.0),
                    _mm512_set1_epi32(i32::MIN),
                ))
            })
        }
    }

    impl ShScalar for F32x16 {
        #[inline(always)]
        fn c(v: f64) -> Self {
            // The same rounding as `<f32 as ShScalar>::c`.
            F32x16::splat(v as f32)
        }
    }

    /// The 16×16 transpose of `r` (row `i` → lane `i` of every result): pairs of rows
    /// interleaved within 128-bit lanes, then four rows per column in each 128-bit lane,
    /// then the 128-bit lanes of four row groups gathered in two lane shuffles.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // no iterators over vectors (see `F32x8`)
    fn transpose16(r: &[__m512; 16]) -> [__m512; 16] {
        unsafe {
            let mut t = [_mm512_setzero_ps(); 16];
            for i in 0..8 {
                t[2 * i] = _mm512_unpacklo_ps(r[2 * i], r[2 * i + 1]);
                t[2 * i + 1] = _mm512_unpackhi_ps(r[2 * i], r[2 * i + 1]);
            }
            // u[4i + j]: rows 4i..4i + 4 of columns j, j + 4, j + 8, j + 12 (one per 128-bit
            // lane).
            let mut u = [_mm512_setzero_ps(); 16];
            for i in 0..4 {
                u[4 * i] = _mm512_shuffle_ps::<0x44>(t[4 * i], t[4 * i + 2]);
                u[4 * i + 1] = _mm512_shuffle_ps::<0xEE>(t[4 * i], t[4 * i + 2]);
                u[4 * i + 2] = _mm512_shuffle_ps::<0x44>(t[4 * i + 1], t[4 * i + 3]);
                u[4 * i + 3] = _mm512_shuffle_ps::<0xEE>(t[4 * i + 1], t[4 * i + 3]);
            }
            let mut c = [_mm512_setzero_ps(); 16];
            for j in 0..4 {
                // Rows 0..8 (v) and 8..16 (w) of columns j, j + 8 (lo) and j + 4, j + 12 (hi).
                let v_lo = _mm512_shuffle_f32x4::<0x88>(u[j], u[4 + j]);
                let v_hi = _mm512_shuffle_f32x4::<0xDD>(u[j], u[4 + j]);
                let w_lo = _mm512_shuffle_f32x4::<0x88>(u[8 + j], u[12 + j]);
                let w_hi = _mm512_shuffle_f32x4::<0xDD>(u[8 + j], u[12 + j]);
                c[j] = _mm512_shuffle_f32x4::<0x88>(v_lo, w_lo);
                c[j + 8] = _mm512_shuffle_f32x4::<0xDD>(v_lo, w_lo);
                c[j + 4] = _mm512_shuffle_f32x4::<0x88>(v_hi, w_hi);
                c[j + 12] = _mm512_shuffle_f32x4::<0xDD>(v_hi, w_hi);
            }
            c
        }
    }

    /// The low `n ≤ 16` lanes.
    #[inline(always)]
    fn low_lanes(n: usize) -> __mmask16 {
        ((1u32 << n) - 1) as __mmask16
    }

    impl F32x16 {
        #[inline(always)]
        fn cmp<const P: i32>(self, o: F32x16) -> __mmask16 {
            unsafe { _mm512_cmp_ps_mask::<P>(self.0, o.0) }
        }
        #[inline(always)]
        fn abs(self) -> F32x16 {
            F32x16(and_bits(self.0, i32::MAX))
        }
    }

    impl Lanes for F32x16 {
        const N: usize = 16;
        type Mask = __mmask16;

        #[inline(always)]
        fn splat(v: f32) -> Self {
            F32x16(unsafe { _mm512_set1_ps(v) })
        }
        #[inline(always)]
        fn gather(f: impl Fn(usize) -> f32) -> Self {
            let a: [f32; 16] = [
                f(0),
                f(1),
                f(2),
                f(3),
                f(4),
                f(5),
                f(6),
                f(7),
                f(8),
                f(9),
                f(10),
                f(11),
                f(12),
                f(13),
                f(14),
                f(15),
            ];
            F32x16(unsafe { _mm512_loadu_ps(a.as_ptr()) })
        }
        #[inline(always)]
        fn write(self, out: &mut [f32]) {
            let out = &mut out[..16];
            unsafe { _mm512_storeu_ps(out.as_mut_ptr(), self.0) }
        }
        /// Sixteen columns at a time: each row's sixteen values in one load (masked to the
        /// row's own values where `src` ends first: masked-off lanes are not read), then a
        /// 16×16 transpose.
        #[inline(always)]
        #[allow(clippy::needless_range_loop)] // no iterators over vectors (see `F32x8`)
        fn load_columns(src: &[f32], stride: usize, out: &mut [Self]) {
            let cols = out.len();
            assert!(cols <= stride && 15 * stride + cols <= src.len());
            let mut c0 = 0;
            while c0 < cols {
                let width = (cols - c0).min(16);
                let mut rows = [unsafe { _mm512_setzero_ps() }; 16];
                for l in 0..16 {
                    let at = l * stride + c0;
                    rows[l] = if at + 16 <= src.len() {
                        // Values past the row's `cols` are loaded but never used.
                        unsafe { _mm512_loadu_ps(src[at..at + 16].as_ptr()) }
                    } else {
                        let part = &src[at..at + width];
                        unsafe { _mm512_maskz_loadu_ps(low_lanes(width), part.as_ptr()) }
                    };
                }
                let t = transpose16(&rows);
                for k in 0..width {
                    out[c0 + k] = F32x16(t[k]);
                }
                c0 += 16;
            }
        }
        /// `S` loads of 16 values; each column gathered from them by two-register permutes
        /// (one per pair of loads) and a masked move.
        #[inline(always)]
        #[allow(clippy::needless_range_loop)] // no iterators over vectors (see `F32x8`)
        fn load_dense<const S: usize>(src: &[f32]) -> [Self; S] {
            assert!((1..=4).contains(&S) && src.len() >= 16 * S);
            let mut regs = [unsafe { _mm512_setzero_ps() }; 4];
            for j in 0..S {
                regs[j] = unsafe { _mm512_loadu_ps(src[16 * j..16 * j + 16].as_ptr()) };
            }
            let mut out = [F32x16::splat(0.0); S];
            for k in 0..S {
                // Lane `l` takes flat value `S·l + k`: from the pair of loads `(0, 1)` below
                // 32, `(2, 3)` from 32 on (the permute reads the index's low five bits).
                let flat: [i32; 16] = std::array::from_fn(|l| (S * l + k) as i32);
                let idx = unsafe { _mm512_loadu_si512(flat.as_ptr().cast()) };
                let mut v = unsafe { _mm512_permutex2var_ps(regs[0], idx, regs[1]) };
                if 15 * S + k >= 32 {
                    let high = (0..16).fold(0u16, |m, l| m | ((flat[l] >= 32) as u16) << l);
                    let p = unsafe { _mm512_permutex2var_ps(regs[2], idx, regs[3]) };
                    v = unsafe { _mm512_mask_mov_ps(v, high, p) };
                }
                out[k] = F32x16(v);
            }
            out
        }
        /// Truncating conversions (`vcvttps2dq`: out of range and NaN give `i32::MIN`),
        /// `i32::MAX` where the value is not below 2³¹, then the two interleaved.
        #[inline(always)]
        fn store_i32_pairs(a: Self, b: Self, out: &mut [[i32; 2]]) {
            let out = &mut out[..16];
            let sat = |v: F32x16| unsafe {
                let t = _mm512_cvttps_epi32(v.0);
                let big = _mm512_cmp_ps_mask::<_CMP_NLT_UQ>(v.0, _mm512_set1_ps(2_147_483_648.0));
                _mm512_mask_mov_epi32(t, big, _mm512_set1_epi32(i32::MAX))
            };
            let (x, y) = (sat(a), sat(b));
            unsafe {
                // Per 128-bit block b: [x4b y4b x4b+1 y4b+1] and [x4b+2 y4b+2 x4b+3 y4b+3];
                // the stores take blocks (lo0, hi0, lo1, hi1) and (lo2, hi2, lo3, hi3).
                let lo = _mm512_unpacklo_epi32(x, y);
                let hi = _mm512_unpackhi_epi32(x, y);
                let first = _mm512_setr_epi64(0, 1, 8, 9, 2, 3, 10, 11);
                let second = _mm512_setr_epi64(4, 5, 12, 13, 6, 7, 14, 15);
                let p = out.as_mut_ptr().cast::<__m512i>();
                _mm512_storeu_si512(p, _mm512_permutex2var_epi64(lo, first, hi));
                _mm512_storeu_si512(p.add(1), _mm512_permutex2var_epi64(lo, second, hi));
            }
        }
        /// At most 16 columns: one 16×16 transpose, then one masked store per row (only
        /// the row's `n` slots are written).
        #[inline(always)]
        #[allow(clippy::needless_range_loop)] // no iterators over vectors (see `F32x8`)
        fn store_columns(cols: &[Self], dst: &mut [f32], stride: usize) {
            let n = cols.len();
            assert!(n <= 16 && n <= stride && 15 * stride + n <= dst.len());
            let mut block = [unsafe { _mm512_setzero_ps() }; 16];
            for k in 0..n {
                block[k] = cols[k].0;
            }
            let rows = transpose16(&block);
            for l in 0..16 {
                let row = &mut dst[l * stride..l * stride + n];
                unsafe { _mm512_mask_storeu_ps(row.as_mut_ptr(), low_lanes(n), rows[l]) };
            }
        }
        // Ordered, non-signalling predicates: false when either side is NaN, like `<` on f32.
        #[inline(always)]
        fn lt(self, o: Self) -> __mmask16 {
            self.cmp::<_CMP_LT_OQ>(o)
        }
        #[inline(always)]
        fn le(self, o: Self) -> __mmask16 {
            self.cmp::<_CMP_LE_OQ>(o)
        }
        #[inline(always)]
        fn gt(self, o: Self) -> __mmask16 {
            self.cmp::<_CMP_GT_OQ>(o)
        }
        #[inline(always)]
        fn ge(self, o: Self) -> __mmask16 {
            self.cmp::<_CMP_GE_OQ>(o)
        }
        #[inline(always)]
        fn select(m: __mmask16, a: Self, b: Self) -> Self {
            F32x16(unsafe { _mm512_mask_blend_ps(m, b.0, a.0) })
        }
        #[inline(always)]
        fn all_false() -> __mmask16 {
            0
        }
        #[inline(always)]
        fn all(m: __mmask16) -> bool {
            m == 0xffff
        }
        #[inline(always)]
        fn bits(m: __mmask16) -> u32 {
            u32::from(m)
        }
        #[inline(always)]
        fn is_finite(self) -> __mmask16 {
            // |x| < ∞, ordered: false for ±∞ and NaN.
            self.abs().lt(F32x16::splat(f32::INFINITY))
        }
        #[inline(always)]
        fn sqrt(self) -> Self {
            F32x16(unsafe { _mm512_sqrt_ps(self.0) })
        }
        #[inline(always)]
        fn exp(self) -> Self {
            F32x16(unsafe { exp_avx512(self.0) })
        }
        #[inline(always)]
        fn ln(self) -> Self {
            F32x16(unsafe { ln_avx512(self.0) })
        }
        #[inline(always)]
        fn ceil(self) -> Self {
            // `round::ceil` lane by lane, as `F32x8::ceil`.
            let x = self;
            let keep = !x.abs().lt(F32x16::splat(8_388_608.0)); // NaN or |x| ≥ 2^23
            let t = F32x16(unsafe { _mm512_cvtepi32_ps(_mm512_cvttps_epi32(x.0)) });
            let c = F32x16::select(t.lt(x), t + F32x16::splat(1.0), t);
            let signed_zero = F32x16(and_bits(x.0, i32::MIN));
            let c = F32x16::select(c.cmp::<_CMP_EQ_OQ>(F32x16::splat(0.0)), signed_zero, c);
            F32x16::select(keep, x, c)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Special values and a spread of magnitudes, both signs.
    fn samples() -> Vec<f32> {
        let mut v = vec![
            0.0,
            -0.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MIN_POSITIVE,
            f32::MIN_POSITIVE / 8.0,
            f32::MAX,
            8_388_607.5,
            8_388_608.0,
            -8_388_607.5,
            0.5,
            -0.5,
            1.0,
            255.0,
        ];
        let mut bits = 1u32;
        while bits < 0x7f80_0000 {
            let x = f32::from_bits(bits);
            v.push(x);
            v.push(-x);
            bits = bits.wrapping_add(0x0001_0f3b); // ~32k values over the whole range
        }
        v
    }

    fn same(a: f32, b: f32) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn check_avx2(xs: &[f32]) {
        for chunk in xs.chunks_exact(8) {
            let x = F32x8::gather(|l| chunk[l]);
            let y = F32x8::gather(|l| chunk[7 - l]);
            let mut out = [[0f32; 8]; 7];
            x.exp().write(&mut out[0]);
            x.ln().write(&mut out[1]);
            x.ceil().write(&mut out[2]);
            x.sqrt().write(&mut out[3]);
            (x / y).write(&mut out[4]);
            F32x8::select(x.lt(y) | !x.is_finite(), x, y).write(&mut out[5]);
            x.clamp_sel(F32x8::splat(-1.0), F32x8::splat(2.0))
                .write(&mut out[6]);
            for l in 0..8 {
                let (a, b) = (chunk[l], chunk[7 - l]);
                let want = [
                    Lanes::exp(a),
                    Lanes::ln(a),
                    Lanes::ceil(a),
                    a.sqrt(),
                    a / b,
                    if a < b || !a.is_finite() { a } else { b },
                    a.clamp_sel(-1.0, 2.0),
                ];
                for (k, w) in want.iter().enumerate() {
                    assert!(
                        same(out[k][l], *w),
                        "op {k} at {a:e}, {b:e}: {} vs {w}",
                        out[k][l]
                    );
                }
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    fn check_avx512(xs: &[f32]) {
        for chunk in xs.chunks_exact(16) {
            let x = F32x16::gather(|l| chunk[l]);
            let y = F32x16::gather(|l| chunk[15 - l]);
            let mut out = [[0f32; 16]; 8];
            x.exp().write(&mut out[0]);
            x.ln().write(&mut out[1]);
            x.ceil().write(&mut out[2]);
            x.sqrt().write(&mut out[3]);
            (x / y).write(&mut out[4]);
            F32x16::select(x.lt(y) | !x.is_finite(), x, y).write(&mut out[5]);
            x.clamp_sel(F32x16::splat(-1.0), F32x16::splat(2.0))
                .write(&mut out[6]);
            (-x).write(&mut out[7]);
            for l in 0..16 {
                let (a, b) = (chunk[l], chunk[15 - l]);
                let want = [
                    Lanes::exp(a),
                    Lanes::ln(a),
                    Lanes::ceil(a),
                    a.sqrt(),
                    a / b,
                    if a < b || !a.is_finite() { a } else { b },
                    a.clamp_sel(-1.0, 2.0),
                    -a,
                ];
                for (k, w) in want.iter().enumerate() {
                    assert!(
                        same(out[k][l], *w),
                        "op {k} at {a:e}, {b:e}: {} vs {w}",
                        out[k][l]
                    );
                }
            }
        }
    }

    /// `load_columns` against `gather` for every column count up to the stride, strides
    /// 1 to 105 (SH degree 5's rest coefficients), with `src` ending right after the last
    /// row's columns (the tail path) and with room after it (the direct loads); and
    /// `store_columns` back, writing only the columns' slots.
    #[inline(always)]
    fn check_columns<R: Lanes>() {
        let n = R::N;
        for stride in 1..=105usize {
            for cols in [1, 2, 3, 4, 5, 7, 8, 9, 10, 15, 16, 17, 24, 45, 105] {
                if cols > stride {
                    continue;
                }
                for spare in [0usize, 9, 17] {
                    let len = (n - 1) * stride + cols + spare;
                    let src: Vec<f32> = (0..len).map(|k| k as f32 * 0.5 - 3.0).collect();
                    let mut out = vec![R::splat(f32::NAN); cols];
                    R::load_columns(&src, stride, &mut out);
                    for (k, o) in out.iter().enumerate() {
                        let mut got = [0f32; 16];
                        o.write(&mut got);
                        for (l, g) in got.iter().enumerate().take(n) {
                            assert_eq!(*g, src[l * stride + k], "stride {stride}, column {k}");
                        }
                    }
                    if cols > 16 {
                        continue;
                    }
                    let mut dst = vec![-1f32; len];
                    R::store_columns(&out, &mut dst, stride);
                    for (i, d) in dst.iter().enumerate() {
                        let (l, k) = (i / stride, i % stride);
                        let want = if l < n && k < cols { src[i] } else { -1.0 };
                        assert_eq!(*d, want, "store: stride {stride}, {cols} columns, slot {i}");
                    }
                }
            }
        }
    }

    /// `load_dense` against `gather` for 1 to 4 values per row, with `src` exactly
    /// `N·S` long and longer; `store_i32_pairs` against `saturate_i32` on `samples()`
    /// (NaN, ±∞, ±2³¹ and neighbours included).
    #[inline(always)]
    fn check_dense<R: Lanes>() {
        fn dense<R: Lanes, const S: usize>() {
            for spare in [0usize, 5] {
                let src: Vec<f32> = (0..R::N * S + spare).map(|k| k as f32 - 7.25).collect();
                let got = R::load_dense::<S>(&src);
                for (k, c) in got.iter().enumerate() {
                    let mut lanes = [0f32; 16];
                    c.write(&mut lanes);
                    for (l, v) in lanes.iter().enumerate().take(R::N) {
                        assert_eq!(*v, src[l * S + k], "{S} per row, column {k}, lane {l}");
                    }
                }
            }
        }
        dense::<R, 1>();
        dense::<R, 2>();
        dense::<R, 3>();
        dense::<R, 4>();
        // The boundary values first: `chunks_exact` drops the list's ragged end.
        let two31 = 2_147_483_648.0f32;
        let mut xs = vec![
            two31,
            -two31,
            f32::from_bits(two31.to_bits() - 1),
            -f32::from_bits(two31.to_bits() - 1),
            f32::from_bits(two31.to_bits() + 1),
            3.0e9,
            -3.0e9,
            1e19,
            -1e19,
            7.9,
            -7.9,
        ];
        xs.extend(samples());
        for chunk in xs.chunks_exact(R::N) {
            let a = R::gather(|l| chunk[l]);
            let b = R::gather(|l| -chunk[R::N - 1 - l]);
            let mut out = [[0i32; 2]; 16];
            R::store_i32_pairs(a, b, &mut out);
            for l in 0..R::N {
                let want = [saturate_i32(chunk[l]), saturate_i32(-chunk[R::N - 1 - l])];
                assert_eq!(out[l], want, "lane {l} of {chunk:?}");
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn check_columns_avx2() {
        check_columns::<F32x8>();
        check_dense::<F32x8>();
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    fn check_columns_avx512() {
        check_columns::<F32x16>();
        check_dense::<F32x16>();
    }

    #[test]
    fn load_and_store_columns_match_gather() {
        check_columns::<f32>();
        check_dense::<f32>();
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 is available (checked just above).
            unsafe { check_columns_avx2() };
        }
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx512f") {
            // SAFETY: AVX-512F is available (checked just above).
            unsafe { check_columns_avx512() };
        }
    }

    #[test]
    fn lanes_match_scalar_bitwise() {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 is available (checked just above).
            unsafe { check_avx2(&samples()) };
        }
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx512f") {
            // SAFETY: AVX-512F is available (checked just above).
            unsafe { check_avx512(&samples()) };
        }
    }
}
