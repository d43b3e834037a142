//! The JSON form of a statistical level that may be +∞ (`eps_at_p_target`): JSON has no
//! infinity, and `serde_json` writes one as `null`, which reads back as "too few states".
//! Here a level is written as a number when finite, as the string `"inf"` when +∞ (every
//! state exceeded, e.g. unlabelled states counted as exceedances), and as `null` only when
//! there is no level (n too small for the target); all three read back.

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// A level as JSON: a number, or `"inf"` (module doc).
#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum Level {
    Number(f64),
    Text(String),
}

fn to_level(v: f64) -> Level {
    if v.is_finite() {
        Level::Number(v)
    } else if v > 0.0 {
        Level::Text("inf".into())
    } else {
        Level::Text(if v < 0.0 { "-inf" } else { "nan" }.into())
    }
}

fn from_level<E: serde::de::Error>(l: Level) -> Result<f64, E> {
    match l {
        Level::Number(v) => Ok(v),
        Level::Text(t) => match t.as_str() {
            "inf" => Ok(f64::INFINITY),
            "-inf" => Ok(f64::NEG_INFINITY),
            "nan" => Ok(f64::NAN),
            _ => Err(E::custom(format!(
                "a statistical level must be a number or \"inf\", got {t:?}"
            ))),
        },
    }
}

/// `f64` with +∞ as `"inf"` (module doc).
pub mod value {
    use super::*;

    /// Writes +∞ as `"inf"`, else the number.
    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        to_level(*v).serialize(s)
    }

    /// Reads a number or `"inf"`.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        from_level(Level::deserialize(d)?)
    }
}

/// `Option<f64>` with +∞ as `"inf"` (module doc).
pub mod option {
    use super::*;

    /// Writes `None` as null, +∞ as `"inf"`, else the number.
    pub fn serialize<S: Serializer>(v: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
        v.map(to_level).serialize(s)
    }

    /// Reads null, a number or `"inf"`.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
        Option::<Level>::deserialize(d)?.map(from_level).transpose()
    }
}

/// `Option<Vec<f64>>` with +∞ entries as `"inf"` (module doc).
pub mod option_vec {
    use super::*;

    /// Writes `None` as null, each +∞ entry as `"inf"`.
    pub fn serialize<S: Serializer>(v: &Option<Vec<f64>>, s: S) -> Result<S::Ok, S::Error> {
        v.as_ref()
            .map(|v| v.iter().map(|x| to_level(*x)).collect::<Vec<_>>())
            .serialize(s)
    }

    /// Reads null, or a list of numbers and `"inf"`s.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Vec<f64>>, D::Error> {
        Option::<Vec<Level>>::deserialize(d)?
            .map(|v| v.into_iter().map(from_level).collect())
            .transpose()
    }
}

#[cfg(test)]
mod tests {
    use serde::{Deserialize, Serialize};

    #[derive(Serialize, Deserialize, Debug, PartialEq)]
    struct T {
        #[serde(with = "super::option")]
        a: Option<f64>,
        #[serde(with = "super::option_vec")]
        b: Option<Vec<f64>>,
    }

    #[test]
    fn infinity_is_written_as_inf_never_as_null_and_reads_back() {
        let t = T {
            a: Some(f64::INFINITY),
            b: Some(vec![1.5, f64::INFINITY]),
        };
        let text = serde_json::to_string(&t).unwrap();
        assert_eq!(text, r#"{"a":"inf","b":[1.5,"inf"]}"#);
        assert_eq!(serde_json::from_str::<T>(&text).unwrap(), t);
        let none = T { a: None, b: None };
        let text = serde_json::to_string(&none).unwrap();
        assert_eq!(text, r#"{"a":null,"b":null}"#);
        assert_eq!(serde_json::from_str::<T>(&text).unwrap(), none);
        let finite: T = serde_json::from_str(r#"{"a":0.25,"b":[0.5]}"#).unwrap();
        assert_eq!(finite.a, Some(0.25));
        assert!(serde_json::from_str::<T>(r#"{"a":"big","b":null}"#).is_err());
    }
}
