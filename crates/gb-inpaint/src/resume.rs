//! What the guided trainer keeps in a checkpoint besides gb-nerf's reconstruction state
//! (field, Adam, occupancy grid, random stream: `gb_nerf::train::checkpoint`), so that a run
//! killed after a checkpoint and resumed writes the same log and metrics as an
//! uninterrupted one:
//!
//! - the run's identity (the method, the resolved prompts and the prior), which a strict
//!   resume ([`crate::GuidedTrainer::resume_matching`]) compares field by field, refusing a
//!   checkpoint of another run with one line naming the field;
//! - the whole run's counters ([`RunTotals`]: guided, unguided and skipped steps, U-Net
//!   calls, field evaluations, step timings);
//! - the visibility maps of the guided views (each computed from the field at the step it
//!   was made, which a resumed run could not rebuild).
//!
//! The guidance's view, timestep and noise need no state: each is drawn from a seed derived
//! from `(seed, step, modality)` (see [`crate::trainer`]). Floats are stored as their bits:
//! serde_json's default float parser does not round-trip every decimal exactly.

use std::path::Path;

use gb_nerf::train::checkpoint::first_difference;
use gb_nerf::train::{NerfConfig, NerfError};
use serde::{Deserialize, Serialize};

use crate::method::{MethodConfig, Prompts};
use crate::prior::PriorInfo;
use crate::visibility::ObservedMap;

/// `f64` fields as `f64::to_bits` (exact through JSON).
mod f64_bits {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u64(v.to_bits())
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        u64::deserialize(d).map(f64::from_bits)
    }
}

/// Counters of a whole run (all processes of a resumed run together), kept in the
/// checkpoint.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RunTotals {
    /// Steps skipped for a non-finite loss.
    pub skipped_steps: usize,
    /// Steps with at least one guidance term.
    pub guided_steps: usize,
    /// Steps without guidance.
    pub unguided_steps: usize,
    /// U-Net calls.
    pub unet_calls: usize,
    /// Sum over the steps of the ray batches' field evaluations per ray.
    #[serde(with = "f64_bits")]
    pub evaluations_per_ray_sum: f64,
    /// Wall time of the guided steps, s.
    #[serde(with = "f64_bits")]
    pub guided_seconds: f64,
    /// Wall time of the unguided steps, s.
    #[serde(with = "f64_bits")]
    pub unguided_seconds: f64,
}

/// An [`ObservedMap`] as stored: the flags as a string of `0` and `1`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SavedMap {
    /// Training-view index.
    pub view: usize,
    /// Side of the grid.
    pub resolution: usize,
    /// Row-major observed flags, `'0'` / `'1'`.
    pub observed: String,
    /// Masked pixels of the grid.
    pub masked: usize,
    /// Step of the field it was computed from.
    pub step: usize,
}

impl SavedMap {
    /// The stored form of `map` of training view `view`.
    pub fn new(view: usize, map: &ObservedMap) -> Self {
        Self {
            view,
            resolution: map.resolution,
            observed: map
                .observed
                .iter()
                .map(|o| if *o { '1' } else { '0' })
                .collect(),
            masked: map.masked,
            step: map.step,
        }
    }

    /// The view index and its map.
    pub fn to_map(&self) -> (usize, ObservedMap) {
        (
            self.view,
            ObservedMap {
                resolution: self.resolution,
                observed: self.observed.chars().map(|c| c == '1').collect(),
                masked: self.masked,
                step: self.step,
            },
        )
    }
}

/// The guided trainer's part of a checkpoint (gb-nerf's `meta.extra`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GuidedState {
    /// The run's identity as TOML text ([`identity`]).
    pub identity_toml: String,
    /// The whole run's counters.
    pub totals: RunTotals,
    /// Visibility maps of the guided views, by view.
    pub visibility: Vec<SavedMap>,
    /// The pixels carried from the reference views ([`crate::reference`]); absent in runs
    /// without a reference (and in checkpoints from before references).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_carry: Option<crate::reference::CarriedSet>,
}

/// The identity of a run: `method` (without its free-text `description`) and, for guided
/// methods, the resolved `prompts` and the `prior` (folder, LoRA, shapes).
pub fn identity(
    method: &MethodConfig,
    guidance: Option<(&PriorInfo, &Prompts)>,
) -> Result<toml::Value, String> {
    let mut t = toml::Table::new();
    let mut m = toml::Value::try_from(method).map_err(|e| e.to_string())?;
    if let Some(m) = m.as_table_mut() {
        m.remove("description");
    }
    t.insert("method".into(), m);
    if let Some((prior, prompts)) = guidance {
        t.insert(
            "prior".into(),
            toml::Value::try_from(prior).map_err(|e| e.to_string())?,
        );
        t.insert(
            "prompts".into(),
            toml::Value::try_from(prompts).map_err(|e| e.to_string())?,
        );
    }
    Ok(toml::Value::Table(t))
}

