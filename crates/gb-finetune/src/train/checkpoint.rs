//! Fine-tuning checkpoints: one file written atomically (temporary file + rename).
//!
//! A checkpoint holds everything a run carries from one step to the next, so that a run
//! killed after it and resumed writes the same adapters bit for bit: the trainable module, the
//! AdamW state, the step, the loss log, the count of consecutive non-finite steps, and the
//! recipe as TOML text (whose floats round-trip exactly, unlike serde_json's default
//! parser). The random streams need no state: the batch of step `s` is drawn from a stream
//! that is a pure function of `(seed, s, micro-batch)` ([`super::batch::stream`]), and the
//! validation's holes and noise from fixed seeds.
//!
//! Layout (version 2): the magic `GBFTCK2\n`, then three sections, each a little-endian `u64` length
//! followed by its bytes: JSON metadata ([`CheckpointMeta`]), the trainable module's record
//! (burnpack bytes of `Module::into_record`, LoRA factors included, parameter ids kept so
//! that the optimiser state maps back), and the AdamW state (burnpack bytes). A version-1
//! file (`GBFTCK1`) is refused with a one-line error naming it.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::FinetuneConfig;
use crate::FinetuneError;

const MAGIC: &[u8] = b"GBFTCK2\n";
/// Magics of older versions, refused by name.
const OLD_MAGICS: &[&[u8]] = &[b"GBFTCK1\n"];

/// Metadata of a checkpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CheckpointMeta {
    /// Optimiser steps completed.
    pub step: usize,
    /// The recipe trained with, as TOML (exact floats; [`CheckpointMeta::config`]).
    pub config_toml: String,
    /// The caller's own state (`null` when none; [`crate::run`] keeps its validation
    /// reports here, floats through [`exact_floats`]).
    #[serde(default)]
    pub extra: serde_json::Value,
    /// Consecutive non-finite steps before this checkpoint (the run stops at
    /// [`super::trainer::MAX_NAN_STEPS`]).
    pub nan_streak: usize,
    /// Loss of every completed step (for the training log), as `f64::to_bits`: a JSON
    /// decimal does not round-trip exactly through serde_json's default float parser.
    pub loss_bits: Vec<u64>,
    /// The ranks of the data-parallel run that wrote it (1: one process; a checkpoint of
    /// before the field is one process's). A resume needs as many ([`super::grad_sync`]).
    #[serde(default = "one_rank")]
    pub ranks: usize,
}

/// One rank: what a file written before the rank count was recorded stands for.
pub(crate) fn one_rank() -> usize {
    1
}

impl CheckpointMeta {
    /// The recipe, parsed from [`Self::config_toml`]; `path` names the checkpoint in errors.
    pub fn config(&self, path: &Path) -> Result<FinetuneConfig, FinetuneError> {
        toml::from_str(&self.config_toml).map_err(|e| invalid(path, format!("config: {e}")))
    }
}

/// `v` with every float written as `{"f64_bits": u64}`: a JSON value that comes back exactly
/// through serde_json's default parser, which reads some decimals one ulp off.
pub fn exact_floats(v: serde_json::Value) -> serde_json::Value {
    use serde_json::Value;
    match v {
        Value::Number(n) if n.is_f64() => {
            serde_json::json!({ "f64_bits": n.as_f64().unwrap_or(f64::NAN).to_bits() })
        }
        Value::Array(a) => Value::Array(a.into_iter().map(exact_floats).collect()),
        Value::Object(m) => {
            Value::Object(m.into_iter().map(|(k, v)| (k, exact_floats(v))).collect())
        }
        other => other,
    }
}

/// The inverse of [`exact_floats`].
pub fn from_exact_floats(v: serde_json::Value) -> serde_json::Value {
    use serde_json::Value;
    match v {
        Value::Object(m) if m.len() == 1 && m.contains_key("f64_bits") => m["f64_bits"]
            .as_u64()
            .and_then(|b| serde_json::Number::from_f64(f64::from_bits(b)))
            .map_or(Value::Null, Value::Number),
        Value::Array(a) => Value::Array(a.into_iter().map(from_exact_floats).collect()),
        Value::Object(m) => Value::Object(
            m.into_iter()
                .map(|(k, v)| (k, from_exact_floats(v)))
                .collect(),
        ),
        other => other,
    }
}

/// The recipe as TOML text (exact floats).
pub fn config_to_toml(config: &FinetuneConfig, path: &Path) -> Result<String, FinetuneError> {
    toml::to_string(config).map_err(|e| invalid(path, format!("config: {e}")))
}

/// The parts of a checkpoint.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckpointParts {
    /// Metadata.
    pub meta: CheckpointMeta,
    /// Module record bytes.
    pub model: Vec<u8>,
    /// Optimiser record bytes.
    pub optimizer: Vec<u8>,
}

fn invalid(path: &Path, message: impl Into<String>) -> FinetuneError {
    FinetuneError::Invalid {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Writes a checkpoint atomically.
pub fn save(path: &Path, parts: &CheckpointParts) -> Result<(), FinetuneError> {
    let meta = serde_json::to_vec(&parts.meta).map_err(|e| invalid(path, e.to_string()))?;
    let out = gb_core::sections::encode(MAGIC, &[&meta, &parts.model, &parts.optimizer]);
    gb_core::write_atomic(path, &out).map_err(|e| FinetuneError::io(path, e))
}

/// Reads a checkpoint written by [`save`].
pub fn load(path: &Path) -> Result<CheckpointParts, FinetuneError> {
    let bytes = std::fs::read(path).map_err(|e| FinetuneError::io(path, e))?;
    let mut sections = gb_core::sections::decode(
        &bytes,
        MAGIC,
        OLD_MAGICS,
        "gb-finetune",
        &["metadata", "model", "optimizer"],
    )
    .map_err(|m| invalid(path, m))?;
    let optimizer = sections.pop().unwrap_or_default();
    let model = sections.pop().unwrap_or_default();
    let meta: CheckpointMeta = serde_json::from_slice(&sections.pop().unwrap_or_default())
        .map_err(|e| invalid(path, format!("metadata: {e}")))?;
    Ok(CheckpointParts {
        meta,
        model,
        optimizer,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn config_round_trips_exactly_and_old_files_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("checkpoint.gbft");
        let config = FinetuneConfig {
            lr: 1.0 / 3.0 * 1e-4,
            alpha: 0.1 + 0.2,
            ..FinetuneConfig::default()
        };
        let parts = CheckpointParts {
            meta: CheckpointMeta {
                step: 3,
                config_toml: config_to_toml(&config, &path).unwrap(),
                nan_streak: 1,
                loss_bits: vec![0.5f64.to_bits()],
                extra: serde_json::Value::Null,
                ranks: 3,
            },
            model: vec![1, 2, 3],
            optimizer: vec![4],
        };
        save(&path, &parts).unwrap();
        let back = load(&path).unwrap();
        assert_eq!(back, parts);
        assert_eq!(back.meta.config(&path).unwrap(), config);
        let value = serde_json::json!({"a": [13.558149127696177, 1, null], "b": {"c": 0.1}});
        let text = serde_json::to_string(&exact_floats(value.clone())).unwrap();
        let back = from_exact_floats(serde_json::from_str(&text).unwrap());
        assert_eq!(back, value);
        std::fs::write(&path, b"GBFTCK1\n\x00").unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(
            e.contains("checkpoint.gbft") && e.contains("GBFTCK1"),
            "{e}"
        );
        assert_eq!(e.lines().count(), 1, "{e}");
    }
}
