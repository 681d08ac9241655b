//! Errors of checkpoint loading.

use std::path::PathBuf;

use crate::config::ConfigError;

/// Error loading a checkpoint folder or applying its tensors to a module.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// A file or folder the checkpoint needs is absent.
    #[error("missing checkpoint file {path}: {what}")]
    MissingFile {
        /// The path that was looked for.
        path: PathBuf,
        /// What it should have contained.
        what: String,
    },
    /// A single file where a diffusers pipeline folder is expected.
    #[error(
        "{path}: a single-file checkpoint{pickle}, but a prior is a diffusers pipeline folder \
         (model_index.json, unet/, vae/, text_encoder/, tokenizer/, scheduler/) with \
         .safetensors weights; convert it with diffusers: {advice}"
    )]
    SingleFile {
        /// The file given.
        path: PathBuf,
        /// `" (a PyTorch pickle, which is never loaded: unpickling can run code)"` for a
        /// pickle, else empty.
        pickle: String,
        /// The conversion command.
        advice: String,
    },
    /// A component folder holds PyTorch pickle weights and no `.safetensors`.
    #[error(
        "{path}: PyTorch pickle weights are not loaded (unpickling can run code) and the \
         `{component}` folder has no .safetensors file; convert the pipeline to safetensors: \
         {advice}"
    )]
    PickleWeights {
        /// The pickle file found.
        path: PathBuf,
        /// The component (`unet`, `vae`, `text_encoder`).
        component: String,
        /// The conversion command.
        advice: String,
    },
    /// A config file could not be read or parsed.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A weight file could not be opened or parsed as safetensors.
    #[error("cannot read weights {path}: {message}")]
    Weights {
        /// The weight file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// A tensor the module needs is in none of the weight files.
    #[error("missing tensor `{tensor}` (module path `{module_path}`, expected shape {expected:?}) in {files}")]
    MissingTensor {
        /// The checkpoint key that was looked for.
        tensor: String,
        /// The module parameter path.
        module_path: String,
        /// The shape the module expects (Burn layout).
        expected: Vec<usize>,
        /// The files searched.
        files: String,
    },
    /// A tensor has a different shape than the module expects.
    #[error("tensor `{tensor}` in {file}: expected shape {expected:?}, found {found:?} (Burn layout, after transposing linear weights)")]
    ShapeMismatch {
        /// The module parameter path.
        tensor: String,
        /// The file it came from.
        file: PathBuf,
        /// The expected shape.
        expected: Vec<usize>,
        /// The shape in the file.
        found: Vec<usize>,
    },
    /// Any other per-tensor failure (dtype, decoding).
    #[error("tensor `{tensor}` in {file}: {message}")]
    Tensor {
        /// The module parameter path.
        tensor: String,
        /// The file it came from.
        file: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// A keymap rule is not a valid regular expression (a bug in [`super::keymap`]).
    #[error("invalid keymap rule `{pattern}` in section {section}: {message}")]
    Keymap {
        /// The section name.
        section: String,
        /// The pattern.
        pattern: String,
        /// The regex error.
        message: String,
    },
    /// Resolving a hub id failed.
    #[error("hub id `{id}`: {message}")]
    Hub {
        /// The repository id.
        id: String,
        /// What went wrong.
        message: String,
    },
    /// A prior specification (`tiny`, a folder, a hub id) that names no usable prior.
    #[error("prior `{spec}`: {message}")]
    PriorSpec {
        /// The specification given.
        spec: String,
        /// What is wrong.
        message: String,
    },
    /// The prior named by `spec` was found but is unusable.
    #[error("prior `{spec}`: {source}")]
    Prior {
        /// The specification given.
        spec: String,
        /// The cause.
        source: Box<CheckpointError>,
    },
}
