//! Errors of LoRA reading, applying and writing.

use std::path::PathBuf;

use crate::checkpoint::CheckpointError;

/// Error handling a LoRA file.
#[derive(Debug, thiserror::Error)]
pub enum LoraError {
    /// The file could not be read or written.
    #[error("LoRA file {path}: {message}")]
    File {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// A key has a form this reader does not know.
    #[error("LoRA file {path}: unrecognised key `{key}`")]
    UnknownKey {
        /// The file.
        path: PathBuf,
        /// The key.
        key: String,
    },
    /// A down/up pair is incomplete or inconsistent.
    #[error("LoRA file {path}: module `{module}`: {message}")]
    BadPair {
        /// The file.
        path: PathBuf,
        /// The LoRA target module as named in the file.
        module: String,
        /// What is wrong.
        message: String,
    },
    /// A LoRA target is not a weight of the module it is applied to.
    #[error("LoRA target `{target}` (key `{key}`) is not a weight of the {component}")]
    UnknownTarget {
        /// The resolved parameter path.
        target: String,
        /// The key in the file.
        key: String,
        /// The component name.
        component: String,
    },
    /// The factors do not fit the weight they target.
    #[error(
        "LoRA for `{target}` (key `{key}`): weight shape {weight:?} does not fit down {down:?} \
         / up {up:?}"
    )]
    ShapeMismatch {
        /// The parameter path.
        target: String,
        /// The first key of the entry in the file.
        key: String,
        /// The weight shape (Burn layout).
        weight: Vec<usize>,
        /// The down (A) factor shape.
        down: Vec<usize>,
        /// The up (B) factor shape.
        up: Vec<usize>,
    },
    /// The target already carries a reparameterisation.
    #[error("`{target}` already has a LoRA adapter; merge it first (lora::merge_lora)")]
    AlreadyAdapted {
        /// The parameter path.
        target: String,
    },
    /// A keymap error.
    #[error(transparent)]
    Keymap(#[from] CheckpointError),
}
