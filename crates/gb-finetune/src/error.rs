//! The error type of gb-finetune: every variant names the file, field or tensor at fault.

use std::path::PathBuf;

/// Error of dataset loading, fine-tuning and checkpointing.
#[derive(Debug, thiserror::Error)]
pub enum FinetuneError {
    /// A file or directory could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// Something the layout requires is absent.
    #[error("{path}: missing {what}")]
    Missing {
        /// What was expected (e.g. "DIODE normal file `*_normal.npy`").
        what: String,
        /// Where it was expected.
        path: PathBuf,
    },
    /// A file exists but its content is wrong (bad JSON line, bad npy shape, ...).
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A configuration value is out of range or inconsistent.
    #[error("config field `{field}`: {message}")]
    Config {
        /// The field name as written in the TOML / on the command line.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// The diffusion stack failed (loading a prior, a LoRA, a tokenizer).
    #[error("{context}: {message}")]
    Diffusion {
        /// What was being done.
        context: String,
        /// The underlying error.
        message: String,
    },
    /// Training diverged.
    #[error("training diverged at step {step}: {message}")]
    Diverged {
        /// The optimiser step.
        step: usize,
        /// What was seen.
        message: String,
    },
}

impl FinetuneError {
    /// Wraps an I/O error with its path.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }

    /// Wraps any diffusion-stack error with its context.
    pub fn diffusion(context: impl Into<String>, err: impl std::fmt::Display) -> Self {
        Self::Diffusion {
            context: context.into(),
            message: err.to_string(),
        }
    }
}
