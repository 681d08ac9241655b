//! `finetune --validate-only`: an inpainting prior with and without its LoRA, and the fill
//! baselines, on held-out pairs, without training ([`validate_prior`]).

use std::path::Path;

use burn::tensor::Device;
use gb_diffusion::pipeline::SdComponents;
use serde::Serialize;

use crate::captions::CaptionMode;
use crate::error::FinetuneError;
use crate::run::validation_settings;
use crate::sample::PairSource;
use crate::train::vae_stage::reconstruction_psnr;
use crate::train::validate::{validate, ValidationReport};
use crate::train::FinetuneConfig;

/// What [`validate_prior`] measured: the command writes it as `OUT/validation.json`.
#[derive(Debug, Clone, Serialize)]
pub struct PriorValidation {
    /// The prior folder.
    pub prior: String,
    /// The LoRA validated on top of it, if any.
    pub lora: Option<String>,
    /// Held-out pairs validated.
    pub samples: usize,
    /// Samples averaged per pair.
    pub averaged_samples: usize,
    /// DDIM steps of each sample.
    pub ddim_steps: usize,
    /// Whether the known pixels were blended back at each step.
    pub blend_known: bool,
    /// The validation resolution.
    pub resolution: usize,
    /// The captions' mode.
    pub mode: CaptionMode,
    /// Wall time of the whole validation.
    pub seconds: f64,
    /// The autoencoder's reconstruction PSNR on the pairs.
    pub autoencoder_psnr: f64,
    /// The base prior (with the fill baselines).
    pub base: ValidationReport,
    /// The prior with its LoRA merged.
    pub with_lora: Option<ValidationReport>,
}

/// Validates `prior` (loaded from `base_dir` by [`SdComponents::load_inpainting`] on the plain
/// `device`) on `val` with `cfg`'s validation settings (normals included), then a copy of it
/// with `lora` merged, or the folder's own LoRA file when `lora` is `None` and it has one.
pub fn validate_prior(
    prior: &SdComponents,
    base_dir: &Path,
    lora: Option<&Path>,
    val: &dyn PairSource,
    cfg: &FinetuneConfig,
    device: &Device,
) -> Result<PriorValidation, FinetuneError> {
    let lora = lora.map(Path::to_path_buf).or_else(|| {
        let own = base_dir.join(gb_diffusion::lora::LORA_FILE_NAME);
        own.is_file().then_some(own)
    });
    let mut settings = validation_settings(cfg);
    settings.normals = true;
    let started = std::time::Instant::now();
    let autoencoder_psnr = reconstruction_psnr(&prior.vae, val, settings.resolution, device)?;
    tracing::info!(autoencoder_psnr, "autoencoder reconstruction");
    let base = validate(prior, val, &settings)?;
    tracing::info!(?base, "validation of the base");
    let with_lora = match &lora {
        Some(path) => {
            let (with, n) = prior.clone().with_lora(path).map_err(|e| {
                FinetuneError::diffusion(format!("attaching {}", path.display()), e)
            })?;
            tracing::info!(adapted = n, "LoRA {}", path.display());
            Some(validate(&with, val, &settings)?)
        }
        None => None,
    };
    Ok(PriorValidation {
        prior: base_dir.display().to_string(),
        lora: lora.as_ref().map(|p| p.display().to_string()),
        samples: settings.samples.min(val.len()),
        averaged_samples: settings.average,
        ddim_steps: settings.ddim_steps,
        blend_known: settings.blend_known,
        resolution: settings.resolution,
        mode: cfg.mode,
        seconds: started.elapsed().as_secs_f64(),
        autoencoder_psnr,
        base,
        with_lora,
    })
}
