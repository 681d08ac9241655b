//! The diffusion prior of a run: a diffusers-layout Stable Diffusion inpainting folder
//! (U-Net, VAE, CLIP text encoder, tokenizer, scheduler), optionally with a LoRA file attached
//! to the U-Net and the text encoder and merged into their weights.
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

use burn::module::Module;
use burn::tensor::Device;
use gb_diffusion::clip::{ClipPromptEncoder, ClipTextModel};
use gb_diffusion::config::{
    AutoencoderKLConfig, ClipTextConfig, PredictionType, SchedulerConfig, UNet2DConditionConfig,
};
use gb_diffusion::distill::sd_adapter::{SdUnetEps, SdVaeEncoder};
use gb_diffusion::distill::{AlphasCumprod, InpaintEpsPredictor, LatentEncoder, PromptEncoder};
use gb_diffusion::lora::LoraFile;
use gb_diffusion::models::{AutoencoderKL, UNet2DConditionModel};
use gb_diffusion::pipeline::{LoraCounts, SdComponents};
use gb_diffusion::precision::{cast_frozen, Precision};
use gb_diffusion::tokenizer::ClipTokenizer;
use serde::Serialize;

use crate::error::InpaintError;
use crate::method::MethodConfig;

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
    LoraFile::read(path).map_err(|e| {
        // gb-diffusion's message already starts with "LoRA file PATH: "
        let text = e.to_string();
        let prefix = format!("LoRA file {}: ", path.display());
        InpaintError::Lora {
            path: path.to_path_buf(),
            reason: text.strip_prefix(&prefix).unwrap_or(&text).to_string(),
        }
    })
}

/// What was loaded, for `config.toml` and the logs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PriorInfo {
    /// The prior folder.
    pub folder: PathBuf,
    /// The LoRA file attached, if any.
    pub lora: Option<PathBuf>,
    /// The per-scene LoRA merged on top, if any ([`crate::personalize`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub personal_lora: Option<PathBuf>,
    /// The precision the networks compute in.
    pub precision: Precision,
    /// Weights adapted by the LoRA in the U-Net.
    pub lora_unet_weights: usize,
    /// Weights adapted by the LoRA in the text encoder.
    pub lora_text_encoder_weights: usize,
    /// The prior's native square resolution (U-Net sample size times the VAE factor).
    pub resolution: usize,
    /// The VAE's spatial factor.
    pub vae_factor: usize,
    /// Number of diffusion training timesteps.
    pub num_train_timesteps: usize,
}

/// The loaded prior behind the distillation interfaces (so that tests may substitute mocks).
pub struct GuidancePrior {
    /// Noise predictor (no graph).
    pub unet: Box<dyn InpaintEpsPredictor>,
    /// Differentiable latent encoder.
    pub encoder: Box<dyn LatentEncoder>,
    /// Prompt encoder.
    pub text: Box<dyn PromptEncoder>,
    /// `alphas_cumprod` of the scheduler.
    pub alphas: AlphasCumprod,
    /// The prior's square input resolution.
    pub resolution: usize,
    /// What was loaded.
    pub info: PriorInfo,
}

impl GuidancePrior {
    /// Loads the prior folder `root` on `device` (the plain device of the run's backend) in
    /// `precision` and attaches `lora` (see the module docs).
    pub fn load(
        root: &Path,
        lora: Option<&Path>,
        precision: Precision,
        device: &Device,
    ) -> Result<Self, InpaintError> {
        Self::load_personalized(root, lora, None, precision, device)
    }

