//! Score distillation (SDS, CSD, Balanced Score Distillation) as gradients into rendered
//! images, through an inpainting diffusion prior.
//!
//! - [`guidance`]: the one [`Guidance`] interface; one file per method ([`sds`], [`csd`],
//!   [`bsd`]); each step is ONE batched U-Net call (SDS and BSD batch 2, CSD batch 3).
//! - [`eps`]: the model interfaces ([`InpaintEpsPredictor`], [`LatentEncoder`]).
//! - [`step`]: [`ScoreDistiller`], one step at latent resolution: `g = w(t) * direction`,
//!   masked at latent resolution, non-finite values zeroed, optionally clamped, injected as
//!   `(latents * g.detach()).sum()` so that autodiff runs through the encoder only.
//! - [`oracle`]: the exact score of a point distribution at the true latents, for oracle
//!   experiments that separate the prior from the distillation.
//! - [`timestep`]: `t` uniform in `[0.02, 0.98]` or the reference's annealed schedule, and
//!   `w(t)`; [`alphas`]: the noise schedule.
//! - [`prior_input`], [`conditioning`], [`view_step`]: crop/resize/paste of the render,
//!   cached view and prompt conditioning, the step on a rendered view.
//! - [`image`]: distillation straight into an image's masked pixels, with Burn's Adam (the
//!   2D playground of `distill-image`).
//! - [`sd_adapter`]: the crate's U-Net and VAE encoder behind those interfaces, and
//!   [`SdPrior`], the one prior type, which holds them and CLIP's prompt encoder.

pub mod alphas;
pub mod bsd;
pub mod conditioning;
pub mod csd;
pub mod diagnostics;
pub mod eps;
pub mod error;
pub mod gradient;
pub mod guidance;
pub mod guidance_method;
pub mod image;
pub mod noise;
pub mod oracle;
pub mod prior_input;
pub mod sd_adapter;
mod sd_prior;
pub mod sds;
pub mod settings_table;
pub mod step;
pub mod timestep;
pub mod view_step;

pub use alphas::AlphasCumprod;
pub use bsd::Bsd;
pub use conditioning::{PromptCache, PromptEncoder, ViewCache, ViewConditioning};
pub use csd::Csd;
pub use diagnostics::StepDiagnostics;
pub use eps::{EpsBatch, InpaintEpsPredictor, LatentEncoder};
pub use error::DistillError;
pub use guidance::{Branch, Guidance};
pub use guidance_method::GuidanceMethod;
pub use oracle::OracleEps;
pub use prior_input::{MaskBox, PriorInputMode};
pub use sd_prior::{PriorInfo, PriorOptions, SdPrior};
pub use sds::Sds;
pub use step::{DistillOutput, DistillSettings, LatentTarget, PromptEmbeddings, ScoreDistiller};
pub use timestep::{TimestepConfig, TimestepSchedule, Weighting};
pub use view_step::{distill_view, prior_image, ViewStepModels};
