//! JSON encoding of `f64` values that may be non-finite (SPEC.md §20.7): a finite value is
//! a number; NaN (a metric of an empty pixel class, a statistic of one sample) is `null`;
//! +∞ (the PSNR of identical images) is the string `"inf"` and −∞ `"-inf"`. JSON has no
//! number for either, and serde_json would write `null` for them, which reads back as NaN
//! (or fails): the stated encoding round-trips every `f64` bit for bit. Use with
//! `#[serde(with = "crate::io::json_float")]`; [`show`] prints the same values for people.

use serde::Serializer;
use serde::de::{self, Deserializer, Visitor};

/// The string of +∞.
pub const INF: &str = "inf";
/// The string of −∞.
pub const NEG_INF: &str = "-inf";

pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
    if v.is_finite() {
        s.serialize_f64(*v)
    } else if v.is_nan() {
        s.serialize_none()
    } else if *v > 0.0 {
        s.serialize_str(INF)
    } else {
        s.serialize_str(NEG_INF)
    }
}

pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    struct V;
    impl<'de> Visitor<'de> for V {
        type Value = f64;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            write!(f, "a number, null (NaN), \"{INF}\" or \"{NEG_INF}\"")
        }
        fn visit_f64<E: de::Error>(self, v: f64) -> Result<f64, E> {
            Ok(v)
        }
        fn visit_i64<E: de::Error>(self, v: i64) -> Result<f64, E> {
            Ok(v as f64)
        }
        fn visit_u64<E: de::Error>(self, v: u64) -> Result<f64, E> {
            Ok(v as f64)
        }
        fn visit_unit<E: de::Error>(self) -> Result<f64, E> {
            Ok(f64::NAN)
        }
        fn visit_none<E: de::Error>(self) -> Result<f64, E> {
            Ok(f64::NAN)
        }
        fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<f64, D::Error> {
            d.deserialize_any(V)
        }
        fn visit_str<E: de::Error>(self, v: &str) -> Result<f64, E> {
            match v {
                INF => Ok(f64::INFINITY),
                NEG_INF => Ok(f64::NEG_INFINITY),
                _ => Err(E::invalid_value(de::Unexpected::Str(v), &self)),
            }
        }
    }
    d.deserialize_any(V)
}

/// `v` with `digits` decimals for a report: `∞` / `−∞` for the infinities, `NaN` as is.
pub fn show(v: f64, digits: usize) -> String {
    if v == f64::INFINITY {
        "∞".into()
    } else if v == f64::NEG_INFINITY {
        "−∞".into()
    } else {
        format!("{v:.digits$}")
    }
}

#[cfg(test)]
mod tests {
    #[derive(serde::Serialize, serde::Deserialize, PartialEq, Debug)]
    struct T(#[serde(with = "super")] f64);

    #[test]
    fn every_value_round_trips_and_shows() {
        for v in [
            0.0,
            -0.0,
            1.5,
            f64::MAX,
            f64::MIN_POSITIVE,
            5e-324,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ] {
            let s = serde_json::to_string(&T(v)).unwrap();
            let back: T = serde_json::from_str(&s).unwrap();
            assert_eq!(back.0.to_bits(), v.to_bits(), "{v} as {s}");
        }
        assert_eq!(serde_json::to_string(&T(f64::INFINITY)).unwrap(), "\"inf\"");
        let nan: T = serde_json::from_str(&serde_json::to_string(&T(f64::NAN)).unwrap()).unwrap();
        assert!(nan.0.is_nan());
        assert!(serde_json::from_str::<T>("\"Infinity\"").is_err());
        assert!(serde_json::from_str::<T>("3").is_ok_and(|t| t.0 == 3.0));
        assert_eq!(super::show(f64::INFINITY, 2), "∞");
        assert_eq!(super::show(12.345, 2), "12.35");
    }
}