/// A field whose value differs between a checkpoint and the run that reads it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Difference {
    /// The dotted path of the field (`preset.train.rays_per_batch`, `method.name`).
    pub field: String,
    /// Its value in the checkpoint.
    pub theirs: String,
    /// Its value in this run.
    pub ours: String,
}

impl From<(String, String, String)> for Difference {
    fn from((field, theirs, ours): (String, String, String)) -> Self {
        Self {
            field,
            theirs,
            ours,
        }
    }
}

impl std::fmt::Display for Difference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "written with {} = {}, this run has {}",
            self.field, self.theirs, self.ours
        )
    }
}

/// The first difference of two tables, looking at their `key` first (the most telling
/// difference: another preset or method by name).
fn name_first(prefix: &str, key: &str, a: &toml::Value, b: &toml::Value) -> Option<Difference> {
    match (a.get(key), b.get(key)) {
        (Some(x), Some(y)) if x != y => {
            Some((format!("{prefix}.{key}"), x.to_string(), y.to_string()).into())
        }
        _ => first_difference(prefix, a, b).map(Difference::from),
    }
}

fn refusal(path: &Path, d: Difference) -> NerfError {
    NerfError::Checkpoint {
        path: path.to_path_buf(),
        reason: format!("{d}; resume with the same settings, or start afresh without --resume"),
    }
}

/// The first field where the preset `given` differs from `stored`, but for `train.steps` and
/// `train.checkpoint_every` (which may change on resume: the run is extended, or checkpointed
/// at another cadence).
pub fn preset_difference(
    stored: &NerfConfig,
    given: &NerfConfig,
) -> Result<Option<Difference>, toml::ser::Error> {
    let mut given = given.clone();
    given.train.steps = stored.train.steps;
    given.train.checkpoint_every = stored.train.checkpoint_every;
    let (a, b) = (
        toml::Value::try_from(stored)?,
        toml::Value::try_from(&given)?,
    );
    Ok(name_first("preset", "name", &a, &b))
}

/// Refuses (naming `path` and the first differing field) a checkpoint whose preset differs
/// from `given` ([`preset_difference`]).
pub fn check_preset(path: &Path, stored: &NerfConfig, given: &NerfConfig) -> Result<(), NerfError> {
    let difference = preset_difference(stored, given).map_err(|e| NerfError::Checkpoint {
        path: path.to_path_buf(),
        reason: format!("config: {e}"),
    })?;
    match difference {
        Some(d) => Err(refusal(path, d)),
        None => Ok(()),
    }
}

/// The first difference of the run identity `current` from a checkpoint's (`stored_toml`,
/// [`identity`]): anywhere when `strict`, else only in the method's name.
pub fn identity_difference(
    stored_toml: &str,
    current: &toml::Value,
    strict: bool,
) -> Result<Option<Difference>, toml::de::Error> {
    let stored: toml::Value = toml::from_str(stored_toml)?;
    let name = |v: &toml::Value| v.get("method").and_then(|m| m.get("name")).cloned();
    let by_name = match (name(&stored), name(current)) {
        (Some(a), Some(b)) if a != b => {
            Some(("method.name".to_string(), a.to_string(), b.to_string()).into())
        }
        _ => None,
    };
    Ok(by_name.or_else(|| {
        strict
            .then(|| first_difference("", &stored, current))
            .flatten()
            .map(Difference::from)
    }))
}

/// Refuses a checkpoint whose run identity (`stored_toml`, [`identity`]) differs from
/// `current` ([`identity_difference`]).
pub fn check_identity(
    path: &Path,
    stored_toml: &str,
    current: &toml::Value,
    strict: bool,
) -> Result<(), NerfError> {
    let difference =
        identity_difference(stored_toml, current, strict).map_err(|e| NerfError::Checkpoint {
            path: path.to_path_buf(),
            reason: format!("run identity: {e}"),
        })?;
    match difference {
        Some(d) => Err(refusal(path, d)),
        None => Ok(()),
    }
}

