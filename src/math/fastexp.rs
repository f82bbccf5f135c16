//! The crate's own `exp` and `ln` for `f32`.
//!
//! The rasterizer must not depend on the platform's libm (SPEC.md §6–7): `f32::exp` may
//! differ by an ulp between glibc, musl, macOS and a GPU's `__expf`. These functions use only
//! IEEE-754 additions, multiplications, comparisons and bit manipulation, in a fixed order and
//! without fused multiply-add, so they give the same bits on every platform and in every SIMD
//! lane (the lane kernels call exactly this code).
//!
//! `exp`: Cody–Waite range reduction `x = k·ln2 + r`, `|r| <= ln2/2`, then the minimax
//! polynomial of Cephes `expf` (S. Moshier, Cephes Math Library, `expf.c`) and `2^k` built in
//! the exponent bits. Domain `[-87.0, 88.0]` (inputs outside are clamped; NaN gives NaN).
//! Measured error against `f64::exp` over the domain: at most [`EXP_MAX_ULP`] ulp
//! (test `fastexp_error_bound`).
//!
//! `ln`: exponent/mantissa split with the mantissa in `[sqrt(1/2), sqrt(2))`, then the Cephes
//! `logf` polynomial. Domain: positive normal floats; `ln(x <= 0)` returns `-inf` for `0` and
//! NaN for negatives, like libm. Measured error at most [`LN_MAX_ULP`] ulp.

/// Largest error of [`exp`] in ulp of the correctly rounded result, pinned by a test.
pub const EXP_MAX_ULP: u32 = 2;
/// Largest error of [`ln`] in ulp of the correctly rounded result, pinned by a test.
pub const LN_MAX_ULP: u32 = 2;

const LOG2_E: f32 = std::f32::consts::LOG2_E;
/// `ln 2` split so that `k·LN2_HI` is exact for |k| < 2^9 (Cephes `C1`, `C2`).
const LN2_HI: f32 = 0.693_359_4;
const LN2_LO: f32 = -2.121_944_4e-4;
/// Adding and subtracting 1.5·2^23 rounds to the nearest integer (ties to even) for
/// |v| < 2^22, using only additions, so it vectorizes without SSE4.1 `roundps`.
const ROUND_MAGIC: f32 = 12_582_912.0;

/// Cephes `logf` polynomial: `p(m) = (((c0·m + c1)·m + c2)·m + …)·m + c8`.
const LOG_P: [f32; 9] = [
    7.037_683_6e-2,
    -1.151_461e-1,
    1.167_699_9e-1,
    -1.242_014_1e-1,
    1.424_932_3e-1,
    -1.666_805_8e-1,
    2.000_071_4e-1,
    -2.499_999_4e-1,
    0.333_333_33,
];

/// `e^x` for `f32`, platform-independent, no FMA. See the module docs for the error bound.
#[inline(always)]
pub fn exp(x: f32) -> f32 {
    // Clamp by selects (not f32::min/max) so that the NaN behaviour is explicit: NaN fails
    // both comparisons, stays NaN and propagates through the arithmetic below.
    let x = if x < -87.0 { -87.0 } else { x };
    let x = if x > 88.0 { 88.0 } else { x };
    // v = 1.5·2^23 + k exactly, so k is both `v − 1.5·2^23` (as a float) and the low bits of
    // v's representation (as an integer): no float-to-int conversion, which vectorizes.
    let v = x * LOG2_E + ROUND_MAGIC;
    let k = v - ROUND_MAGIC;
    let r = (x - k * LN2_HI) - k * LN2_LO;
    let z = r * r;
    let p = ((((1.987_569_1e-4 * r + 1.398_199_9e-3) * r + 8.333_452e-3) * r + 4.166_579_6e-2) * r
        + 1.666_666_5e-1)
        * r
        + 0.5;
    let y = (p * z + r) + 1.0;
    // 2^k for k in [-126, 127], assembled in the exponent field: bits(v) = 0x4B40_0000 + k.
    let scale = f32::from_bits(v.to_bits().wrapping_sub(0x4B40_0000 - 127) << 23);
    y * scale
}