    /// [`Self::load`], then the per-scene LoRA `personal` ([`crate::personalize`], trained on
    /// top of the prior with `lora` merged) merged as well.
    pub fn load_personalized(
        root: &Path,
        lora: Option<&Path>,
        personal: Option<&Path>,
        precision: Precision,
        device: &Device,
    ) -> Result<Self, InpaintError> {
        let prior_err = |component: &str, e: &dyn std::fmt::Display| InpaintError::Prior {
            path: root.to_path_buf(),
            reason: format!("{component}: {e}"),
        };
        if !root.is_dir() {
            return Err(InpaintError::Prior {
                path: root.to_path_buf(),
                reason: "not a folder (expected a diffusers layout: model_index.json, unet/, \
                         vae/, text_encoder/, tokenizer/, scheduler/)"
                    .into(),
            });
        }
        let lora_file = lora.map(read_lora).transpose()?;
        let personal_file = personal.map(read_lora).transpose()?;
        let lora_err = |e: &dyn std::fmt::Display| InpaintError::Lora {
            path: lora.map(Path::to_path_buf).unwrap_or_default(),
            reason: e.to_string(),
        };
        let loaded = SdComponents::load(root, device, &device.clone().autodiff())
            .map_err(|e| prior_err(e.component, &e.source))?;
        let alphas = AlphasCumprod::from_config(&loaded.scheduler)
            .map_err(|e| prior_err("scheduler", &e))?;
        let (mut loaded, mut counts) = (loaded, LoraCounts::default());
        if let Some(file) = &lora_file {
            (loaded, counts) = loaded.merge_lora(file).map_err(|e| lora_err(&e))?;
            tracing::info!(
                lora = %file.path.display(),
                unet_weights = counts.unet,
                text_encoder_weights = counts.text_encoder,
                "LoRA attached and merged"
            );
        }
        if let Some(file) = &personal_file {
            (loaded, _) = loaded.merge_lora(file).map_err(|e| InpaintError::Lora {
                path: file.path.clone(),
                reason: e.to_string(),
            })?;
            tracing::info!(lora = %file.path.display(), "per-scene LoRA merged");
        }
        let parts = Parts {
            in_channels: loaded.unet_config.in_channels,
            resolution: loaded.resolution(),
            factor: loaded.vae_factor(),
            prediction: loaded.scheduler.prediction_type,
            unet: loaded.unet,
            vae: loaded.vae,
            text: loaded.text_encoder,
            tokenizer: loaded.tokenizer,
            alphas,
        };
        let mut prior = parts.into_prior(
            root.to_path_buf(),
            lora.map(Path::to_path_buf),
            (counts.unet, counts.text_encoder),
            precision,
            device,
        );
        prior.info.personal_lora = personal.map(Path::to_path_buf);
        Ok(prior)
    }

    /// A prior of the given shapes with random weights (no files but the tokenizer at
    /// `tokenizer_dir`), for benchmarks at a real model's size, such as SD-1.5-inpainting's,
    /// where no checkpoint is at hand. Its scores are meaningless; its cost is the real one.
    pub fn random(
        unet: &UNet2DConditionConfig,
        vae: &AutoencoderKLConfig,
        text: &ClipTextConfig,
        tokenizer_dir: &Path,
        precision: Precision,
        device: &Device,
    ) -> Result<Self, InpaintError> {
        let prior_err = |component: &str, e: &dyn std::fmt::Display| InpaintError::Prior {
            path: tokenizer_dir.to_path_buf(),
            reason: format!("{component}: {e}"),
        };
        let tokenizer =
            ClipTokenizer::from_dir(tokenizer_dir).map_err(|e| prior_err("tokenizer", &e))?;
        let sched = SchedulerConfig::default();
        let alphas = AlphasCumprod::from_config(&sched).map_err(|e| prior_err("scheduler", &e))?;
        let parts = Parts {
            unet: UNet2DConditionModel::new(unet, device),
            in_channels: unet.in_channels,
            resolution: unet.native_resolution(vae.scale_factor()),
            vae: AutoencoderKL::new(vae, &device.clone().autodiff()),
            factor: vae.scale_factor(),
            text: ClipTextModel::new(text, device),
            tokenizer,
            prediction: sched.prediction_type,
            alphas,
        };
        Ok(parts.into_prior(
            PathBuf::from("random-weights"),
            None,
            (0, 0),
            precision,
            device,
        ))
    }
}

/// The networks of a prior, loaded or built, before [`GuidancePrior`] wraps them.
struct Parts {
    unet: UNet2DConditionModel,
    in_channels: usize,
    /// The native square resolution ([`UNet2DConditionConfig::native_resolution`]).
    resolution: usize,
    /// On the autodiff device.
    vae: AutoencoderKL,
    factor: usize,
    text: ClipTextModel,
    tokenizer: ClipTokenizer,
    prediction: PredictionType,
    alphas: AlphasCumprod,
}

impl Parts {
    /// Casts the networks to `precision` and wraps them behind the distillation interfaces;
    /// `lora_weights` are the U-Net and text-encoder weights a LoRA adapted.
    fn into_prior(
        self,
        folder: PathBuf,
        lora: Option<PathBuf>,
        lora_weights: (usize, usize),
        precision: Precision,
        device: &Device,
    ) -> GuidancePrior {
        let resolution = self.resolution;
        GuidancePrior {
            info: PriorInfo {
                folder,
                lora,
                personal_lora: None,
                precision,
                lora_unet_weights: lora_weights.0,
                lora_text_encoder_weights: lora_weights.1,
                resolution,
                vae_factor: self.factor,
                num_train_timesteps: self.alphas.len(),
            },
            unet: Box::new(SdUnetEps::new(
                cast_frozen(self.unet, precision),
                self.in_channels,
                self.prediction,
                self.alphas.clone(),
            )),
            encoder: Box::new(SdVaeEncoder::new(
                cast_frozen(self.vae, precision).no_grad(),
                self.factor,
            )),
            text: Box::new(ClipPromptEncoder::new(
                self.tokenizer,
                cast_frozen(self.text, precision),
                device.clone(),
            )),
            alphas: self.alphas,
            resolution,
        }
    }
}
