//! Checkpoints: one file written atomically (temporary file + rename, via
//! [`gb_core::write_atomic`]), so a crash leaves either the previous checkpoint or the new
//! one.
//!
//! A checkpoint holds everything a run carries from one step to the next, so that a run
//! resumed from it continues bit for bit as the uninterrupted run would: the field, the Adam
//! state, the occupancy grid (running densities, occupied cells, threshold), the exact
//! position of the ray/jitter/occupancy random stream ([`RngState`]), the configuration
//! (as TOML text, whose floats round-trip exactly, unlike serde_json's default parser), a
//! fingerprint of the training data, and an opaque JSON value for the caller's own state
//! (the guided trainer's counters and visibility maps).
//!
//! Layout (version 2): the magic `GBNERFCK2\n`, then five sections, each a little-endian
//! `u64` length followed by its bytes: JSON metadata ([`CheckpointMeta`]), the field
//! parameters (burnpack bytes of `Module::into_record`), the Adam state (burnpack bytes of
//! the optimiser record), the occupancy grid's running densities (`f32` little-endian) and its
//! occupied cells (one byte per cell). A version-1 file (`GBNERFCK1`) is refused with a
//! one-line error: it lacks the random stream, so it cannot continue exactly.

use std::path::Path;

use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::data::TrainData;
use super::{NerfConfig, NerfError};

const MAGIC: &[u8] = b"GBNERFCK2\n";
/// Magics of older versions, refused by name.
const OLD_MAGICS: &[&[u8]] = &[b"GBNERFCK1\n"];

/// The exact state of a `ChaCha8Rng`: key, stream and position in 32-bit words.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RngState {
    /// The 256-bit key.
    pub seed: [u8; 32],
    /// The stream (nonce).
    pub stream: u64,
    /// Words consumed so far, a decimal `u128`.
    pub word_pos: String,
}

impl RngState {
    /// The state of `rng`.
    pub fn of(rng: &ChaCha8Rng) -> Self {
        Self {
            seed: rng.get_seed(),
            stream: rng.get_stream(),
            word_pos: rng.get_word_pos().to_string(),
        }
    }

    /// A generator at exactly this state; `None` when `word_pos` is not a number.
    pub fn restore(&self) -> Option<ChaCha8Rng> {
        use rand::SeedableRng;
        let pos: u128 = self.word_pos.parse().ok()?;
        let mut rng = ChaCha8Rng::from_seed(self.seed);
        rng.set_stream(self.stream);
        rng.set_word_pos(pos);
        Some(rng)
    }
}

/// Metadata of a checkpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CheckpointMeta {
    /// Steps completed.
    pub step: usize,
    /// The configuration trained with, as TOML (exact floats).
    pub config_toml: String,
    /// Name of the scene trained on.
    pub scene: String,
    /// [`data_fingerprint`] of the training data, hexadecimal.
    pub data_fingerprint: String,
    /// The trainer's random stream after `step` steps.
    pub rng: RngState,
    /// `f32::to_bits` of the occupancy grid's density threshold (when one is used).
    pub occupancy_threshold_bits: Option<u32>,
    /// The caller's own state (`null` for plain reconstruction); floats in it should be
    /// stored as bits for an exact round trip.
    #[serde(default)]
    pub extra: serde_json::Value,
}

impl CheckpointMeta {
    /// The configuration, parsed from [`Self::config_toml`]; `path` names the checkpoint in
    /// errors.
    pub fn config(&self, path: &Path) -> Result<NerfConfig, NerfError> {
        toml::from_str(&self.config_toml).map_err(|e| err(path, format!("config: {e}")))
    }
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
    /// Occupied cells of the occupancy grid.
    pub occupied: Vec<bool>,
}

