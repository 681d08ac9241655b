//! A guidance weight of a method: a number, or `"auto"` (the scene picks it from
//! `[auto]`'s candidates before the run; see [`crate::auto`]).

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// `lambda_rgb` / `lambda_normal`: a fixed weight or `"auto"`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Weight {
    /// This weight.
    Fixed(f64),
    /// Chosen per scene by [`crate::auto::choose_weights`].
    Auto,
}

impl Weight {
    /// The weight; an unresolved `"auto"` reads 0 (the trainer refuses to start with one).
    pub fn value(self) -> f64 {
        match self {
            Weight::Fixed(v) => v,
            Weight::Auto => 0.0,
        }
    }

    /// Whether the scene picks it.
    pub fn is_auto(self) -> bool {
        self == Weight::Auto
    }
}

impl From<f64> for Weight {
    fn from(v: f64) -> Self {
        Weight::Fixed(v)
    }
}

impl Serialize for Weight {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Weight::Fixed(v) => s.serialize_f64(*v),
            Weight::Auto => s.serialize_str("auto"),
        }
    }
}

impl<'de> Deserialize<'de> for Weight {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Number(f64),
            Integer(i64),
            Word(String),
        }
        match Raw::deserialize(d)? {
            Raw::Number(v) => Ok(Weight::Fixed(v)),
            Raw::Integer(v) => Ok(Weight::Fixed(v as f64)),
            Raw::Word(w) if w == "auto" => Ok(Weight::Auto),
            Raw::Word(w) => Err(serde::de::Error::custom(format!(
                "expected a number or \"auto\", found \"{w}\""
            ))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Deserialize, Serialize)]
    struct T {
        w: Weight,
    }

    #[test]
    fn reads_numbers_and_auto_and_writes_them_back() {
        let n: T = toml::from_str("w = 1e-5").unwrap();
        assert_eq!(n.w, Weight::Fixed(1e-5));
        let i: T = toml::from_str("w = 0").unwrap();
        assert_eq!(i.w, Weight::Fixed(0.0));
        let a: T = toml::from_str("w = \"auto\"").unwrap();
        assert_eq!(a.w, Weight::Auto);
        assert_eq!(toml::to_string(&a).unwrap().trim(), "w = \"auto\"");
        assert_eq!(
            toml::from_str::<T>(&toml::to_string(&n).unwrap())
                .unwrap()
                .w,
            n.w
        );
        let e = toml::from_str::<T>("w = \"big\"").unwrap_err().to_string();
        assert!(e.contains("\"auto\""), "{e}");
    }
}
