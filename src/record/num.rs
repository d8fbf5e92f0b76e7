//! JSON encodings of floats that survive non-finite values.
//!
//! * Observations, actions, rewards and info values: finite numbers are written as JSON
//!   numbers (shortest round-trip form, read back bitwise), non-finite ones as `null`, which
//!   reads back as NaN.
//! * Space bounds (metadata): finite values widened to f64, `±inf` / NaN as the strings
//!   `"inf"`, `"-inf"`, `"nan"`, so that unbounded spaces keep their sign.

use serde::de::{MapAccess, Visitor};
use serde::ser::{SerializeMap, SerializeSeq};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

fn opt32(x: f32) -> Option<f32> {
    x.is_finite().then_some(x)
}

fn opt64(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

/// `&[f32]` ↔ `[number | null]`.
pub(crate) mod f32s {
    use super::*;

    pub(crate) fn serialize<S: Serializer>(v: &[f32], s: S) -> Result<S::Ok, S::Error> {
        let mut seq = s.serialize_seq(Some(v.len()))?;
        for &x in v {
            seq.serialize_element(&opt32(x))?;
        }
        seq.end()
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f32>, D::Error> {
        let v = Vec::<Option<f32>>::deserialize(d)?;
        Ok(v.into_iter().map(|x| x.unwrap_or(f32::NAN)).collect())
    }

    /// An optional field written only when present (with `skip_serializing_if`).
    pub(crate) fn serialize_some<S: Serializer>(
        v: &Option<&[f32]>,
        s: S,
    ) -> Result<S::Ok, S::Error> {
        serialize(v.unwrap_or(&[]), s)
    }

    /// An optional field: present, it reads as [`deserialize`] does.
    pub(crate) fn deserialize_some<'de, D: Deserializer<'de>>(
        d: D,
    ) -> Result<Option<Vec<f32>>, D::Error> {
        deserialize(d).map(Some)
    }
}

/// `f32` ↔ `number | null`.
pub(crate) mod f32n {
    use super::*;

    pub(crate) fn serialize<S: Serializer>(v: &f32, s: S) -> Result<S::Ok, S::Error> {
        opt32(*v).serialize(s)
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f32, D::Error> {
        Ok(Option::<f32>::deserialize(d)?.unwrap_or(f32::NAN))
    }
}

/// `f64` ↔ `number | null`.
pub(crate) mod f64n {
    use super::*;

    pub(crate) fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        opt64(*v).serialize(s)
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
    }
}

/// An ordered list of `(key, value)` ↔ a JSON object `{key: number | null}` that keeps the
/// written key order when read back.
pub(crate) mod ordered_map {
    use super::*;

    pub(crate) fn serialize<S: Serializer>(v: &[(String, f64)], s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(v.len()))?;
        for (k, x) in v {
            m.serialize_entry(k, &opt64(*x))?;
        }
        m.end()
    }

    struct V;

    impl<'de> Visitor<'de> for V {
        type Value = Vec<(String, f64)>;

        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("an object of numbers")
        }

        fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
            let mut out = Vec::new();
            while let Some((k, v)) = map.next_entry::<String, Option<f64>>()? {
                out.push((k, v.unwrap_or(f64::NAN)));
            }
            Ok(out)
        }
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(
        d: D,
    ) -> Result<Vec<(String, f64)>, D::Error> {
        d.deserialize_map(V)
    }
}

/// Space bounds: `&[f32]` ↔ `[number | "inf" | "-inf" | "nan"]` (numbers widened to f64,
/// exact both ways).
pub(crate) mod bounds {
    use super::*;

    #[derive(Serialize, Deserialize)]
    #[serde(untagged)]
    enum Bound {
        Num(f64),
        Str(String),
    }

    pub(crate) fn serialize<S: Serializer>(v: &[f32], s: S) -> Result<S::Ok, S::Error> {
        let mut seq = s.serialize_seq(Some(v.len()))?;
        for &x in v {
            let b = if x.is_finite() {
                Bound::Num(x as f64)
            } else if x.is_nan() {
                Bound::Str("nan".into())
            } else if x > 0.0 {
                Bound::Str("inf".into())
            } else {
                Bound::Str("-inf".into())
            };
            seq.serialize_element(&b)?;
        }
        seq.end()
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f32>, D::Error> {
        let v = Vec::<Bound>::deserialize(d)?;
        v.into_iter()
            .map(|b| match b {
                Bound::Num(x) => Ok(x as f32),
                Bound::Str(s) => match s.as_str() {
                    "inf" => Ok(f32::INFINITY),
                    "-inf" => Ok(f32::NEG_INFINITY),
                    "nan" => Ok(f32::NAN),
                    _ => Err(serde::de::Error::custom(format!("bad bound {s:?}"))),
                },
            })
            .collect()
    }
}
