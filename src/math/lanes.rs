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
    fn lt(self, o: Self) -> Self::Mask;
    fn le(self, o: Self) -> Self::Mask;
    fn gt(self, o: Self) -> Self::Mask;
    fn ge(self, o: Self) -> Self::Mask;
    /// `m ? a : b` per lane.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
    fn all_false() -> Self::Mask;
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
