//! 2D inpainting with a Stable Diffusion inpainting prior: diffusers'
//! `StableDiffusionInpaintPipeline` for a 9-channel U-Net (strength 1) with DDIM.
//!
//! The U-Net input is `[noisy latent (c), mask at latent size (1), masked-image latent (c)]`,
//! `c` the VAE's latent channels (4 for Stable Diffusion).
//! Classifier-free guidance follows diffusers: `eps = eps_uncond + s * (eps_text -
//! eps_uncond)`, with the negative prompt as the unconditional input, and none when `s <= 1`.
//! The masked-image latent is the *mean* of the VAE posterior times `scaling_factor`
//! (diffusers samples it; with a trained VAE the difference is negligible).

use std::path::Path;

use burn::tensor::{Device, Tensor, TensorData};
use rand::{Rng, SeedableRng};

use crate::checkpoint::CheckpointError;
use crate::clip::{encode_prompts, PromptError};
use crate::pipeline::{ComponentError, SdComponents};
use crate::scheduler::{DdimScheduler, SchedulerError};

/// Error of the inpainting sampler.
#[derive(Debug, thiserror::Error)]
pub enum InpaintError {
    /// A component could not be loaded.
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    /// A component of the folder could not be loaded.
    #[error(transparent)]
    Component(#[from] ComponentError),
    /// A prompt could not be encoded.
    #[error(transparent)]
    Prompt(#[from] PromptError),
    /// The scheduler rejected a request.
    #[error(transparent)]
    Scheduler(#[from] SchedulerError),
    /// The U-Net is not an inpainting U-Net.
    #[error(
        "{path}: in_channels = {found} and out_channels = {out}; an inpainting U-Net for the \
         VAE's {latent} latent channels needs in_channels = {} (latent + mask + masked-image \
         latent) and out_channels = {latent}",
        2 * latent + 1
    )]
    NotInpainting {
        /// The U-Net config file.
        path: String,
        /// Its `in_channels`.
        found: usize,
        /// Its `out_channels`.
        out: usize,
        /// The VAE's `latent_channels`.
        latent: usize,
    },
    /// Image and mask disagree, or the size does not fit the VAE.
    #[error("{0}")]
    Size(String),
    /// A LoRA file could not be read or attached.
    #[error(transparent)]
    Lora(#[from] crate::lora::LoraError),
}

/// The 2D sampler's side of the one loaded-networks type: an inpainting folder, its LoRA,
/// its prompts.
impl SdComponents {
    /// Loads every component of a diffusers inpainting folder onto `device`
    /// ([`SdComponents::load`]); a U-Net that is not an inpainting U-Net for the VAE's
    /// latents is refused.
    pub fn load_inpainting(root: &Path, device: &Device) -> Result<Self, InpaintError> {
        let c = SdComponents::load(root, device, device)?;
        let latent = c.vae_config.latent_channels;
        if !c.unet_config.is_inpainting_for(latent) {
            return Err(InpaintError::NotInpainting {
                path: root.join("unet/config.json").display().to_string(),
                found: c.unet_config.in_channels,
                out: c.unet_config.out_channels,
                latent,
            });
        }
        Ok(c)
    }

    /// Attaches the LoRA file `path` to the U-Net and the text encoder and merges it into
    /// their weights. Returns the prior and the number of adapted weights (an error when the
    /// file adapts none of them).
    pub fn with_lora(self, path: &Path) -> Result<(Self, usize), InpaintError> {
        let file = crate::lora::LoraFile::read(path)?;
        let (merged, counts) = self.merge_lora(&file)?;
        Ok((merged, counts.unet + counts.text_encoder))
    }

    /// Text embeddings `[n, 77, d]` of `prompts` (`last_hidden_state`).
    pub fn encode_prompts(&self, prompts: &[&str]) -> Result<Tensor<3>, InpaintError> {
        Ok(encode_prompts(
            &self.tokenizer,
            &self.text_encoder,
            prompts,
            &self.device,
        )?)
    }
}

/// One inpainting request. Images are `[h, w, 3]` / `[h, w]` row-major in `[0, 1]`.
#[derive(Debug, Clone)]
pub struct InpaintRequest {
    /// Width of image and mask.
    pub width: usize,
    /// Height of image and mask.
    pub height: usize,
    /// RGB values in `[0, 1]`, `height * width * 3`.
    pub rgb: Vec<f32>,
    /// Mask values in `[0, 1]` (>= 0.5 is repainted), `height * width`.
    pub mask: Vec<f32>,
    /// The prompt.
    pub prompt: String,
    /// The negative prompt (the unconditional input of the guidance).
    pub negative_prompt: String,
    /// DDIM steps.
    pub steps: usize,
    /// Guidance scale `s`.
    pub guidance: f64,
    /// Seed of the initial noise.
    pub seed: u64,
    /// Initial latents `[1, c, h / f, w / f]`, `c` the VAE's latent channels (overrides
    /// `seed`; for parity runs).
    pub init_latents: Option<Vec<f32>>,
    /// After each step, replace the known region of the latents by the image's latent
    /// noised to the next timestep (with the initial noise), as diffusers' inpainting
    /// pipeline does for 4-channel U-Nets (and RePaint without resampling). Off reproduces
    /// diffusers' 9-channel pipeline exactly.
    pub blend_known: bool,
}

/// The prepared conditioning: latent-size binary mask and scaled masked-image latent.
pub struct InpaintConditioning {
    /// `[1, 1, h / f, w / f]`, 1 where the image is repainted.
    pub mask_latent: Tensor<4>,
    /// `vae.encode(image * (mask < 0.5)).mean * scaling_factor`, `[1, c, h / f, w / f]`.
    pub masked_image_latents: Tensor<4>,
}

/// Mask, masked image and its latent as diffusers prepares them: the mask is binarised at
/// 0.5, the masked image is the image in `[-1, 1]` with the masked pixels set to 0, and the
/// latent-size mask is nearest-neighbour sampled (`F.interpolate`, pixel `(i f, j f)`).
pub fn prepare_conditioning(
    prior: &SdComponents,
    req: &InpaintRequest,
) -> Result<InpaintConditioning, InpaintError> {
    let (w, h, f) = (req.width, req.height, prior.vae_factor());
    if req.rgb.len() != w * h * 3 || req.mask.len() != w * h {
        return Err(InpaintError::Size(format!(
            "image has {} values and mask {} for {w}x{h}",
            req.rgb.len(),
            req.mask.len()
        )));
    }
    if w % f != 0 || h % f != 0 || w == 0 || h == 0 {
        return Err(InpaintError::Size(format!(
            "image size {w}x{h} must be a positive multiple of the VAE factor {f}"
        )));
    }
    let binary: Vec<f32> = req
        .mask
        .iter()
        .map(|&m| if m >= 0.5 { 1.0 } else { 0.0 })
        .collect();
    let mut masked = image_chw(req);
    for plane in masked.chunks_mut(h * w) {
        for (v, m) in plane.iter_mut().zip(&binary) {
            if *m >= 0.5 {
                *v = 0.0;
            }
        }
    }
    let (lh, lw) = (h / f, w / f);
    let mut small = Vec::with_capacity(lh * lw);
    for y in 0..lh {
        for x in 0..lw {
            small.push(binary[(y * f) * w + x * f]);
        }
    }
    let device = &prior.device;
    let masked = Tensor::<4>::from_data(TensorData::new(masked, [1, 3, h, w]), device);
    let masked_image_latents = prior
        .vae
        .encode_mean(masked)
        .mul_scalar(prior.vae.scaling_factor);
    Ok(InpaintConditioning {
        mask_latent: Tensor::from_data(TensorData::new(small, [1, 1, lh, lw]), device),
        masked_image_latents,
    })
}

/// The request's image as `[3, h, w]` planes in `[-1, 1]` (the VAE's input range).
fn image_chw(req: &InpaintRequest) -> Vec<f32> {
    let hw = req.width * req.height;
    let mut out = vec![0f32; 3 * hw];
    for p in 0..hw {
        for c in 0..3 {
            out[c * hw + p] = req.rgb[p * 3 + c] * 2.0 - 1.0;
        }
    }
    out
}

/// Standard-normal values from a seeded ChaCha8 generator (Box-Muller), identical on
/// every backend.
pub fn seeded_normal(n: usize, seed: u64) -> Vec<f32> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(n + 1);
    while out.len() < n {
        let u1: f64 = rng.random::<f64>().max(f64::MIN_POSITIVE);
        let u2: f64 = rng.random::<f64>();
        let r = (-2.0 * u1.ln()).sqrt();
        let a = 2.0 * std::f64::consts::PI * u2;
        out.push((r * a.cos()) as f32);
        out.push((r * a.sin()) as f32);
    }
    out.truncate(n);
    out
}

/// Runs DDIM inpainting and returns the image `[1, 3, h, w]` in `[0, 1]`. `on_step` is
/// called after each step with its index and timestep.
pub fn inpaint(
    prior: &SdComponents,
    req: &InpaintRequest,
    mut on_step: impl FnMut(usize, usize),
) -> Result<Tensor<4>, InpaintError> {
    let cond = prepare_conditioning(prior, req)?;
    let f = prior.vae_factor();
    let (lh, lw) = (req.height / f, req.width / f);
    let c = prior.vae.latent_channels;
    let device = &prior.device;
    let init = match &req.init_latents {
        Some(v) if v.len() == c * lh * lw => v.clone(),
        Some(v) => {
            return Err(InpaintError::Size(format!(
                "initial latents have {} values, expected {c}x{lh}x{lw}",
                v.len()
            )))
        }
        None => seeded_normal(c * lh * lw, req.seed),
    };
    let mut scheduler = DdimScheduler::new(prior.scheduler.clone());
    scheduler.set_timesteps(req.steps)?;
    // DDIM's init_noise_sigma is 1.
    let mut latents = Tensor::<4>::from_data(TensorData::new(init, [1, c, lh, lw]), device);

    let cfg = req.guidance > 1.0;
    let (context, batch) = if cfg {
        let ctx = prior.encode_prompts(&[req.negative_prompt.as_str(), req.prompt.as_str()])?;
        (ctx, 2)
    } else {
        (prior.encode_prompts(&[req.prompt.as_str()])?, 1)
    };
    // the image's own latent (known region) and the initial noise, for `blend_known`
    let known = if req.blend_known {
        let img = Tensor::<4>::from_data(
            TensorData::new(image_chw(req), [1, 3, req.height, req.width]),
            device,
        );
        Some((
            prior
                .vae
                .encode_mean(img)
                .mul_scalar(prior.vae.scaling_factor),
            latents.clone(),
        ))
    } else {
        None
    };
    let timesteps = scheduler.timesteps.clone();
    let mask = cond.mask_latent.clone().repeat_dim(0, batch);
    let mil = cond.masked_image_latents.repeat_dim(0, batch);
    for (i, &t) in timesteps.iter().enumerate() {
        let input = Tensor::cat(
            vec![
                latents.clone().repeat_dim(0, batch),
                mask.clone(),
                mil.clone(),
            ],
            1,
        );
        let eps = prior.unet.forward(input, &[t as f32], context.clone());
        let eps = if cfg {
            let uncond = eps.clone().narrow(0, 0, 1);
            let text = eps.narrow(0, 1, 1);
            uncond.clone() + (text - uncond).mul_scalar(req.guidance)
        } else {
            eps
        };
        latents = scheduler.step(eps, t, latents)?;
        if let Some((z0, noise)) = &known {
            let target = match timesteps.get(i + 1) {
                Some(&next) => scheduler.add_noise(z0.clone(), noise.clone(), &[next])?,
                None => z0.clone(),
            };
            let hole = cond.mask_latent.clone();
            latents = latents * hole.clone() + target * hole.neg().add_scalar(1.0);
        }
        on_step(i, t);
    }
    let image = prior
        .vae
        .decode(latents.div_scalar(prior.vae.scaling_factor));
    Ok(image.mul_scalar(0.5).add_scalar(0.5).clamp(0.0, 1.0))
}
