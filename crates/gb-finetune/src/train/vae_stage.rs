//! First stage of the tiny prior: a small `AutoencoderKL` trained from scratch on the RGB
//! images and normal maps it will later encode (reconstruction MSE of a posterior sample
//! plus a small KL term, as the LDM autoencoders minus the adversarial and perceptual
//! terms). Its `scaling_factor` is then set to `1 / std(latent mean)`, as SD's 0.18215 was.

use burn::module::Module;
use burn::optim::{AdamWConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use rand::Rng;
use serde::{Deserialize, Serialize};

use gb_diffusion::config::AutoencoderKLConfig;
use gb_diffusion::models::AutoencoderKL;

use super::batch::{normals, stream};
use super::validate::masked_psnr;
use crate::crop::random_square_crop;
use crate::sample::PairSource;
use crate::FinetuneError;

/// Hyper-parameters of the autoencoder stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VaeStageConfig {
    /// Optimiser steps.
    pub steps: usize,
    /// Images per step.
    pub batch: usize,
    /// AdamW learning rate.
    pub lr: f64,
    /// Weight of the KL term (per latent value).
    pub kl_weight: f64,
    /// Square crop side in pixels.
    pub resolution: usize,
    /// Seed of the random stream.
    pub seed: u64,
}

impl Default for VaeStageConfig {
    fn default() -> Self {
        Self {
            steps: 600,
            batch: 8,
            lr: 1e-3,
            kl_weight: 1e-6,
            resolution: 64,
            seed: 0,
        }
    }
}

/// Crops `batch` random images (RGB or normal map, half each where normals exist) for step
/// `step`, as `[b, 3, r, r]` values in `[-1, 1]`.
pub fn image_batch(
    source: &dyn PairSource,
    resolution: usize,
    batch: usize,
    seed: u64,
    step: usize,
) -> Result<Vec<f32>, FinetuneError> {
    let mut rng = stream(seed ^ 0x5641_4531, step, 0);
    let r = resolution;
    let mut out = Vec::with_capacity(batch * 3 * r * r);
    for _ in 0..batch {
        let s = source.load(rng.random_range(0..source.len()))?;
        let c = random_square_crop(&s, r, &mut rng);
        let use_normal = c.normal.is_some() && rng.random_bool(0.5);
        let px = if use_normal {
            c.normal.as_ref().unwrap_or(&c.rgb)
        } else {
            &c.rgb
        };
        for ch in 0..3 {
            out.extend((0..r * r).map(|i| px[i * 3 + ch] * 2.0 - 1.0));
        }
    }
    Ok(out)
}

/// Trains a VAE of shape `vae_config` from scratch on `source`; `on_step(step, loss)` is
/// called after each step. Returns the VAE (with `scaling_factor` set) and its losses.
pub fn train_vae(
    vae_config: &AutoencoderKLConfig,
    source: &dyn PairSource,
    cfg: &VaeStageConfig,
    device: &Device,
    mut on_step: impl FnMut(usize, f64),
) -> Result<(AutoencoderKL, Vec<f64>), FinetuneError> {
    if source.is_empty() {
        return Err(FinetuneError::Config {
            field: "dataset".into(),
            message: "the autoencoder stage has no images".into(),
        });
    }
    device.seed(cfg.seed);
    let mut vae = AutoencoderKL::new(vae_config, device);
    let mut optim = AdamWConfig::new().with_weight_decay(0.0).init();
    let r = cfg.resolution;
    let mut losses = Vec::with_capacity(cfg.steps);
    for step in 0..cfg.steps {
        let x = image_batch(source, r, cfg.batch, cfg.seed, step)?;
        let x = Tensor::<4>::from_data(TensorData::new(x, [cfg.batch, 3, r, r]), device);
        let (mean, logvar) = vae.encode_moments(x.clone());
        let dims = mean.dims();
        let mut rng = stream(cfg.seed ^ 0x4e4f_4953, step, 0);
        let eps = Tensor::<4>::from_data(
            TensorData::new(normals(&mut rng, dims.iter().product()), dims),
            device,
        );
        let z = mean.clone() + logvar.clone().mul_scalar(0.5).exp() * eps;
        let recon = vae.decode(z);
        let mse = (recon - x).powi_scalar(2).mean();
        let kl = (mean.powi_scalar(2) + logvar.clone().exp() - logvar - 1.0)
            .mean()
            .mul_scalar(0.5);
        let loss = mse + kl.mul_scalar(cfg.kl_weight);
        let value = loss.clone().into_scalar::<f64>();
        if !value.is_finite() {
            return Err(FinetuneError::Diverged {
                step,
                message: format!("autoencoder loss {value}; lower `lr`"),
            });
        }
        let grads = GradientsParams::from_grads(loss.backward(), &vae);
        vae = optim.step(cfg.lr, vae, grads);
        losses.push(value);
        on_step(step, value);
    }
    vae.scaling_factor = latent_scale(&vae, source, cfg, device)?;
    Ok((vae, losses))
}