/// Drops from the JSONL log at `path` every line that is not a complete JSON object with a
/// `step` below `step` (the lines a killed run wrote after its last checkpoint, and a line
/// cut by the kill), so that the resumed run's lines follow on exactly. A missing log is
/// left missing.
pub fn truncate_log(path: &Path, step: usize) -> std::io::Result<()> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(e),
    };
    let mut kept = String::new();
    for line in text.lines() {
        let earlier = serde_json::from_str::<serde_json::Value>(line)
            .ok()
            .and_then(|v| v.get("step").and_then(|s| s.as_u64()))
            .is_some_and(|s| (s as usize) < step);
        if earlier {
            kept.push_str(line);
            kept.push('\n');
        }
    }
    if kept.len() != text.len() {
        gb_core::write_atomic(path, kept.as_bytes())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn totals_and_maps_round_trip_exactly_through_json() {
        let totals = RunTotals {
            skipped_steps: 1,
            guided_steps: 2,
            unguided_steps: 3,
            unet_calls: 4,
            evaluations_per_ray_sum: 0.1 + 0.2,
            guided_seconds: 1.0 / 3.0,
            unguided_seconds: std::f64::consts::PI,
        };
        let map = ObservedMap {
            resolution: 2,
            observed: vec![true, false, false, true],
            masked: 3,
            step: 7,
        };
        let state = GuidedState {
            identity_toml: String::new(),
            totals: totals.clone(),
            visibility: vec![SavedMap::new(5, &map)],
            reference_carry: Some(crate::reference::CarriedSet {
                step: 3,
                pixels: vec![crate::reference::CarriedPixel {
                    view: 1,
                    x: 2,
                    y: 4,
                    rgb: [0.1, 0.2, 0.7],
                    depth: 2.5,
                }],
                tested: 9,
                anchors: vec![vec![1.5, 3.25]],
                observed: vec![vec![true, false]],
            }),
        };
        let back: GuidedState =
            serde_json::from_str(&serde_json::to_string(&state).unwrap()).unwrap();
        assert_eq!(back.reference_carry, state.reference_carry);
        let without = GuidedState {
            reference_carry: None,
            ..state.clone()
        };
        let text = serde_json::to_string(&without).unwrap();
        assert!(!text.contains("reference_carry"), "{text}");
        assert_eq!(back.totals, totals);
        assert_eq!(back.visibility[0].to_map(), (5, map));
    }

    #[test]
    fn the_log_keeps_only_complete_lines_before_the_step() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("train_log.jsonl");
        std::fs::write(
            &path,
            "{\"step\":0}\n{\"step\":1}\n{\"step\":2}\n{\"step\":3}\n{\"st",
        )
        .unwrap();
        truncate_log(&path, 2).unwrap();
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            "{\"step\":0}\n{\"step\":1}\n"
        );
        truncate_log(&dir.path().join("missing.jsonl"), 2).unwrap();
        assert!(!dir.path().join("missing.jsonl").exists());
    }

    #[test]
    fn a_different_preset_is_refused_naming_the_field_and_the_file() {
        let a = NerfConfig::preset("fast").unwrap();
        let mut b = a.clone();
        b.train.steps += 10;
        b.train.checkpoint_every = 1;
        let path = Path::new("out/checkpoint.bin");
        check_preset(path, &a, &b).unwrap();
        b.train.rays_per_batch += 1;
        let e = check_preset(path, &a, &b).unwrap_err().to_string();
        assert!(
            e.starts_with("out/checkpoint.bin:") && e.contains("preset.train.rays_per_batch"),
            "{e}"
        );
        assert_eq!(e.lines().count(), 1);
        let d = preset_difference(&a, &b).unwrap().unwrap();
        assert_eq!(
            (d.field.as_str(), d.theirs.parse::<usize>().unwrap() + 1),
            ("preset.train.rays_per_batch", b.train.rays_per_batch)
        );
        assert!(!d.to_string().contains("--resume"), "{d}");
    }

    #[test]
    fn an_identity_differs_by_method_name_first_and_elsewhere_only_when_strict() {
        let none = MethodConfig::builtin("none").unwrap();
        let stored = toml::to_string(&identity(&none, None).unwrap()).unwrap();
        let same = identity(&none, None).unwrap();
        assert_eq!(identity_difference(&stored, &same, true).unwrap(), None);
        let mut renamed = none.clone();
        renamed.name = "mine".into();
        renamed.lambda_rgb = crate::method::Weight::Fixed(1.0);
        let renamed = identity(&renamed, None).unwrap();
        for strict in [false, true] {
            // the name first, though method.lambda_rgb sorts before it
            let d = identity_difference(&stored, &renamed, strict)
                .unwrap()
                .unwrap();
            assert_eq!(d.field, "method.name", "strict: {strict}");
        }
        let mut weighted = none.clone();
        weighted.lambda_rgb = crate::method::Weight::Fixed(1.0);
        let weighted = identity(&weighted, None).unwrap();
        assert_eq!(
            identity_difference(&stored, &weighted, false).unwrap(),
            None
        );
        let d = identity_difference(&stored, &weighted, true)
            .unwrap()
            .unwrap();
        assert_eq!(d.field, "method.lambda_rgb");
        let e = check_identity(Path::new("run/checkpoint.bin"), &stored, &weighted, true)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("run/checkpoint.bin:") && e.contains("method.lambda_rgb"),
            "{e}"
        );
    }
}