/// [`exp`] on 8 lanes with AVX2 intrinsics: the same IEEE operations in the same order
/// (no FMA), so every lane equals the scalar result bit for bit (test
/// `exp_and_ln_simd_match_scalar_bitwise`).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub unsafe fn exp_avx2(x: std::arch::x86_64::__m256) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    let c = |v: f32| _mm256_set1_ps(v);
    // `max_ps(a, b)` is `a > b ? a : b` and returns `b` when unordered, so with the constant
    // first these are exactly the scalar selects, NaN kept.
    let x = _mm256_max_ps(c(-87.0), x);
    let x = _mm256_min_ps(c(88.0), x);
    // SAFETY: AVX2 is available (this function's contract); x is now in range.
    unsafe { exp_avx2_in_range(x) }
}

/// [`exp_avx2`] without its two input clamps: for `x` in `[-87, 88]` the same bits (the
/// clamps change nothing there); outside, an unspecified value (above 88 the exponent field
/// wraps, and the result may be subnormal: callers keep masked-out lanes below 88 too). For
/// kernels whose lanes outside the range are masked out anyway (the blends: `x = −min(σ,
/// 30)` of a lane with `σ ≥ 0` lies in `[-30, 0]`), fewer instructions per call.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub unsafe fn exp_avx2_in_range(x: std::arch::x86_64::__m256) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    let c = |v: f32| _mm256_set1_ps(v);
    let v = _mm256_add_ps(_mm256_mul_ps(x, c(LOG2_E)), c(ROUND_MAGIC));
    let k = _mm256_sub_ps(v, c(ROUND_MAGIC));
    let r = _mm256_sub_ps(
        _mm256_sub_ps(x, _mm256_mul_ps(k, c(LN2_HI))),
        _mm256_mul_ps(k, c(LN2_LO)),
    );
    let z = _mm256_mul_ps(r, r);
    let mut p = _mm256_add_ps(_mm256_mul_ps(c(1.987_569_1e-4), r), c(1.398_199_9e-3));
    p = _mm256_add_ps(_mm256_mul_ps(p, r), c(8.333_452e-3));
    p = _mm256_add_ps(_mm256_mul_ps(p, r), c(4.166_579_6e-2));
    p = _mm256_add_ps(_mm256_mul_ps(p, r), c(1.666_666_5e-1));
    p = _mm256_add_ps(_mm256_mul_ps(p, r), c(0.5));
    let y = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(p, z), r), c(1.0));
    let bits = _mm256_sub_epi32(_mm256_castps_si256(v), _mm256_set1_epi32(0x4B40_0000 - 127));
    let scale = _mm256_castsi256_ps(_mm256_slli_epi32::<23>(bits));
    _mm256_mul_ps(y, scale)
}

/// [`exp`] on 16 lanes with AVX-512F intrinsics: the same operations in the same order as
/// [`exp_avx2`], bit for bit the scalar result (test `exp_and_ln_simd_match_scalar_bitwise`).
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
pub unsafe fn exp_avx512(x: std::arch::x86_64::__m512) -> std::arch::x86_64::__m512 {
    use std::arch::x86_64::*;
    let c = |v: f32| _mm512_set1_ps(v);
    // As in `exp_avx2`: `max(c, x)` / `min(c, x)` return x's NaN, the scalar selects.
    let x = _mm512_max_ps(c(-87.0), x);
    let x = _mm512_min_ps(c(88.0), x);
    // SAFETY: AVX-512F is available (this function's contract); x is now in range.
    unsafe { exp_avx512_in_range(x) }
}

/// [`exp_avx512`] without its two input clamps, as [`exp_avx2_in_range`]: the same bits
/// for `x` in `[-87, 88]`, an unspecified value outside (normal, ∞, 0 or NaN: `vscalefps`
/// saturates instead of wrapping).
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
pub unsafe fn exp_avx512_in_range(x: std::arch::x86_64::__m512) -> std::arch::x86_64::__m512 {
    use std::arch::x86_64::*;
    let c = |v: f32| _mm512_set1_ps(v);
    let v = _mm512_add_ps(_mm512_mul_ps(x, c(LOG2_E)), c(ROUND_MAGIC));
    let k = _mm512_sub_ps(v, c(ROUND_MAGIC));
    let r = _mm512_sub_ps(
        _mm512_sub_ps(x, _mm512_mul_ps(k, c(LN2_HI))),
        _mm512_mul_ps(k, c(LN2_LO)),
    );
    let z = _mm512_mul_ps(r, r);
    let mut p = _mm512_add_ps(_mm512_mul_ps(c(1.987_569_1e-4), r), c(1.398_199_9e-3));
    p = _mm512_add_ps(_mm512_mul_ps(p, r), c(8.333_452e-3));
    p = _mm512_add_ps(_mm512_mul_ps(p, r), c(4.166_579_6e-2));
    p = _mm512_add_ps(_mm512_mul_ps(p, r), c(1.666_666_5e-1));
    p = _mm512_add_ps(_mm512_mul_ps(p, r), c(0.5));
    let y = _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(p, z), r), c(1.0));
    // y·2^k in one rounding, as `y·scale` with the scale assembled in the exponent field
    // (the scalar form): k is an integer in [−126, 127] here, so 2^k is a normal f32 and
    // both are the correctly rounded product (`vscalefps` rounds once, like the multiply).
    _mm512_scalef_ps(y, k)
}