/// `1 / std` of the latent means over a few held batches (SD's `scaling_factor` rule).
pub fn latent_scale(
    vae: &AutoencoderKL,
    source: &dyn PairSource,
    cfg: &VaeStageConfig,
    device: &Device,
) -> Result<f64, FinetuneError> {
    let (mut sum, mut sq, mut n) = (0.0f64, 0.0f64, 0usize);
    let r = cfg.resolution;
    for k in 0..4 {
        let x = image_batch(source, r, cfg.batch, cfg.seed ^ 0x5343_414c, k)?;
        let x = Tensor::<4>::from_data(TensorData::new(x, [cfg.batch, 3, r, r]), device);
        let m: Vec<f32> = vae
            .encode_mean(x)
            .into_data()
            .try_to_vec::<f32>()
            .map_err(|e| FinetuneError::diffusion("latent statistics", format!("{e:?}")))?;
        for v in m {
            sum += v as f64;
            sq += (v as f64) * (v as f64);
            n += 1;
        }
    }
    let mean = sum / n as f64;
    let std = (sq / n as f64 - mean * mean).max(1e-12).sqrt();
    Ok(1.0 / std)
}

/// The VAE config JSON (diffusers' `config.json`) with `scaling_factor` replaced.
pub fn with_scaling_factor(config_json: &serde_json::Value, factor: f64) -> serde_json::Value {
    let mut v = config_json.clone();
    if let Some(obj) = v.as_object_mut() {
        obj.insert("scaling_factor".into(), serde_json::json!(factor));
    }
    v
}

/// The VAE as a plain (no-autodiff) frozen module.
pub fn frozen(vae: AutoencoderKL) -> AutoencoderKL {
    vae.valid().no_grad()
}

/// Images per batch and batches of [`reconstruction_psnr`]'s held-out crops.
pub const RECONSTRUCTION_CROPS: (usize, usize) = (8, 4);

/// Seed of [`reconstruction_psnr`]'s crops (fixed, so two autoencoders see the same images).
const RECONSTRUCTION_SEED: u64 = 0x5245_434f;

/// The autoencoder's ceiling: mean PSNR (dB, images in `[0, 1]`) of each image against its
/// reconstruction (the posterior mean decoded), over [`RECONSTRUCTION_CROPS`] square crops
/// of side `resolution` drawn from `source` with a fixed seed. Every fill of the prior is
/// decoded by the same decoder, so in practice none gets closer to the truth than this.
pub fn reconstruction_psnr(
    vae: &AutoencoderKL,
    source: &dyn PairSource,
    resolution: usize,
    device: &Device,
) -> Result<f64, FinetuneError> {
    let (batch, batches) = RECONSTRUCTION_CROPS;
    let r = resolution;
    let n = 3 * r * r;
    // images in [0, 1], every pixel scored (an exact reconstruction counts as 100 dB)
    let unit =
        |v: &[f32]| -> Vec<f32> { v.iter().map(|p| (p.clamp(-1.0, 1.0) + 1.0) / 2.0).collect() };
    let whole = vec![1.0f32; r * r];
    let mut sum = 0.0;
    for k in 0..batches {
        let x = image_batch(source, r, batch, RECONSTRUCTION_SEED, k)?;
        let t = Tensor::<4>::from_data(TensorData::new(x.clone(), [batch, 3, r, r]), device);
        let y: Vec<f32> = vae
            .decode(vae.encode_mean(t))
            .into_data()
            .try_to_vec::<f32>()
            .map_err(|e| {
                FinetuneError::diffusion("autoencoder reconstruction", format!("{e:?}"))
            })?;
        for i in 0..batch {
            let (a, b) = (unit(&x[i * n..(i + 1) * n]), unit(&y[i * n..(i + 1) * n]));
            sum += masked_psnr(&a, &b, &whole)
                .unwrap_or(f64::INFINITY)
                .min(100.0);
        }
    }
    Ok(sum / (batch * batches) as f64)
}