fn err(path: &Path, reason: impl Into<String>) -> NerfError {
    NerfError::Checkpoint {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

/// The configuration as TOML text (exact floats).
pub fn config_to_toml(config: &NerfConfig, path: &Path) -> Result<String, NerfError> {
    toml::to_string(config).map_err(|e| err(path, format!("config: {e}")))
}

/// A 64-bit fingerprint (FNV-1a over 32-bit words) of the training data: the views' cameras,
/// images, masks and depths, and the pixel pool. Two runs on the same scene at the same
/// downscaling have the same fingerprint.
pub fn data_fingerprint(data: &TrainData) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut word = |w: u32| {
        h ^= w as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    };
    word(data.views.len() as u32);
    for v in &data.views {
        let c = &v.camera;
        word(c.width as u32);
        word(c.height as u32);
        for f in [c.fx, c.fy, c.cx, c.cy] {
            word(f.to_bits());
        }
        for row in &c.c2w {
            for f in row {
                word(f.to_bits());
            }
        }
        v.image.data.iter().for_each(|f| word(f.to_bits()));
        match &v.mask {
            Some(m) => m.data.iter().for_each(|b| word(*b as u32 + 2)),
            None => word(1),
        }
        match &v.depth {
            Some(d) => d.iter().for_each(|f| word(f.to_bits())),
            None => word(1),
        }
    }
    word(data.pixels.len() as u32);
    word(data.sparse.len() as u32);
    for p in &data.sparse {
        word(p.view);
        [p.x, p.y, p.depth].iter().for_each(|f| word(f.to_bits()));
    }
    h
}

/// The first place where two TOML values differ, as `(path, left, right)` with `prefix`
/// before the path (`None` when equal). Tables are compared key by key (sorted), arrays
/// element by element.
pub fn first_difference(
    prefix: &str,
    a: &toml::Value,
    b: &toml::Value,
) -> Option<(String, String, String)> {
    let show =
        |v: Option<&toml::Value>| v.map_or_else(|| "(absent)".to_string(), |v| v.to_string());
    match (a, b) {
        (toml::Value::Table(x), toml::Value::Table(y)) => {
            let mut keys: Vec<&String> = x.keys().chain(y.keys()).collect();
            keys.sort();
            keys.dedup();
            keys.into_iter().find_map(|k| {
                let path = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                match (x.get(k), y.get(k)) {
                    (Some(p), Some(q)) => first_difference(&path, p, q),
                    (p, q) => Some((path, show(p), show(q))),
                }
            })
        }
        (toml::Value::Array(x), toml::Value::Array(y)) if x.len() == y.len() => x
            .iter()
            .zip(y)
            .enumerate()
            .find_map(|(i, (p, q))| first_difference(&format!("{prefix}[{i}]"), p, q)),
        _ if a == b => None,
        _ => Some((prefix.to_string(), a.to_string(), b.to_string())),
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
    let occupied: Vec<u8> = parts.occupied.iter().map(|o| *o as u8).collect();
    let out = gb_core::sections::encode(
        MAGIC,
        &[&meta, &parts.model, &parts.optimizer, &occ, &occupied],
    );
    gb_core::write_atomic(path, &out).map_err(|e| err(path, e.to_string()))
}

/// Reads a checkpoint written by [`save`].
pub fn load(path: &Path) -> Result<CheckpointParts, NerfError> {
    let bytes = std::fs::read(path).map_err(|e| err(path, e.to_string()))?;
    let mut sections = gb_core::sections::decode(
        &bytes,
        MAGIC,
        OLD_MAGICS,
        "gb-nerf",
        &["metadata", "model", "optimizer", "occupancy", "occupied"],
    )
    .map_err(|m| err(path, m))?;
    let meta: CheckpointMeta =
        serde_json::from_slice(&sections[0]).map_err(|e| err(path, format!("metadata: {e}")))?;
    if sections[3].len() % 4 != 0 {
        return Err(err(path, "occupancy section is not a whole number of f32"));
    }
    let occupancy: Vec<f32> = sections[3]
        .chunks(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let occupied: Vec<bool> = sections[4].iter().map(|b| *b != 0).collect();
    if occupied.len() != occupancy.len() {
        return Err(err(
            path,
            format!(
                "occupancy grid has {} densities but {} occupied flags",
                occupancy.len(),
                occupied.len()
            ),
        ));
    }
    let optimizer = sections.swap_remove(2);
    let model = sections.swap_remove(1);
    Ok(CheckpointParts {
        meta,
        model,
        optimizer,
        occupancy,
        occupied,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn rng_state_restores_the_exact_stream() {
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        // an odd number of words: the restored generator must continue mid-block
        for _ in 0..37 {
            rng.random::<u32>();
        }
        rng.random::<f64>();
        let state = RngState::of(&rng);
        let json = serde_json::to_string(&state).unwrap();
        let back: RngState = serde_json::from_str(&json).unwrap();
        let mut restored = back.restore().unwrap();
        let a: Vec<u64> = (0..100).map(|_| rng.random()).collect();
        let b: Vec<u64> = (0..100).map(|_| restored.random()).collect();
        assert_eq!(a, b);
    }

    #[test]
    fn first_difference_names_the_nested_field() {
        let a: toml::Value = toml::from_str("name = 'x'\n[train]\nsteps = 3\nlr = 0.1").unwrap();
        let b: toml::Value = toml::from_str("name = 'x'\n[train]\nsteps = 3\nlr = 0.2").unwrap();
        let (path, l, r) = first_difference("preset", &a, &b).unwrap();
        assert_eq!(
            (path.as_str(), l.as_str(), r.as_str()),
            ("preset.train.lr", "0.1", "0.2")
        );
        assert!(first_difference("preset", &a, &a).is_none());
        let c: toml::Value = toml::from_str("name = 'x'").unwrap();
        let (path, _, r) = first_difference("", &a, &c).unwrap();
        assert_eq!((path.as_str(), r.as_str()), ("train", "(absent)"));
    }

    #[test]
    fn an_old_checkpoint_is_refused_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("old.bin");
        std::fs::write(&path, b"GBNERFCK1\n\x00").unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(e.contains("old.bin") && e.contains("GBNERFCK1"), "{e}");
        assert_eq!(e.lines().count(), 1, "{e}");
    }
}
