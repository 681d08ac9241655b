//! The config form of [`DistillSettings`]: one flat table, as a method config's `[rgb]` and
//! `[normal]` tables write it.
//!
//! ```toml
//! method = "csd"        # sds | csd | bsd (and "none" where the guidance is optional)
//! w1 = 7.5              # CSD / BSD: weight of eps(y)
//! w2 = 6.5              # CSD / BSD: weight of eps(y_neg), subtracted
//! w3 = -1.0             # CSD only: weight of eps(null) (default w2 - w1)
//! # guidance_scale = 7.5  (SDS only: classifier-free guidance scale)
//! weighting = "one_minus_alpha_bar"   # or "constant"
//! grad_clamp = 1.0      # optional
//! [timesteps]           # optional: t_min, t_max, schedule
//! ```
//!
//! The table deserialises straight into [`DistillSettings`] (whose `guidance` is the one
//! [`GuidanceMethod`]); a weight missing for its method, a weight that does not apply to it,
//! an unknown key or an invalid value is an error naming it. [`optional`] reads and writes an
//! `Option<DistillSettings>`, with `method = "none"` for `None`.

use serde::{Deserialize, Serialize};

use super::guidance_method::GuidanceMethod;
use super::step::DistillSettings;
use super::timestep::{TimestepConfig, Weighting};

/// The method names a table takes.
pub const METHOD_NAMES: [&str; 4] = ["none", "sds", "csd", "bsd"];

/// The flat table (see the module docs).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SettingsTable {
    method: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    guidance_scale: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    w1: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    w2: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    w3: Option<f32>,
    #[serde(default)]
    timesteps: TimestepConfig,
    #[serde(default)]
    weighting: Weighting,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    grad_clamp: Option<f32>,
}

impl SettingsTable {
    /// The settings, `None` for `method = "none"`, or what is wrong (one line).
    pub fn into_settings(self) -> Result<Option<DistillSettings>, String> {
        let method = self.method.as_str();
        let need = |name: &str, v: Option<f32>| {
            v.ok_or_else(|| format!("method = \"{method}\" needs `{name}`"))
        };
        let unused = |name: &str, v: Option<f32>| match v {
            Some(_) => Err(format!("`{name}` does not apply to method = \"{method}\"")),
            None => Ok(()),
        };
        let guidance = match method {
            "none" => return Ok(None),
            "sds" => {
                for (name, v) in [("w1", self.w1), ("w2", self.w2), ("w3", self.w3)] {
                    unused(name, v)?;
                }
                GuidanceMethod::Sds {
                    guidance_scale: need("guidance_scale", self.guidance_scale)?,
                }
            }
            "csd" => {
                unused("guidance_scale", self.guidance_scale)?;
                GuidanceMethod::Csd {
                    w1: need("w1", self.w1)?,
                    w2: need("w2", self.w2)?,
                    w3: self.w3,
                }
            }
            "bsd" => {
                unused("guidance_scale", self.guidance_scale)?;
                unused("w3", self.w3)?;
                GuidanceMethod::Bsd {
                    w1: need("w1", self.w1)?,
                    w2: need("w2", self.w2)?,
                }
            }
            other => {
                return Err(format!(
                    "unknown method \"{other}\": expected one of {}",
                    METHOD_NAMES.join(", ")
                ))
            }
        };
        let settings = DistillSettings {
            guidance,
            timesteps: self.timesteps,
            weighting: self.weighting,
            grad_clamp: self.grad_clamp,
        };
        settings.validate().map_err(|e| e.to_string())?;
        Ok(Some(settings))
    }

    /// The table of `settings` (`method = "none"` for `None`).
    pub fn of(settings: Option<&DistillSettings>) -> Self {
        let mut table = SettingsTable {
            method: "none".into(),
            guidance_scale: None,
            w1: None,
            w2: None,
            w3: None,
            timesteps: TimestepConfig::default(),
            weighting: Weighting::default(),
            grad_clamp: None,
        };
        let Some(s) = settings else {
            return table;
        };
        table.method = s.guidance.name().into();
        match s.guidance {
            GuidanceMethod::Sds { guidance_scale } => table.guidance_scale = Some(guidance_scale),
            GuidanceMethod::Csd { w1, w2, w3 } => {
                (table.w1, table.w2, table.w3) = (Some(w1), Some(w2), w3);
            }
            GuidanceMethod::Bsd { w1, w2 } => (table.w1, table.w2) = (Some(w1), Some(w2)),
        }
        table.timesteps = s.timesteps;
        table.weighting = s.weighting;
        table.grad_clamp = s.grad_clamp;
        table
    }
}

impl TryFrom<SettingsTable> for DistillSettings {
    type Error = String;

    fn try_from(table: SettingsTable) -> Result<Self, String> {
        table
            .into_settings()?
            .ok_or_else(|| "method = \"none\" is not a guidance here".to_string())
    }
}

