//! The diffusion prior of a run ([`SdPrior`], gb-diffusion's one prior type): a
//! diffusers-layout Stable Diffusion inpainting folder (U-Net, VAE, CLIP text encoder,
//! tokenizer, scheduler), optionally with a LoRA file attached to the U-Net and the text
//! encoder and merged into their weights ([`load_prior`]), or
//! networks of a real model's shapes with random weights for benchmarks ([`random_prior`]).
//!
//! The U-Net and the text encoder live on the plain device (they run without a graph); the
//! VAE lives on its autodiff version with frozen parameters, so that the guidance gradient
//! reaches the rendered image through the encoder only.
//!
//! All three compute in the run's [`Precision`] (`--precision`; f16 by default on a GPU card,
//! f32 elsewhere; see [`gb_diffusion::precision`]): the weights are cast once, after any LoRA
//! is merged in f32. What enters and leaves the networks, the score combination and the
//! gradient handed to the NeRF stay f32.
//!
//! Which LoRA: `--lora FILE` when given (whatever the method says, with a note in the log),
//! else `PRIOR/pytorch_lora_weights.safetensors` when the method has `use_lora = true` (an
//! error naming that path when it does not exist), else none. A LoRA file that cannot be
//! read, that targets weights the prior does not have, or that has no entry for either
//! network is an error naming the file.

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use gb_diffusion::config::{
    AutoencoderKLConfig, ClipTextConfig, SchedulerConfig, UNet2DConditionConfig,
};
use gb_diffusion::distill::error::PRIOR_LAYOUT;
use gb_diffusion::distill::{AlphasCumprod, DistillError};
use gb_diffusion::lora::{LoraError, LoraFile};
use gb_diffusion::pipeline::SdComponents;
use gb_diffusion::precision::Precision;
use gb_diffusion::tokenizer::ClipTokenizer;

use crate::error::InpaintError;
use crate::method::MethodConfig;

pub use gb_diffusion::distill::{PriorInfo, PriorOptions, SdPrior};
pub use gb_diffusion::lora::LORA_FILE_NAME;

/// The LoRA of a run: `explicit` (`--lora`) wins; else the prior's own file when the method
/// uses one (an error when it is missing); else none.
pub fn lora_for(
    method: &MethodConfig,
    prior_dir: &Path,
    explicit: Option<&Path>,
) -> Result<Option<PathBuf>, InpaintError> {
    if let Some(p) = explicit {
        if !p.is_file() {
            return Err(InpaintError::Lora {
                path: p.to_path_buf(),
                reason: "no such file (--lora takes a .safetensors LoRA file)".into(),
            });
        }
        if !method.use_lora {
            tracing::warn!(
                lora = %p.display(),
                method = %method.name,
                "--lora given: attaching it although the method has use_lora = false"
            );
        }
        return Ok(Some(p.to_path_buf()));
    }
    if !method.use_lora {
        return Ok(None);
    }
    let expected = prior_dir.join(LORA_FILE_NAME);
    if expected.is_file() {
        Ok(Some(expected))
    } else {
        Err(InpaintError::LoraMissing {
            method: method.name.clone(),
            expected,
        })
    }
}

/// Reads a LoRA file; the error names it once.
pub(crate) fn read_lora(path: &Path) -> Result<LoraFile, InpaintError> {
    LoraFile::read(path).map_err(|e| lora_error(path, &e))
}

/// [`InpaintError::Lora`] for the file `path`, naming it once (gb-diffusion's message of a
/// file that cannot be read already starts with "LoRA file PATH: ").
fn lora_error(path: &Path, e: &LoraError) -> InpaintError {
    let text = e.to_string();
    let prefix = format!("LoRA file {}: ", path.display());
    InpaintError::Lora {
        path: path.to_path_buf(),
        reason: text.strip_prefix(&prefix).unwrap_or(&text).to_string(),
    }
}

/// [`SdPrior::load`] (gb-diffusion's one loader) with its errors in the run's words: a
/// folder's failure is [`InpaintError::Prior`] naming the component, a LoRA's is
/// [`InpaintError::Lora`] naming the file.
pub fn load_prior(
    root: &Path,
    opts: &PriorOptions,
    device: &Device,
) -> Result<SdPrior, InpaintError> {
    SdPrior::load(root, opts, device).map_err(|e| match e {
        DistillError::PriorFolder { path } => InpaintError::Prior {
            path,
            reason: PRIOR_LAYOUT.into(),
        },
        DistillError::Load {
            component,
            path,
            source,
        } => InpaintError::Prior {
            path,
            reason: format!("{component}: {source}"),
        },
        DistillError::Lora { path, error } => lora_error(&path, &error),
        other => InpaintError::Distill(other),
    })
}

/// A prior of the given shapes with random weights (no files but the tokenizer at
/// `tokenizer_dir`), for benchmarks at a real model's size, such as SD-1.5-inpainting's,
/// where no checkpoint is at hand. Its scores are meaningless; its cost is the real one.
pub fn random_prior(
    unet: &UNet2DConditionConfig,
    vae: &AutoencoderKLConfig,
    text: &ClipTextConfig,
    tokenizer_dir: &Path,
    precision: Precision,
    device: &Device,
) -> Result<SdPrior, InpaintError> {
    let prior_err = |component: &str, e: &dyn std::fmt::Display| InpaintError::Prior {
        path: tokenizer_dir.to_path_buf(),
        reason: format!("{component}: {e}"),
    };
    let tokenizer =
        ClipTokenizer::from_dir(tokenizer_dir).map_err(|e| prior_err("tokenizer", &e))?;
    let scheduler = SchedulerConfig::default();
    let alphas = AlphasCumprod::from_config(&scheduler).map_err(|e| prior_err("scheduler", &e))?;
    let parts = SdComponents::random(
        PathBuf::from("random-weights"),
        tokenizer,
        unet,
        vae,
        text,
        scheduler,
        device,
        &device.clone().autodiff(),
    );
    Ok(SdPrior::from_components(parts, alphas, precision, device))
}
