//! The self-supervised inpainting loss of diffusers' inpainting trainers: encode the image
//! and the masked image with the frozen VAE, noise the latent at a random timestep, feed the
//! 9-channel input `[noisy latent, mask at latent size, masked-image latent]` to the U-Net
//! conditioned on the prompt, and regress the noise (or `v`) with an f32 MSE.

use burn::tensor::{Device, Tensor, TensorData};

use gb_diffusion::config::PredictionType;

use super::batch::HostBatch;
use super::models::{PriorModels, Trainable};
use crate::FinetuneError;

/// Conditioning built from a batch with the frozen VAE (no graph).
pub struct LatentBatch {
    /// Clean latents times `scaling_factor`, `[b, c, h, w]` (`c` the VAE's latent channels).
    pub latents: Tensor<4>,
    /// Masked-image latents times `scaling_factor`, `[b, c, h, w]`.
    pub masked_latents: Tensor<4>,
    /// The hole at latent resolution (nearest, as diffusers' `interpolate`), `[b, 1, h, w]`.
    pub mask: Tensor<4>,
}

/// Nearest down-sampling of `[b, 1, r, r]` holes by `factor` (PyTorch's `nearest`: the
/// top-left pixel of each cell), binarised at 0.5.
pub fn mask_to_latent(masks: &[f32], batch: usize, r: usize, factor: usize) -> Vec<f32> {
    let l = r / factor;
    let mut out = Vec::with_capacity(batch * l * l);
    for b in 0..batch {
        for y in 0..l {
            for x in 0..l {
                let v = masks[b * r * r + (y * factor) * r + x * factor];
                out.push(if v >= 0.5 { 1.0 } else { 0.0 });
            }
        }
    }
    out
}

/// Encodes the images and masked images of `batch` (pixels in `[-1, 1]`, masked pixels 0,
/// as diffusers' `prepare_mask_and_masked_image`) with the VAE posterior mean.
pub fn encode_batch(models: &PriorModels, batch: &HostBatch, device: &Device) -> LatentBatch {
    let (b, r, f) = (batch.size, batch.resolution, models.vae_factor);
    let mut x = Vec::with_capacity(batch.images.len());
    let mut masked = Vec::with_capacity(batch.images.len());
    for i in 0..b {
        for c in 0..3 {
            for p in 0..r * r {
                let v = batch.images[(i * 3 + c) * r * r + p] * 2.0 - 1.0;
                x.push(v);
                masked.push(if batch.masks[i * r * r + p] >= 0.5 {
                    0.0
                } else {
                    v
                });
            }
        }
    }
    let sf = models.vae.scaling_factor;
    let both = Tensor::<4>::from_data(
        TensorData::new([x, masked].concat(), [2 * b, 3, r, r]),
        device,
    );
    let z = models.vae.encode_mean(both).mul_scalar(sf).detach();
    let l = r / f;
    LatentBatch {
        latents: z.clone().narrow(0, 0, b),
        masked_latents: z.narrow(0, b, b),
        mask: Tensor::from_data(
            TensorData::new(mask_to_latent(&batch.masks, b, r, f), [b, 1, l, l]),
            device,
        ),
    }
}

/// The loss of one micro-batch for `trainable` (which may carry LoRA adapters): mean
/// squared error between the U-Net's prediction and the target of the schedule's
/// `prediction_type`. `train_text` runs the text encoder under autodiff; otherwise its
/// output is detached.
pub fn inpainting_loss(
    models: &PriorModels,
    trainable: &Trainable,
    batch: &HostBatch,
    device: &Device,
    train_text: bool,
) -> Result<Tensor<1>, FinetuneError> {
    let (b, r, f) = (batch.size, batch.resolution, models.vae_factor);
    let l = r / f;
    let cond = encode_batch(models, batch, device);
    let c = models.vae.latent_channels;
    let noise = Tensor::<4>::from_data(TensorData::new(batch.noise.clone(), [b, c, l, l]), device);
    let ab: Vec<f32> = batch
        .timesteps
        .iter()
        .map(|&t| models.alphas_cumprod[t] as f32)
        .collect();
    let sqrt_ab = Tensor::<4>::from_data(
        TensorData::new(
            ab.iter().map(|a| a.sqrt()).collect::<Vec<_>>(),
            [b, 1, 1, 1],
        ),
        device,
    );
    let sqrt_1mab = Tensor::<4>::from_data(
        TensorData::new(
            ab.iter().map(|a| (1.0 - a).sqrt()).collect::<Vec<_>>(),
            [b, 1, 1, 1],
        ),
        device,
    );
    let noisy = cond.latents.clone() * sqrt_ab.clone() + noise.clone() * sqrt_1mab.clone();
    let input = Tensor::cat(vec![noisy, cond.mask, cond.masked_latents], 1);
    let ids = models.token_ids(&batch.prompts, device)?;
    let context = trainable.text_encoder.forward(ids);
    let context = if train_text {
        context
    } else {
        context.detach()
    };
    let ts: Vec<f32> = batch.timesteps.iter().map(|&t| t as f32).collect();
    let pred = trainable.unet.forward(input, &ts, context);
    let target = match models.scheduler.prediction_type {
        PredictionType::VPrediction => noise * sqrt_ab - cond.latents * sqrt_1mab,
        _ => noise,
    };
    Ok((pred - target).powi_scalar(2).mean())
}
