//! Fine-tuning checkpoints: one file written atomically (temporary file + rename).
//!
//! Layout: the magic `GBFTCK1\n`, then three sections, each a little-endian `u64` length
//! followed by its bytes: JSON metadata ([`CheckpointMeta`]), the trainable module's record
//! (burnpack bytes of `Module::into_record`, LoRA factors included, parameter ids kept so
//! that the optimiser state maps back), and the AdamW state (burnpack bytes).

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::FinetuneConfig;
use crate::FinetuneError;

const MAGIC: &[u8] = b"GBFTCK1\n";

/// Metadata of a checkpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CheckpointMeta {
    /// Optimiser steps completed.
    pub step: usize,
    /// The recipe trained with.
    pub config: FinetuneConfig,
    /// Loss of every completed step (for the training log), as `f64::to_bits`: a JSON
    /// decimal does not round-trip exactly through serde_json's default float parser.
    pub loss_bits: Vec<u64>,
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
    let mut out = MAGIC.to_vec();
    for section in [&meta, &parts.model, &parts.optimizer] {
        out.extend_from_slice(&(section.len() as u64).to_le_bytes());
        out.extend_from_slice(section);
    }
    gb_core::write_atomic(path, &out).map_err(|e| FinetuneError::io(path, e))
}

/// Reads a checkpoint written by [`save`].
pub fn load(path: &Path) -> Result<CheckpointParts, FinetuneError> {
    let bytes = std::fs::read(path).map_err(|e| FinetuneError::io(path, e))?;
    if !bytes.starts_with(MAGIC) {
        return Err(invalid(path, "not a gb-finetune checkpoint (bad magic)"));
    }
    let mut pos = MAGIC.len();
    let mut sections: Vec<Vec<u8>> = Vec::new();
    for name in ["metadata", "model", "optimizer"] {
        let len_bytes: [u8; 8] = bytes
            .get(pos..pos + 8)
            .and_then(|s| s.try_into().ok())
            .ok_or_else(|| invalid(path, format!("truncated before the {name} section")))?;
        let len = u64::from_le_bytes(len_bytes) as usize;
        pos += 8;
        let body = bytes
            .get(pos..pos.saturating_add(len))
            .ok_or_else(|| invalid(path, format!("truncated {name} section")))?;
        sections.push(body.to_vec());
        pos += len;
    }
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
