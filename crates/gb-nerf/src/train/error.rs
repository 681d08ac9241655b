//! Errors of the reconstruction: configuration, scene contents and checkpoints.

use std::path::PathBuf;

/// Everything that can go wrong while configuring, training or checkpointing a NeRF.
#[derive(Debug, thiserror::Error)]
pub enum NerfError {
    /// A configuration file could not be read or parsed.
    #[error("{path}: invalid NeRF config: {reason}")]
    Config {
        /// The file (or preset name).
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// An unknown preset name.
    #[error("unknown preset '{0}': expected one of fast, balanced, paper (or a .toml path)")]
    UnknownPreset(String),
    /// The scene cannot be trained on.
    #[error("scene '{scene}': {reason}")]
    Scene {
        /// Scene name.
        scene: String,
        /// What is wrong.
        reason: String,
    },
    /// A checkpoint could not be written or read.
    #[error("{path}: checkpoint: {reason}")]
    Checkpoint {
        /// The checkpoint file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A tensor read back to the host did not hold the expected values.
    #[error(transparent)]
    Values(#[from] gb_core::TensorValuesError),
    /// A file could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The IO error.
        source: std::io::Error,
    },
}