/// Natural logarithm for positive normal `f32`, platform-independent, no FMA.
#[inline]
pub fn ln(x: f32) -> f32 {
    if x.is_nan() || x < 0.0 {
        return f32::NAN;
    }
    if x == 0.0 {
        return f32::NEG_INFINITY;
    }
    if x == f32::INFINITY {
        return f32::INFINITY;
    }
    // Subnormals: scale into the normal range first.
    let (x, bias) = if x < f32::MIN_POSITIVE {
        (x * 16_777_216.0, -24i32)
    } else {
        (x, 0)
    };
    let bits = x.to_bits();
    let mut e = ((bits >> 23) & 0xff) as i32 - 126 + bias;
    // Mantissa in [0.5, 1).
    let mut m = f32::from_bits((bits & 0x007f_ffff) | 0x3f00_0000);
    if m < std::f32::consts::FRAC_1_SQRT_2 {
        e -= 1;
        m = (m + m) - 1.0;
    } else {
        m -= 1.0;
    }
    let z = m * m;
    let mut p = LOG_P[0];
    for c in &LOG_P[1..] {
        p = p * m + c;
    }
    let mut y = (p * m) * z;
    let ef = e as f32;
    y += -2.121_944_4e-4 * ef;
    y += -0.5 * z;
    let mut r = m + y;
    r += 0.693_359_4 * ef;
    r
}

/// [`ln`] on 8 lanes with AVX2 intrinsics: the same operations in the same order, special
/// values included, so every lane equals the scalar result bit for bit (test
/// `exp_and_ln_simd_match_scalar_bitwise`).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub unsafe fn ln_avx2(x: std::arch::x86_64::__m256) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    let c = |v: f32| _mm256_set1_ps(v);
    let ci = |v: i32| _mm256_set1_epi32(v);
    // Subnormals: scale into the normal range first (x < MIN_POSITIVE, ordered).
    let sub = _mm256_cmp_ps::<_CMP_LT_OQ>(x, c(f32::MIN_POSITIVE));
    let xs = _mm256_blendv_ps(x, _mm256_mul_ps(x, c(16_777_216.0)), sub);
    let bias = _mm256_and_si256(_mm256_castps_si256(sub), ci(-24));
    let bits = _mm256_castps_si256(xs);
    let e = _mm256_add_epi32(
        _mm256_sub_epi32(
            _mm256_and_si256(_mm256_srli_epi32::<23>(bits), ci(0xff)),
            ci(126),
        ),
        bias,
    );
    let m = _mm256_castsi256_ps(_mm256_or_si256(
        _mm256_and_si256(bits, ci(0x007f_ffff)),
        ci(0x3f00_0000),
    ));
    let low = _mm256_cmp_ps::<_CMP_LT_OQ>(m, c(std::f32::consts::FRAC_1_SQRT_2));
    // e -= 1 where low (the mask is −1 there).
    let e = _mm256_add_epi32(e, _mm256_castps_si256(low));
    let m = _mm256_blendv_ps(
        _mm256_sub_ps(m, c(1.0)),
        _mm256_sub_ps(_mm256_add_ps(m, m), c(1.0)),
        low,
    );
    let z = _mm256_mul_ps(m, m);
    let mut p = c(LOG_P[0]);
    for &k in &LOG_P[1..] {
        p = _mm256_add_ps(_mm256_mul_ps(p, m), c(k));
    }
    let mut y = _mm256_mul_ps(_mm256_mul_ps(p, m), z);
    let ef = _mm256_cvtepi32_ps(e);
    y = _mm256_add_ps(y, _mm256_mul_ps(c(-2.121_944_4e-4), ef));
    y = _mm256_add_ps(y, _mm256_mul_ps(c(-0.5), z));
    let mut r = _mm256_add_ps(m, y);
    r = _mm256_add_ps(r, _mm256_mul_ps(c(0.693_359_4), ef));
    // Special values, in the scalar order: NaN or negative → NaN, 0 → −∞, +∞ → +∞.
    let r = _mm256_blendv_ps(
        r,
        c(f32::INFINITY),
        _mm256_cmp_ps::<_CMP_EQ_OQ>(x, c(f32::INFINITY)),
    );
    let r = _mm256_blendv_ps(
        r,
        c(f32::NEG_INFINITY),
        _mm256_cmp_ps::<_CMP_EQ_OQ>(x, c(0.0)),
    );
    let nan = _mm256_or_ps(
        _mm256_cmp_ps::<_CMP_UNORD_Q>(x, x),
        _mm256_cmp_ps::<_CMP_LT_OQ>(x, c(0.0)),
    );
    _mm256_blendv_ps(r, c(f32::NAN), nan)
}