impl From<DistillSettings> for SettingsTable {
    fn from(settings: DistillSettings) -> Self {
        SettingsTable::of(Some(&settings))
    }
}

/// `#[serde(with = "...::settings_table::optional")]` for an `Option<DistillSettings>`
/// field: the flat table, with `method = "none"` for `None`.
pub mod optional {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    use super::{DistillSettings, SettingsTable};

    /// Writes `method = "none"` for `None`.
    pub fn serialize<S: Serializer>(
        value: &Option<DistillSettings>,
        serializer: S,
    ) -> Result<S::Ok, S::Error> {
        SettingsTable::of(value.as_ref()).serialize(serializer)
    }

    /// Reads the table; `method = "none"` is `None`.
    pub fn deserialize<'de, D: Deserializer<'de>>(
        deserializer: D,
    ) -> Result<Option<DistillSettings>, D::Error> {
        SettingsTable::deserialize(deserializer)?
            .into_settings()
            .map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;

    /// A config with one optional guidance, as a method config holds `[rgb]`.
    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Holder {
        #[serde(default, with = "optional")]
        rgb: Option<DistillSettings>,
    }

    fn read(table: serde_json::Value) -> Result<Option<DistillSettings>, String> {
        serde_json::from_value::<Holder>(json!({ "rgb": table }))
            .map(|h| h.rgb)
            .map_err(|e| e.to_string())
    }

    #[test]
    fn each_method_reads_into_the_one_guidance_type_and_writes_back() {
        let bsd = read(json!({"method": "bsd", "w1": 7.5, "w2": 6.5})).unwrap();
        assert_eq!(bsd, Some(DistillSettings::paper_rgb()));
        let csd = read(json!({"method": "csd", "w1": 1.0, "w2": 2.0, "grad_clamp": 0.5}));
        let csd = csd.unwrap().unwrap();
        assert_eq!(
            csd.guidance,
            GuidanceMethod::Csd {
                w1: 1.0,
                w2: 2.0,
                w3: None
            }
        );
        assert_eq!(csd.grad_clamp, Some(0.5));
        let sds = read(json!({"method": "sds", "guidance_scale": 100.0, "weighting": "constant"}));
        let sds = sds.unwrap().unwrap();
        assert_eq!(
            sds.guidance,
            GuidanceMethod::Sds {
                guidance_scale: 100.0
            }
        );
        assert_eq!(sds.weighting, Weighting::Constant);
        assert_eq!(read(json!({"method": "none"})).unwrap(), None);
        assert_eq!(
            serde_json::from_value::<Holder>(json!({})).unwrap().rgb,
            None
        );
        for settings in [Some(csd), Some(sds), None] {
            let holder = Holder { rgb: settings };
            let text = serde_json::to_string(&holder).unwrap();
            assert_eq!(
                serde_json::from_str::<Holder>(&text).unwrap(),
                holder,
                "{text}"
            );
        }
        let none = serde_json::to_value(Holder { rgb: None }).unwrap();
        assert_eq!(none["rgb"]["method"], "none");
    }

    #[test]
    fn a_wrong_table_is_an_error_naming_the_key() {
        let cases = [
            (
                json!({"method": "bsd", "w1": 1.0}),
                "method = \"bsd\" needs `w2`",
            ),
            (
                json!({"method": "bsd", "w1": 1.0, "w2": 0.5, "w3": 0.0}),
                "`w3` does not apply to method = \"bsd\"",
            ),
            (
                json!({"method": "sds", "guidance_scale": 7.5, "w1": 1.0}),
                "`w1` does not apply to method = \"sds\"",
            ),
            (json!({"method": "sds"}), "needs `guidance_scale`"),
            (
                json!({"method": "dds", "w1": 1.0}),
                "unknown method \"dds\": expected one of none",
            ),
            (
                json!({"method": "bsd", "w1": 1.0, "w2": 0.5, "w_1": 2.0}),
                "unknown field `w_1`",
            ),
            (
                json!({"method": "bsd", "w1": 1.0, "w2": 0.5, "grad_clamp": 0.0}),
                "grad_clamp = 0 must be > 0",
            ),
            (
                json!({"method": "csd", "w1": 1.0, "w2": 0.5,
                       "timesteps": {"t_min": 0.0, "t_max": 0.98, "schedule": {"kind": "uniform"}}}),
                "t_min = 0 is outside (0, 1)",
            ),
        ];
        for (table, want) in cases {
            let err = read(table.clone()).unwrap_err();
            assert!(err.contains(want), "{table}: {err}");
        }
        let nan = DistillSettings {
            guidance: GuidanceMethod::Bsd {
                w1: f32::NAN,
                w2: 0.5,
            },
            ..DistillSettings::paper_rgb()
        };
        assert!(nan.validate().unwrap_err().to_string().contains("w1 = NaN"));
        let err = serde_json::from_value::<DistillSettings>(json!({"method": "none"}));
        assert!(err.unwrap_err().to_string().contains("not a guidance here"));
    }
}
