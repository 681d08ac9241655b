//! Checkpoints: one file written atomically (temporary file + rename, via
//! [`gb_core::write_atomic`]), so a crash leaves either the previous checkpoint or the new
//! one.
//!
//! Layout: the magic `GBNERFCK1\n`, then four sections, each a little-endian `u64` length
//! followed by its bytes: JSON metadata ([`CheckpointMeta`]), the field parameters (burnpack
//! bytes of `Module::into_record`), the Adam state (burnpack bytes of the optimiser record),
//! and the occupancy grid's running densities (`f32` little-endian).

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{NerfConfig, NerfError};

const MAGIC: &[u8] = b"GBNERFCK1\n";

/// Metadata of a checkpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CheckpointMeta {
    /// Steps completed.
    pub step: usize,
    /// The configuration trained with.
    pub config: NerfConfig,
    /// Density threshold of the occupancy grid (when one is used).
    pub occupancy_threshold: Option<f32>,
}

/// The parts of a checkpoint, as bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckpointParts {
    /// Metadata.
    pub meta: CheckpointMeta,
    /// Field parameters (burnpack).
    pub model: Vec<u8>,
    /// Optimiser state (burnpack).
    pub optimizer: Vec<u8>,
    /// Occupancy densities.
    pub occupancy: Vec<f32>,
}

fn err(path: &Path, reason: impl Into<String>) -> NerfError {
    NerfError::Checkpoint {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

/// Writes a checkpoint atomically.
pub fn save(path: &Path, parts: &CheckpointParts) -> Result<(), NerfError> {
    let meta = serde_json::to_vec(&parts.meta).map_err(|e| err(path, e.to_string()))?;
    let occ: Vec<u8> = parts
        .occupancy
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let mut out = MAGIC.to_vec();
    for section in [&meta, &parts.model, &parts.optimizer, &occ] {
        out.extend_from_slice(&(section.len() as u64).to_le_bytes());
        out.extend_from_slice(section);
    }
    gb_core::write_atomic(path, &out).map_err(|e| err(path, e.to_string()))
}

/// Reads a checkpoint written by [`save`].
pub fn load(path: &Path) -> Result<CheckpointParts, NerfError> {
    let bytes = std::fs::read(path).map_err(|e| err(path, e.to_string()))?;
    if !bytes.starts_with(MAGIC) {
        return Err(err(path, "not a gb-nerf checkpoint (bad magic)"));
    }
    let mut pos = MAGIC.len();
    let mut sections = Vec::new();
    for name in ["metadata", "model", "optimizer", "occupancy"] {
        let len_bytes = bytes
            .get(pos..pos + 8)
            .ok_or_else(|| err(path, format!("truncated before the {name} section")))?;
        let len = u64::from_le_bytes(len_bytes.try_into().unwrap_or([0; 8])) as usize;
        pos += 8;
        let body = bytes
            .get(pos..pos.saturating_add(len))
            .ok_or_else(|| err(path, format!("truncated {name} section")))?;
        sections.push(body.to_vec());
        pos += len;
    }
    let meta: CheckpointMeta =
        serde_json::from_slice(&sections[0]).map_err(|e| err(path, format!("metadata: {e}")))?;
    if sections[3].len() % 4 != 0 {
        return Err(err(path, "occupancy section is not a whole number of f32"));
    }
    let occupancy = sections[3]
        .chunks(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let optimizer = sections.swap_remove(2);
    let model = sections.swap_remove(1);
    Ok(CheckpointParts {
        meta,
        model,
        optimizer,
        occupancy,
    })
}
