//! The one loader of a diffusers Stable Diffusion folder: [`SdComponents::load`] reads the
//! tokenizer, text encoder, U-Net, VAE and scheduler (`model_index.json` layout, `.fp16`
//! variants, safetensors only) and names the component that failed; [`SdComponents::random`]
//! builds the same networks with random weights. Every user of a prior starts here: the 2D
//! inpainting pipeline ([`crate::inpaint`], on [`SdComponents::load_inpainting`]), the
//! distillation prior of the playground, the guided NeRF and the benchmarks
//! ([`crate::distill::SdPrior`]), and LoRA fine-tuning (`gb_finetune::train::PriorModels`).

use std::path::{Path, PathBuf};

use burn::tensor::Device;

use crate::checkpoint::{DiffusersFolder, WeightVariant};
use crate::clip::{load_text_encoder, ClipTextModel};
use crate::config::ClipTextConfig;
use crate::config::{AutoencoderKLConfig, SchedulerConfig, UNet2DConditionConfig};
use crate::lora::{merge_pipeline_lora, LoraError, LoraFile};
use crate::models::{load_unet, load_vae, AutoencoderKL, UNet2DConditionModel};
use crate::tokenizer::ClipTokenizer;

/// A component of the folder that could not be loaded.
#[derive(Debug, thiserror::Error)]
#[error("{component}: {source}")]
pub struct ComponentError {
    /// `model_index`, `tokenizer`, `text_encoder`, `unet`, `vae` or `scheduler`.
    pub component: &'static str,
    /// The cause.
    pub source: Box<dyn std::error::Error + Send + Sync + 'static>,
}

fn component<E: std::error::Error + Send + Sync + 'static>(
    component: &'static str,
) -> impl Fn(E) -> ComponentError {
    move |e| ComponentError {
        component,
        source: Box::new(e),
    }
}

/// Every network and config of a diffusers Stable Diffusion folder.
#[derive(Clone)]
pub struct SdComponents {
    /// Where the networks came from: the folder, a recipe folder, or a name (random weights).
    pub root: PathBuf,
    /// CLIP tokenizer of `tokenizer/`.
    pub tokenizer: ClipTokenizer,
    /// CLIP text encoder of `text_encoder/`.
    pub text_encoder: ClipTextModel,
    /// The U-Net of `unet/`.
    pub unet: UNet2DConditionModel,
    /// Its config.
    pub unet_config: UNet2DConditionConfig,
    /// The VAE of `vae/` (on the VAE's device).
    pub vae: AutoencoderKL,
    /// Its config.
    pub vae_config: AutoencoderKLConfig,
    /// `scheduler/scheduler_config.json` (SD-1.5 defaults when absent).
    pub scheduler: SchedulerConfig,
    /// The device of the U-Net and the text encoder (the VAE's may be its autodiff version).
    pub device: Device,
}

/// How many weights a LoRA adapted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LoraCounts {
    /// In the U-Net.
    pub unet: usize,
    /// In the text encoder.
    pub text_encoder: usize,
}

impl SdComponents {
    /// Loads every component of `root` (tokenizer, text encoder, U-Net, VAE, scheduler, in
    /// that order): the U-Net and text encoder on `device`, the VAE on `vae_device` (an
    /// autodiff device where gradients flow through the encoder).
    pub fn load(root: &Path, device: &Device, vae_device: &Device) -> Result<Self, ComponentError> {
        // the cheap components first: a folder that is no pipeline fails before any weights load
        let folder = DiffusersFolder::open(root).map_err(component("model_index"))?;
        let tok_dir = folder
            .component_dir("tokenizer")
            .map_err(component("tokenizer"))?;
        let tokenizer = ClipTokenizer::from_dir(&tok_dir).map_err(component("tokenizer"))?;
        let text_encoder = load_text_encoder(&folder, WeightVariant::Auto, device)
            .map_err(component("text_encoder"))?;
        let (unet, unet_config) = load_unet(root, device).map_err(component("unet"))?;
        let (vae, vae_config) = load_vae(root, vae_device).map_err(component("vae"))?;
        let sched_path = root.join("scheduler").join("scheduler_config.json");
        let scheduler = if sched_path.is_file() {
            SchedulerConfig::from_file(&sched_path).map_err(component("scheduler"))?
        } else {
            SchedulerConfig::default()
        };
        Ok(Self {
            root: root.to_path_buf(),
            tokenizer,
            text_encoder,
            unet,
            unet_config,
            vae,
            vae_config,
            scheduler,
            device: device.clone(),
        })
    }

    /// Networks of the given configs with random weights (the U-Net and text encoder on
    /// `device`, the VAE on `vae_device`), named `root`: a prior at a real model's size
    /// where no checkpoint is at hand, whose cost is the real one and whose scores mean
    /// nothing.
    #[allow(clippy::too_many_arguments)]
    pub fn random(
        root: PathBuf,
        tokenizer: ClipTokenizer,
        unet: &UNet2DConditionConfig,
        vae: &AutoencoderKLConfig,
        text: &ClipTextConfig,
        scheduler: SchedulerConfig,
        device: &Device,
        vae_device: &Device,
    ) -> Self {
        Self {
            root,
            tokenizer,
            text_encoder: ClipTextModel::new(text, device),
            unet: UNet2DConditionModel::new(unet, device),
            unet_config: unet.clone(),
            vae: AutoencoderKL::new(vae, vae_device),
            vae_config: vae.clone(),
            scheduler,
            device: device.clone(),
        }
    }

    /// Attaches the LoRA `file` to the U-Net and the text encoder and merges it into their
    /// weights.
    pub fn merge_lora(mut self, file: &LoraFile) -> Result<(Self, LoraCounts), LoraError> {
        let merged = merge_pipeline_lora(self.unet, &self.unet_config, self.text_encoder, file)?;
        self.unet = merged.unet;
        self.text_encoder = merged.text_encoder;
        let counts = LoraCounts {
            unet: merged.unet_weights,
            text_encoder: merged.text_encoder_weights,
        };
        Ok((self, counts))
    }

    /// The image-to-latent factor of the VAE.
    pub fn vae_factor(&self) -> usize {
        self.vae_config.scale_factor()
    }

    /// The prior's square input resolution (`unet.sample_size * factor`; 512 for SD 1.5).
    pub fn resolution(&self) -> usize {
        self.unet_config.native_resolution(self.vae_factor())
    }
}
