//! [`SdPrior`]: the one type of a Stable Diffusion prior that guides a distillation (the
//! playground of `cargo xtask distill-image`, the guided NeRF of gb-inpaint, the benchmarks).
//! [`SdPrior::load`] is the one loader: a diffusers folder ([`crate::pipeline::SdComponents`]),
//! a LoRA merged into the U-Net and the text encoder, a per-scene LoRA merged on top
//! ([`PriorOptions`]). It and the random-weight benchmarks build it in one place,
//! [`SdPrior::from_components`]: the U-Net and the text encoder on the plain device (they run
//! without a graph), the VAE on its autodiff version with frozen parameters (the guidance
//! gradient reaches the image through the encoder only), all three cast once, after any LoRA
//! is merged in f32, to the [`Precision`].

use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::tensor::Device;
use serde::Serialize;

use super::alphas::AlphasCumprod;
use super::error::{BoxedSourceError, DistillError};
use super::sd_adapter::{SdUnetEps, SdVaeEncoder};
use crate::clip::ClipPromptEncoder;
use crate::lora::LoraFile;
use crate::pipeline::{LoraCounts, SdComponents};
use crate::precision::{cast_frozen, Precision};

/// What a prior was loaded from, for a run's `config.toml` and the logs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PriorInfo {
    /// The prior folder.
    pub folder: PathBuf,
    /// The LoRA file attached, if any.
    pub lora: Option<PathBuf>,
    /// The per-scene LoRA merged on top, if any (gb-inpaint's `personalize`).
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

/// How [`SdPrior::load`] loads a prior.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PriorOptions {
    /// A LoRA file attached to the U-Net and the text encoder and merged into their weights.
    pub lora: Option<PathBuf>,
    /// A per-scene LoRA (trained on top of the prior with `lora` merged) merged after it.
    pub personal: Option<PathBuf>,
    /// The precision the networks compute in; `None`: the device's default
    /// ([`Precision::default_for`]).
    pub precision: Option<Precision>,
}

/// A Stable Diffusion prior loaded for distillation.
pub struct SdPrior {
    /// The U-Net (no graph).
    pub unet: SdUnetEps,
    /// The VAE encoder (autodiff).
    pub encoder: SdVaeEncoder,
    /// The text encoder (no graph).
    pub text: ClipPromptEncoder,
    /// `alphas_cumprod` of the scheduler.
    pub alphas: AlphasCumprod,
    /// The prior's native image resolution (`unet.sample_size * factor`, 512 for SD 1.5).
    pub resolution: usize,
    /// The plain device of the U-Net and text encoder (the VAE runs on its autodiff version).
    pub device: Device,
    /// What was loaded (the LoRA fields are the loader's to fill).
    pub info: PriorInfo,
}

impl SdPrior {
    /// Loads the diffusers folder `root` ([`SdComponents::load`]: the U-Net and text encoder
    /// on `device`, the VAE on its autodiff version), merges `opts`' LoRA and then its
    /// per-scene LoRA, and casts the networks to `opts`' precision. Both LoRA files are read
    /// before any weights load, so that a bad one fails at once; an error names the folder's
    /// component or the LoRA file.
    pub fn load(root: &Path, opts: &PriorOptions, device: &Device) -> Result<Self, DistillError> {
        if !root.is_dir() {
            return Err(DistillError::PriorFolder {
                path: root.to_path_buf(),
            });
        }
        let lora_err = |path: &Path| {
            let path = path.to_path_buf();
            move |error| DistillError::Lora {
                path,
                error: Box::new(error),
            }
        };
        let read = |p: &PathBuf| LoraFile::read(p).map_err(lora_err(p));
        let lora = opts.lora.as_ref().map(read).transpose()?;
        let personal = opts.personal.as_ref().map(read).transpose()?;
        let load_err = |component: &'static str, source: BoxedSourceError| DistillError::Load {
            component,
            path: root.to_path_buf(),
            source,
        };
        let c = SdComponents::load(root, device, &device.clone().autodiff())
            .map_err(|e| load_err(e.component, e.source))?;
        let alphas = AlphasCumprod::from_config(&c.scheduler)
            .map_err(|e| load_err("scheduler", Box::new(e)))?;
        let (mut c, mut counts) = (c, LoraCounts::default());
        if let Some(file) = &lora {
            (c, counts) = c.merge_lora(file).map_err(lora_err(&file.path))?;
            tracing::info!(
                lora = %file.path.display(),
                unet_weights = counts.unet,
                text_encoder_weights = counts.text_encoder,
                "LoRA attached and merged"
            );
        }
        if let Some(file) = &personal {
            (c, _) = c.merge_lora(file).map_err(lora_err(&file.path))?;
            tracing::info!(lora = %file.path.display(), "per-scene LoRA merged");
        }
        let precision = opts
            .precision
            .unwrap_or_else(|| Precision::default_for(device));
        let mut prior = Self::from_components(c, alphas, precision, device);
        prior.info.lora = opts.lora.clone();
        prior.info.personal_lora = opts.personal.clone();
        prior.info.lora_unet_weights = counts.unet;
        prior.info.lora_text_encoder_weights = counts.text_encoder;
        Ok(prior)
    }

    /// The one construction point: `c`'s networks (the U-Net and text encoder on `device`,
    /// the VAE on its autodiff version, any LoRA already merged) cast to `precision`, frozen,
    /// and wrapped behind the distillation interfaces, with the schedule's `alphas`. Its
    /// [`PriorInfo`] names `c.root` and no LoRA.
    pub fn from_components(
        c: SdComponents,
        alphas: AlphasCumprod,
        precision: Precision,
        device: &Device,
    ) -> Self {
        let (factor, resolution) = (c.vae_factor(), c.resolution());
        Self {
            info: PriorInfo {
                folder: c.root.clone(),
                lora: None,
                personal_lora: None,
                precision,
                lora_unet_weights: 0,
                lora_text_encoder_weights: 0,
                resolution,
                vae_factor: factor,
                num_train_timesteps: alphas.len(),
            },
            unet: SdUnetEps::new(
                cast_frozen(c.unet, precision),
                c.unet_config.in_channels,
                c.scheduler.prediction_type,
                alphas.clone(),
            ),
            encoder: SdVaeEncoder::new(cast_frozen(c.vae, precision).no_grad(), factor),
            text: ClipPromptEncoder::new(
                c.tokenizer,
                cast_frozen(c.text_encoder, precision),
                device.clone(),
            ),
            alphas,
            resolution,
            device: device.clone(),
        }
    }
}
