//! Errors of the score-distillation module.

use super::guidance::Branch;

/// Why a prior path that is not a folder is refused.
pub const PRIOR_LAYOUT: &str = "not a folder (expected a diffusers layout: model_index.json, \
    unet/, vae/, text_encoder/, tokenizer/, scheduler/)";

/// Boxed error from an eps-predictor, latent-encoder or prompt-encoder implementation.
pub type BoxedSourceError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Everything that can go wrong while computing a score-distillation gradient.
#[derive(Debug, thiserror::Error)]
pub enum DistillError {
    /// A timestep fraction outside the open interval (0, 1).
    #[error(
        "timestep {field} = {value} is outside (0, 1): t = 0 has no noise and t = 1 is pure noise \
         (use a value in [0.02, 0.98] as in the paper)"
    )]
    TimestepOutOfRange {
        /// Which setting or argument held the value (`t_min`, `t_max`, `t`).
        field: &'static str,
        /// The rejected value.
        value: f64,
    },
    /// `t_min` larger than `t_max`.
    #[error("timestep range is empty: t_min = {t_min} > t_max = {t_max}")]
    TimestepRangeEmpty {
        /// Lower bound.
        t_min: f64,
        /// Upper bound.
        t_max: f64,
    },
    /// The noise schedule (`alphas_cumprod`) is empty or not in (0, 1].
    #[error("alphas_cumprod: {0}")]
    BadNoiseSchedule(String),
    /// A weight or guidance scale that is not a finite number.
    #[error("guidance weight {name} = {value} is not finite")]
    NonFiniteWeight {
        /// Name of the weight (`w1`, `w2`, `w3`, `guidance_scale`, `grad_clamp`).
        name: &'static str,
        /// The rejected value.
        value: f32,
    },
    /// A gradient clamp that is not strictly positive.
    #[error("grad_clamp = {0} must be > 0")]
    BadClamp(f32),
    /// A guidance needs a text embedding that was not supplied.
    #[error("the {method} guidance needs the {branch:?} text embedding, which was not supplied")]
    MissingEmbedding {
        /// Guidance method name.
        method: &'static str,
        /// The missing conditioning branch.
        branch: Branch,
    },
    /// Two tensors whose shapes do not fit together.
    #[error("shape mismatch: {tensor} has shape {actual:?}, expected {expected}")]
    Shape {
        /// Which tensor.
        tensor: &'static str,
        /// Its actual shape.
        actual: Vec<usize>,
        /// What was expected, in words.
        expected: String,
    },
    /// A mask with no pixel set, so there is no bounding box to crop.
    #[error("mask {0} is empty: no pixel >= 0.5, nothing to distill")]
    EmptyMask(String),
    /// The prior input mode needs a ground-truth image that was not supplied.
    #[error("prior input mode 'paste_on_ground_truth' needs the ground-truth image of view {0}")]
    MissingGroundTruth(usize),
    /// No cached conditioning for a view.
    #[error("no cached conditioning for view {0}: call prepare_view first")]
    UnknownView(usize),
    /// An invalid configuration value.
    #[error("distill config field {field}: {message}")]
    Config {
        /// The offending field.
        field: &'static str,
        /// What is wrong with it.
        message: String,
    },
    /// A prior component could not be loaded.
    #[error("loading the prior's {component} from {path} failed")]
    Load {
        /// Which component (`unet`, `vae`, `text_encoder`, `tokenizer`, `scheduler`).
        component: &'static str,
        /// The prior folder.
        path: std::path::PathBuf,
        /// The underlying error.
        #[source]
        source: BoxedSourceError,
    },
    /// The prior path is not a folder.
    #[error("{}: {PRIOR_LAYOUT}", path.display())]
    PriorFolder {
        /// The path given.
        path: std::path::PathBuf,
    },
    /// A LoRA file could not be read or does not fit the prior.
    #[error("{error}")]
    Lora {
        /// The LoRA file.
        path: std::path::PathBuf,
        /// What is wrong (its message names the file where the file could not be read).
        error: Box<crate::lora::LoraError>,
    },
    /// The eps predictor (U-Net) failed.
    #[error("eps predictor failed")]
    Predictor(#[source] BoxedSourceError),
    /// The latent encoder (VAE encoder) failed.
    #[error("latent encoder failed")]
    Encoder(#[source] BoxedSourceError),
    /// The prompt encoder (text encoder) failed on a prompt.
    #[error("prompt encoder failed on prompt {prompt:?}")]
    PromptEncoder {
        /// The prompt that failed.
        prompt: String,
        /// The underlying error.
        #[source]
        source: BoxedSourceError,
    },
    /// Reading a tensor back to the host failed.
    #[error("reading tensor {0} back to the host failed: {1}")]
    Readback(&'static str, String),
}
