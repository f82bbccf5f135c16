//! `floor` and `ceil` of f32 without a libm call: the default x86-64 target has no
//! `roundss` (SSE4.1), so `f32::floor` / `f32::ceil` compile to calls into libm, ~1 % of a
//! training iteration (benches/README.md). These are exact — bit for bit `f32::floor` /
//! `f32::ceil`, the sign of zero included — for every f32 (test
//! `floor_and_ceil_match_std_bit_for_bit`).

/// Below this magnitude an f32 may have a fractional part; at or above it (and for NaN and
/// infinities) the value is its own floor and ceil.
const INTEGRAL_FROM: f32 = 8_388_608.0; // 2^23

/// `x.floor()`, bit for bit.
#[inline(always)]
pub fn floor(x: f32) -> f32 {
    if x.is_nan() || x.abs() >= INTEGRAL_FROM {
        return x;
    }
    let t = x as i32 as f32; // truncation towards zero, exact below 2^23
    let f = if t > x { t - 1.0 } else { t };
    if f == 0.0 { f32::copysign(0.0, x) } else { f }
}

/// `x.ceil()`, bit for bit.
#[inline(always)]
pub fn ceil(x: f32) -> f32 {
    if x.is_nan() || x.abs() >= INTEGRAL_FROM {
        return x;
    }
    let t = x as i32 as f32;
    let c = if t < x { t + 1.0 } else { t };
    if c == 0.0 { f32::copysign(0.0, x) } else { c }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_and_ceil_match_std_bit_for_bit() {
        let special = [
            0.0f32,
            -0.0,
            0.3,
            -0.3,
            0.5,
            -0.5,
            1.0,
            -1.0,
            1.5,
            -1.5,
            8_388_607.5,
            -8_388_607.5,
            8_388_608.0,
            -8_388_608.0,
            16_777_217.0,
            f32::MAX,
            f32::MIN,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            1e-45,
            -1e-45,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        let check = |x: f32| {
            assert_eq!(floor(x).to_bits(), x.floor().to_bits(), "floor({x:e})");
            assert_eq!(ceil(x).to_bits(), x.ceil().to_bits(), "ceil({x:e})");
        };
        special.iter().copied().for_each(check);
        // Every 97th bit pattern: all exponents, both signs, NaN payloads included.
        let mut b = 0u32;
        loop {
            let x = f32::from_bits(b);
            if x.is_nan() {
                assert!(floor(x).is_nan() && ceil(x).is_nan());
            } else {
                check(x);
            }
            match b.checked_add(97) {
                Some(n) => b = n,
                None => break,
            }
        }
    }
}