/// [`ln`] on 16 lanes with AVX-512F intrinsics: [`ln_avx2`]'s operations one for one, bit
/// for bit the scalar result (test `exp_and_ln_simd_match_scalar_bitwise`).
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
pub unsafe fn ln_avx512(x: std::arch::x86_64::__m512) -> std::arch::x86_64::__m512 {
    use std::arch::x86_64::*;
    let c = |v: f32| _mm512_set1_ps(v);
    let ci = |v: i32| _mm512_set1_epi32(v);
    let sub = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(x, c(f32::MIN_POSITIVE));
    let xs = _mm512_mask_blend_ps(sub, x, _mm512_mul_ps(x, c(16_777_216.0)));
    let bias = _mm512_maskz_mov_epi32(sub, ci(-24));
    let bits = _mm512_castps_si512(xs);
    let e = _mm512_add_epi32(
        _mm512_sub_epi32(
            _mm512_and_si512(_mm512_srli_epi32::<23>(bits), ci(0xff)),
            ci(126),
        ),
        bias,
    );
    let m = _mm512_castsi512_ps(_mm512_or_si512(
        _mm512_and_si512(bits, ci(0x007f_ffff)),
        ci(0x3f00_0000),
    ));
    let low = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(m, c(std::f32::consts::FRAC_1_SQRT_2));
    let e = _mm512_mask_sub_epi32(e, low, e, ci(1));
    let m = _mm512_mask_blend_ps(
        low,
        _mm512_sub_ps(m, c(1.0)),
        _mm512_sub_ps(_mm512_add_ps(m, m), c(1.0)),
    );
    let z = _mm512_mul_ps(m, m);
    let mut p = c(LOG_P[0]);
    for &k in &LOG_P[1..] {
        p = _mm512_add_ps(_mm512_mul_ps(p, m), c(k));
    }
    let mut y = _mm512_mul_ps(_mm512_mul_ps(p, m), z);
    let ef = _mm512_cvtepi32_ps(e);
    y = _mm512_add_ps(y, _mm512_mul_ps(c(-2.121_944_4e-4), ef));
    y = _mm512_add_ps(y, _mm512_mul_ps(c(-0.5), z));
    let mut r = _mm512_add_ps(m, y);
    r = _mm512_add_ps(r, _mm512_mul_ps(c(0.693_359_4), ef));
    let inf = _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(x, c(f32::INFINITY));
    let r = _mm512_mask_blend_ps(inf, r, c(f32::INFINITY));
    let zero = _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(x, c(0.0));
    let r = _mm512_mask_blend_ps(zero, r, c(f32::NEG_INFINITY));
    let nan =
        _mm512_cmp_ps_mask::<_CMP_UNORD_Q>(x, x) | _mm512_cmp_ps_mask::<_CMP_LT_OQ>(x, c(0.0));
    _mm512_mask_blend_ps(nan, r, c(f32::NAN))
}

