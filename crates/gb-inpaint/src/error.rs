//! Errors of the pipeline. Every variant names the file, folder, field or step at fault, and
//! everything a user can get wrong (method file, prior folder, LoRA file, a scene without
//! masks, missing pre-inpainted images) is detected before training starts.

use std::path::PathBuf;

use gb_diffusion::distill::DistillError;
use gb_nerf::train::NerfError;

/// Everything that can go wrong while configuring or running the guided reconstruction.
#[derive(Debug, thiserror::Error)]
pub enum InpaintError {
    /// A method configuration could not be read, parsed or validated.
    #[error("{path}: invalid method config: {reason}")]
    MethodConfig {
        /// The file (or `configs/methods/NAME.toml` for a built-in method).
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A method name that is neither built in nor a `.toml` path.
    #[error("unknown method '{name}': expected one of {known} (or a path to a .toml file)")]
    UnknownMethod {
        /// The name given.
        name: String,
        /// The built-in names, comma-separated.
        known: String,
    },
    /// The prior folder is missing or one of its components cannot be loaded.
    #[error("prior {path}: {reason}")]
    Prior {
        /// The prior folder.
        path: PathBuf,
        /// What is wrong (with the failing component and its cause).
        reason: String,
    },
    /// A LoRA file could not be read or does not fit the prior.
    #[error("LoRA file {path}: {reason}")]
    Lora {
        /// The LoRA file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The method asks for a LoRA and none was given or found next to the prior.
    #[error(
        "method '{method}' uses a LoRA (use_lora = true) but {expected} does not exist: pass \
         --lora FILE, or choose a method without the LoRA (e.g. --method bsd)"
    )]
    LoraMissing {
        /// The method name.
        method: String,
        /// Where the LoRA was looked for.
        expected: PathBuf,
    },
    /// The method needs a diffusion prior and none was given.
    #[error("method '{method}' needs a diffusion prior (--prior tiny|DIR|HUB_ID); got none")]
    PriorRequired {
        /// The method name.
        method: String,
    },
    /// The scene has nothing to remove: no training view has a non-empty mask.
    #[error(
        "scene '{scene}' has no training view with an object mask: object removal needs masks \
         (LLFF / SPIn-NeRF layout: images_F/label/NAME.png)"
    )]
    NoMasks {
        /// The scene name.
        scene: String,
    },
    /// The pre-inpainted inputs of a scene are missing or do not fit it.
    #[error("pre-inpainted inputs: {path}: {reason}")]
    PreInpainted {
        /// The folder or file at fault.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// Too many consecutive steps had a non-finite loss; training stopped.
    #[error(
        "training stopped at step {step}: {count} consecutive steps had a non-finite loss \
         (each was skipped); {checkpoint}"
    )]
    NonFiniteLoss {
        /// The step of the last non-finite loss.
        step: usize,
        /// How many in a row.
        count: usize,
        /// Where the last good checkpoint is, in words.
        checkpoint: String,
    },
    /// A field of a run's specification ([`crate::run::RunSpec`], named as its command-line
    /// flag) or a file it names is unusable.
    #[error("{field}: {reason}")]
    Spec {
        /// The field (`--out`, `--baseline`, ...) or file.
        field: String,
        /// What is wrong.
        reason: String,
    },
    /// The scene could not be loaded or generated.
    #[error("{what} {path}: {source}")]
    Scene {
        /// `loading scene` or `generating scene`.
        what: &'static str,
        /// The scene folder.
        path: PathBuf,
        /// The cause.
        source: Box<gb_nerf::scene::SceneError>,
    },
    /// The prior could not be resolved (`tiny`, folder, hub id).
    #[error(transparent)]
    Checkpoint(#[from] gb_diffusion::checkpoint::CheckpointError),
    /// A metric could not be computed.
    #[error("metric: {0}")]
    Metric(#[from] gb_eval::MetricError),
    /// The metric suite could not read its inputs.
    #[error("evaluation: {0}")]
    Evaluation(#[from] gb_eval::suite::SuiteError),
    /// The NeRF side failed (config, scene contents, checkpoint).
    #[error(transparent)]
    Nerf(#[from] NerfError),
    /// The score distillation failed.
    #[error("score distillation: {0}")]
    Distill(#[from] DistillError),
    /// 2D inpainting with the prior (`fill`) failed.
    #[error("2D inpainting: {0}")]
    Sample(#[from] gb_diffusion::inpaint::InpaintError),
    /// Per-scene personalisation of the prior failed ([`crate::personalize`]).
    #[error("personalisation: {reason}")]
    Personalize {
        /// What failed, with its cause.
        reason: String,
    },
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The IO error.
        source: std::io::Error,
    },
}

impl From<gb_report::ReportError> for InpaintError {
    fn from(e: gb_report::ReportError) -> Self {
        match e {
            gb_report::ReportError::Io { path, source } => InpaintError::Io { path, source },
        }
    }
}

impl InpaintError {
    /// An [`InpaintError::Io`] for `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        InpaintError::Io {
            path: path.into(),
            source,
        }
    }
}
