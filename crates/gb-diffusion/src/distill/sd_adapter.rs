//! Adapters from the crate's Stable Diffusion modules to the distillation interfaces: the
//! U-Net as an [`InpaintEpsPredictor`], the VAE encoder as a [`LatentEncoder`], CLIP as a
//! [`PromptEncoder`], and [`SdPrior`], which loads all three (plus the noise schedule) from a
//! diffusers-layout folder.

use std::path::Path;

use burn::module::Module;
use burn::tensor::{Device, Tensor};

use super::alphas::AlphasCumprod;
use super::conditioning::PromptEncoder;
use super::eps::{EpsBatch, InpaintEpsPredictor, LatentEncoder};
use super::error::DistillError;
use crate::checkpoint::{DiffusersFolder, WeightVariant};
use crate::clip::{load_text_encoder, ClipTextModel};
use crate::config::{PredictionType, SchedulerConfig};
use crate::models::{load_unet, load_vae, AutoencoderKL, UNet2DConditionModel};
use crate::tokenizer::ClipTokenizer;

fn boxed<E: std::error::Error + Send + Sync + 'static>(e: E) -> super::error::BoxedSourceError {
    Box::new(e)
}

/// The SD U-Net as a noise predictor. A 9-channel (inpainting) U-Net receives
/// `[x_t, mask, masked_image_latents]`; a 4-channel one only `x_t`. A v-prediction U-Net's
/// output is converted to eps with `eps = sqrt(ab) * v + sqrt(1 - ab) * x_t`.
pub struct SdUnetEps {
    unet: UNet2DConditionModel,
    in_channels: usize,
    prediction: PredictionType,
    alphas: AlphasCumprod,
}

impl SdUnetEps {
    /// Wraps a U-Net loaded on a non-autodiff device.
    pub fn new(
        unet: UNet2DConditionModel,
        in_channels: usize,
        prediction: PredictionType,
        alphas: AlphasCumprod,
    ) -> Self {
        Self {
            unet,
            in_channels,
            prediction,
            alphas,
        }
    }
}

impl InpaintEpsPredictor for SdUnetEps {
    fn predict_eps(&self, batch: EpsBatch) -> Result<Tensor<4>, DistillError> {
        let c = batch.noisy_latents.dims()[1];
        let sample = if self.in_channels == c {
            batch.noisy_latents.clone()
        } else if self.in_channels == 2 * c + 1 {
            Tensor::cat(
                vec![
                    batch.noisy_latents.clone(),
                    batch.mask.clone(),
                    batch.masked_image_latents.clone(),
                ],
                1,
            )
        } else {
            return Err(DistillError::Shape {
                tensor: "U-Net input",
                actual: batch.noisy_latents.dims().to_vec(),
                expected: format!(
                    "latents whose channels c give in_channels = {} as c or 2c + 1",
                    self.in_channels
                ),
            });
        };
        let out = self.unet.forward(
            sample,
            &[batch.timestep as f32],
            batch.text_embeddings.clone(),
        );
        Ok(match self.prediction {
            PredictionType::Epsilon => out,
            PredictionType::VPrediction => {
                let ab = self.alphas.at(batch.timestep);
                out.mul_scalar(ab.sqrt()) + batch.noisy_latents.mul_scalar((1.0 - ab).sqrt())
            }
        })
    }
}

/// The VAE encoder: `mean(image) * scaling_factor`, differentiable (the module lives on an
/// autodiff device; its parameters are not trained).
pub struct SdVaeEncoder {
    vae: AutoencoderKL,
    factor: usize,
}

impl SdVaeEncoder {
    /// Wraps a VAE loaded on an autodiff device (parameters frozen with `no_grad`), with its
    /// spatial factor `2^(len(block_out_channels) - 1)`.
    pub fn new(vae: AutoencoderKL, factor: usize) -> Self {
        Self { vae, factor }
    }
}

impl LatentEncoder for SdVaeEncoder {
    fn encode(&self, image: Tensor<4>) -> Result<Tensor<4>, DistillError> {
        let image = if image.is_autodiff() {
            image
        } else {
            image.autodiff()
        };
        Ok(self
            .vae
            .encode_mean(image)
            .mul_scalar(self.vae.scaling_factor))
    }

    fn downsample_factor(&self) -> usize {
        self.factor
    }
}

/// CLIP tokenizer + text model as a prompt encoder (`last_hidden_state`, `[1, 77, D]`).
pub struct ClipPromptEncoder {
    tokenizer: ClipTokenizer,
    model: ClipTextModel,
    device: Device,
}

impl PromptEncoder for ClipPromptEncoder {
    fn encode_prompt(&self, prompt: &str) -> Result<Tensor<3>, DistillError> {
        let err = |source| DistillError::PromptEncoder {
            prompt: prompt.to_string(),
            source,
        };
        let ids = self.tokenizer.encode(prompt).map_err(|e| err(boxed(e)))?;
        let row: Vec<i64> = ids.into_iter().map(i64::from).collect();
        let ids = self
            .model
            .ids_tensor(&[row], &self.device)
            .map_err(|e| err(boxed(e)))?;
        Ok(self.model.forward(ids))
    }
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
}

impl SdPrior {
    /// Loads `unet/`, `vae/`, `text_encoder/`, `tokenizer/` and `scheduler/` from a
    /// diffusers folder; the U-Net and text encoder on `device`, the VAE on its autodiff
    /// version.
    pub fn load(root: &Path, device: &Device) -> Result<Self, DistillError> {
        let load = |component: &'static str| {
            move |e: super::error::BoxedSourceError| DistillError::Load {
                component,
                path: root.to_path_buf(),
                source: e,
            }
        };
        let folder = DiffusersFolder::open(root).map_err(|e| load("model_index")(boxed(e)))?;
        let (unet, unet_cfg) = load_unet(root, device).map_err(|e| load("unet")(boxed(e)))?;
        let (vae, vae_cfg) =
            load_vae(root, &device.clone().autodiff()).map_err(|e| load("vae")(boxed(e)))?;
        let vae = vae.no_grad();
        let model = load_text_encoder(&folder, WeightVariant::Auto, device)
            .map_err(|e| load("text_encoder")(boxed(e)))?;
        let tok_dir = folder
            .component_dir("tokenizer")
            .map_err(|e| load("tokenizer")(boxed(e)))?;
        let tokenizer =
            ClipTokenizer::from_dir(&tok_dir).map_err(|e| load("tokenizer")(boxed(e)))?;
        let sched_path = root.join("scheduler").join("scheduler_config.json");
        let sched = if sched_path.is_file() {
            SchedulerConfig::from_file(&sched_path).map_err(|e| load("scheduler")(boxed(e)))?
        } else {
            SchedulerConfig::default()
        };
        let alphas = AlphasCumprod::from_config(&sched)?;
        let factor = vae_cfg.scale_factor();
        let resolution = unet_cfg.sample_size.unwrap_or(64) * factor;
        Ok(Self {
            unet: SdUnetEps::new(
                unet,
                unet_cfg.in_channels,
                sched.prediction_type,
                alphas.clone(),
            ),
            encoder: SdVaeEncoder::new(vae, factor),
            text: ClipPromptEncoder {
                tokenizer,
                model,
                device: device.clone(),
            },
            alphas,
            resolution,
        })
    }
}
