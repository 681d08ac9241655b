//! Adapters from the crate's Stable Diffusion modules to the distillation interfaces: the
//! U-Net as an [`InpaintEpsPredictor`] and the VAE encoder as a [`LatentEncoder`]. The prior
//! that holds them is [`SdPrior`].

use burn::tensor::Tensor;

use super::alphas::AlphasCumprod;
use super::eps::{EpsBatch, InpaintEpsPredictor, LatentEncoder};
use super::error::DistillError;
pub use super::sd_prior::SdPrior;
use crate::config::PredictionType;
use crate::models::{AutoencoderKL, UNet2DConditionModel};

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