/// Logistic sigmoid `1 / (1 + e^-x)` on top of [`exp`].
#[inline]
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + exp(-x))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance in ulp between an f32 and the correctly rounded f32 of an f64 value.
    fn ulp_error(got: f32, exact: f64) -> u32 {
        let want = exact as f32;
        (got.to_bits() as i64 - want.to_bits() as i64).unsigned_abs() as u32
    }

    #[test]
    fn fastexp_error_bound() {
        let mut worst = 0;
        let n = 2_000_000;
        for i in 0..=n {
            let x = -87.0 + 175.0 * (i as f64 / n as f64);
            let x = x as f32;
            worst = worst.max(ulp_error(exp(x), (x as f64).exp()));
        }
        assert!(worst <= EXP_MAX_ULP, "exp worst error {worst} ulp");
    }

    #[test]
    fn ln_error_bound() {
        let mut worst = 0;
        let mut x = 1e-37f32;
        while x < 1e37 {
            worst = worst.max(ulp_error(ln(x), (x as f64).ln()));
            x *= 1.000_37;
        }
        assert!(worst <= LN_MAX_ULP, "ln worst error {worst} ulp");
        assert_eq!(ln(1.0), 0.0);
        assert_eq!(ln(0.0), f32::NEG_INFINITY);
        assert!(ln(-1.0).is_nan());
    }

    /// `simd` (lanes of `width`) against `scalar`, bit for bit (NaN payloads aside), on
    /// `xs` (truncated to whole vectors).
    #[cfg(target_arch = "x86_64")]
    fn assert_lanes_match(
        xs: &[f32],
        width: usize,
        simd: impl Fn(&[f32], &mut [f32]),
        scalar: impl Fn(f32) -> f32,
        name: &str,
    ) {
        let mut out = vec![0f32; width];
        for chunk in xs.chunks_exact(width) {
            simd(chunk, &mut out);
            for (x, o) in chunk.iter().zip(&out) {
                let want = scalar(*x);
                assert!(
                    o.to_bits() == want.to_bits() || (o.is_nan() && want.is_nan()),
                    "{name}({x:e}) = {o:e}, scalar {want:e}"
                );
            }
        }
    }

    /// Every `stride`-th bit pattern of both signs, plus ±0, ±∞ and NaN.
    #[cfg(target_arch = "x86_64")]
    fn bit_patterns(stride: usize) -> Vec<f32> {
        let mut xs: Vec<f32> = vec![f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.0, -0.0];
        xs.extend((0..=u32::MAX).step_by(stride).map(f32::from_bits));
        xs
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn exp_and_ln_simd_match_scalar_bitwise() {
        use std::arch::x86_64::*;
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY (each closure): AVX2 is available (checked above); chunks have 8 lanes.
            let exp8 = |x: &[f32], o: &mut [f32]| unsafe {
                _mm256_storeu_ps(o.as_mut_ptr(), exp_avx2(_mm256_loadu_ps(x.as_ptr())))
            };
            let ln8 = |x: &[f32], o: &mut [f32]| unsafe {
                _mm256_storeu_ps(o.as_mut_ptr(), ln_avx2(_mm256_loadu_ps(x.as_ptr())))
            };
            assert_lanes_match(&bit_patterns(61), 8, exp8, exp, "exp_avx2");
            assert_lanes_match(&bit_patterns(97), 8, ln8, ln, "ln_avx2");
        }
        if std::is_x86_feature_detected!("avx512f") {
            // SAFETY (each closure): AVX-512F is available (checked above); 16 lanes.
            let exp16 = |x: &[f32], o: &mut [f32]| unsafe {
                _mm512_storeu_ps(o.as_mut_ptr(), exp_avx512(_mm512_loadu_ps(x.as_ptr())))
            };
            let ln16 = |x: &[f32], o: &mut [f32]| unsafe {
                _mm512_storeu_ps(o.as_mut_ptr(), ln_avx512(_mm512_loadu_ps(x.as_ptr())))
            };
            assert_lanes_match(&bit_patterns(61), 16, exp16, exp, "exp_avx512");
            assert_lanes_match(&bit_patterns(97), 16, ln16, ln, "ln_avx512");
        }
    }

    #[test]
    fn exp_special_values() {
        assert_eq!(exp(0.0), 1.0);
        assert!(exp(f32::NAN).is_nan());
        assert!(exp(-1000.0) > 0.0 && exp(-1000.0).is_normal());
        assert!(exp(1000.0).is_finite());
    }
}
