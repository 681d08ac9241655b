//! Validation of an inpainting prior on held-out pairs: inpaint a fixed hole in each
//! held-out RGB image and normal map with the DDIM sampler of [`gb_diffusion::inpaint`]
//! (guidance 1: the conditional prediction alone, as the prior is used in distillation's
//! conditional branch), then score the hole: masked PSNR for RGB, masked mean angular
//! error for normals. The same holes are filled by two simple baselines (mean colour of
//! the known pixels, nearest known pixel) so that a prior's benefit is measured, not assumed.
//!
//! A diffusion sample is a draw from the prior's posterior, and PSNR punishes that spread:
//! even a perfect sampler scores about 3 dB below the posterior mean, the estimate PSNR
//! rewards. With `average = K > 1` each hole is also filled with the mean of K samples
//! (different noise; normal maps are averaged as vectors and renormalised), reported as
//! `prior_averaged` next to the single sample `prior`.

use burn::module::Module;
use burn::tensor::Device;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use gb_diffusion::inpaint::{inpaint, InpaintRequest};
use gb_diffusion::pipeline::SdComponents;

use super::models::{PriorModels, Trainable};
use crate::captions::{prompts_for, CaptionMode, Modality};
use crate::crop::center_square_resize;
use crate::masks::{MaskConfig, MaskGenerator};
use crate::normal_map::masked_angular_error_deg;
use crate::sample::PairSource;
use crate::FinetuneError;

/// Scores of one way of filling the holes (a prior, or a baseline).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FillScores {
    /// Mean masked PSNR (dB) over the held-out RGB images.
    pub rgb_masked_psnr: Option<f64>,
    /// Mean angular error (degrees) inside the hole over the held-out normal maps.
    pub normal_angular_error_deg: Option<f64>,
}

/// A validation pass.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ValidationReport {
    /// Samples used.
    pub samples: usize,
    /// The prior being validated.
    pub prior: FillScores,
    /// Mean-colour fill.
    pub fill_mean: FillScores,
    /// Nearest-known-pixel fill.
    pub fill_nearest: FillScores,
    /// Samples averaged per hole for `prior_averaged` (1: none).
    #[serde(default)]
    pub averaged_samples: usize,
    /// The prior's fill as the mean of `averaged_samples` samples (a posterior-mean estimate).
    #[serde(default)]
    pub prior_averaged: Option<FillScores>,
}

/// Settings of a validation pass.
#[derive(Debug, Clone, PartialEq)]
pub struct ValidationSettings {
    /// Square side the samples are resized to (the prior's resolution).
    pub resolution: usize,
    /// Held-out samples to use (the first `n` of the source).
    pub samples: usize,
    /// DDIM steps.
    pub ddim_steps: usize,
    /// Prompt mode.
    pub mode: CaptionMode,
    /// Whether normals are validated (they are skipped for an RGB-only base).
    pub normals: bool,
    /// Seed of the holes and the sampler noise.
    pub seed: u64,
    /// Hole sizes.
    pub mask: MaskConfig,
    /// Samples averaged per hole for the posterior-mean estimate (1: single sample only).
    pub average: usize,
    /// Sample with the known region blended in after each step
    /// ([`gb_diffusion::inpaint::InpaintRequest::blend_known`]).
    pub blend_known: bool,
}

/// PSNR (dB) of `a` against `b` (`[h, w, 3]` in `[0, 1]`) over the pixels where `hole >= 0.5`.
pub fn masked_psnr(a: &[f32], b: &[f32], hole: &[f32]) -> Option<f64> {
    let (mut se, mut n) = (0.0f64, 0usize);
    for (p, &m) in hole.iter().enumerate() {
        if m >= 0.5 {
            for c in 0..3 {
                let d = (a[p * 3 + c] - b[p * 3 + c]) as f64;
                se += d * d;
                n += 1;
            }
        }
    }
    if n == 0 {
        return None;
    }
    let mse = se / n as f64;
    Some(if mse == 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    })
}

/// Fills the hole with the mean colour of the known pixels.
pub fn fill_mean(img: &[f32], hole: &[f32]) -> Vec<f32> {
    let mut mean = [0.0f64; 3];
    let mut n = 0usize;
    for (p, &m) in hole.iter().enumerate() {
        if m < 0.5 {
            for c in 0..3 {
                mean[c] += img[p * 3 + c] as f64;
            }
            n += 1;
        }
    }
    let mean = mean.map(|s| (s / n.max(1) as f64) as f32);
    let mut out = img.to_vec();
    for (p, &m) in hole.iter().enumerate() {
        if m >= 0.5 {
            out[p * 3..p * 3 + 3].copy_from_slice(&mean);
        }
    }
    out
}

/// Fills each hole pixel with the closest known pixel (breadth-first over 4-neighbours,
/// ties broken by scan order), the simplest propagation fill.
pub fn fill_nearest(img: &[f32], hole: &[f32], w: usize, h: usize) -> Vec<f32> {
    let mut out = img.to_vec();
    let mut src: Vec<Option<usize>> = hole
        .iter()
        .enumerate()
        .map(|(p, &m)| (m < 0.5).then_some(p))
        .collect();
    let mut frontier: std::collections::VecDeque<usize> =
        (0..w * h).filter(|&p| src[p].is_some()).collect();
    while let Some(p) = frontier.pop_front() {
        let (x, y) = (p % w, p / w);
        let mut nb = Vec::with_capacity(4);
        if x > 0 {
            nb.push(p - 1);
        }
        if x + 1 < w {
            nb.push(p + 1);
        }
        if y > 0 {
            nb.push(p - w);
        }
        if y + 1 < h {
            nb.push(p + w);
        }
        for q in nb {
            if src[q].is_none() {
                src[q] = src[p];
                frontier.push_back(q);
            }
        }
    }
    for p in 0..w * h {
        if let Some(s) = src[p] {
            if s != p {
                let v: [f32; 3] = [img[s * 3], img[s * 3 + 1], img[s * 3 + 2]];
                out[p * 3..p * 3 + 3].copy_from_slice(&v);
            }
        }
    }
    out
}

/// The sampler's [`SdComponents`] of `models` with `trainable` (adapters included) on the
/// plain `device`.
pub fn sampling_prior(
    models: &PriorModels,
    trainable: &Trainable,
    device: &Device,
) -> SdComponents {
    let t = trainable.valid();
    SdComponents {
        root: models.source.clone(),
        tokenizer: models.tokenizer.clone(),
        text_encoder: t.text_encoder,
        unet: t.unet,
        unet_config: models.unet_config.clone(),
        vae: models.vae.valid(),
        vae_config: models.vae_config.clone(),
        scheduler: models.scheduler.clone(),
        device: device.clone(),
    }
}

#[derive(Default)]
struct Acc {
    psnr: Vec<f64>,
    ang: Vec<f64>,
}

impl Acc {
    fn scores(&self) -> FillScores {
        let mean = |v: &[f64]| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
        FillScores {
            rgb_masked_psnr: mean(&self.psnr),
            normal_angular_error_deg: mean(&self.ang),
        }
    }
    fn add(
        &mut self,
        modality: Modality,
        out: &[f32],
        truth: &[f32],
        hole: &[f32],
        r: usize,
        valid: &[f32],
    ) {
        match modality {
            Modality::Rgb => {
                if let Some(p) = masked_psnr(out, truth, hole) {
                    // an exact fill (inf) is capped so that one sample cannot dominate
                    self.psnr.push(p.min(100.0));
                }
            }
            Modality::Normal => {
                let weight: Vec<f32> = hole
                    .iter()
                    .zip(valid)
                    .map(|(h, v)| if *h >= 0.5 { *v } else { 0.0 })
                    .collect();
                if let Some(a) = masked_angular_error_deg(out, truth, &weight, r, r) {
                    self.ang.push(a);
                }
            }
        }
    }
}

/// Validates `prior` (a sampling view, see [`sampling_prior`]) on the first
/// `settings.samples` items of `source`, with the fill baselines on the same holes.
pub fn validate(
    prior: &SdComponents,
    source: &dyn PairSource,
    settings: &ValidationSettings,
) -> Result<ValidationReport, FinetuneError> {
    let r = settings.resolution;
    let gen = MaskGenerator::new(settings.mask.clone())?;
    let (mut ours, mut mean, mut near) = (Acc::default(), Acc::default(), Acc::default());
    let mut averaged = Acc::default();
    let n = settings.samples.min(source.len());
    for i in 0..n {
        let s = center_square_resize(&source.load(i)?, r);
        let mut rng = ChaCha8Rng::seed_from_u64(settings.seed.wrapping_add(i as u64));
        let hole = gen.sample(&mut rng, r, r);
        for (modality, prompt) in prompts_for(settings.mode, &s.caption) {
            let truth = match modality {
                Modality::Rgb => s.rgb.clone(),
                Modality::Normal if settings.normals => match &s.normal {
                    Some(n) => n.clone(),
                    None => continue,
                },
                Modality::Normal => continue,
            };
            let k = settings.average.max(1);
            let mut sum = vec![0.0f32; 3 * r * r];
            let mut first = Vec::new();
            for j in 0..k {
                let req = InpaintRequest {
                    width: r,
                    height: r,
                    rgb: truth.clone(),
                    mask: hole.clone(),
                    prompt: prompt.clone(),
                    negative_prompt: String::new(),
                    steps: settings.ddim_steps,
                    guidance: 1.0,
                    seed: settings
                        .seed
                        .wrapping_add(1000 + i as u64)
                        .wrapping_add(1_000_003 * j as u64),
                    init_latents: None,
                    blend_known: settings.blend_known,
                };
                let img = inpaint(prior, &req, |_, _| {})
                    .map_err(|e| FinetuneError::diffusion("validation inpainting", e))?;
                let chw: Vec<f32> = img
                    .into_data()
                    .try_to_vec::<f32>()
                    .map_err(|e| FinetuneError::diffusion("validation output", format!("{e:?}")))?;
                // [1,3,r,r] -> hwc; normal maps are summed as unit vectors
                let hwc = chw_to_hwc(&chw, r);
                let add = match modality {
                    Modality::Rgb => hwc.clone(),
                    Modality::Normal => unit_vectors(&hwc),
                };
                for (a, b) in sum.iter_mut().zip(&add) {
                    *a += b;
                }
                if j == 0 {
                    first = hwc;
                }
            }
            let out = compose(&truth, &first, &hole);
            if k > 1 {
                let mean: Vec<f32> = match modality {
                    Modality::Rgb => sum.iter().map(|v| v / k as f32).collect(),
                    Modality::Normal => encode_mean_normals(&sum),
                };
                averaged.add(
                    modality,
                    &compose(&truth, &mean, &hole),
                    &truth,
                    &hole,
                    r,
                    &s.normal_valid,
                );
            }
            ours.add(modality, &out, &truth, &hole, r, &s.normal_valid);
            mean.add(
                modality,
                &fill_mean(&truth, &hole),
                &truth,
                &hole,
                r,
                &s.normal_valid,
            );
            near.add(
                modality,
                &fill_nearest(&truth, &hole, r, r),
                &truth,
                &hole,
                r,
                &s.normal_valid,
            );
        }
    }
    Ok(ValidationReport {
        samples: n,
        prior: ours.scores(),
        fill_mean: mean.scores(),
        fill_nearest: near.scores(),
        averaged_samples: settings.average.max(1),
        prior_averaged: (settings.average > 1).then(|| averaged.scores()),
    })
}

/// `[3, r, r]` planes to `[r, r, 3]` pixels.
fn chw_to_hwc(chw: &[f32], r: usize) -> Vec<f32> {
    let mut out = vec![0.0; 3 * r * r];
    for p in 0..r * r {
        for c in 0..3 {
            out[p * 3 + c] = chw[c * r * r + p];
        }
    }
    out
}

/// Known pixels of `truth`, hole pixels of `fill`.
fn compose(truth: &[f32], fill: &[f32], hole: &[f32]) -> Vec<f32> {
    let mut out = truth.to_vec();
    for (p, &m) in hole.iter().enumerate() {
        if m >= 0.5 {
            out[p * 3..p * 3 + 3].copy_from_slice(&fill[p * 3..p * 3 + 3]);
        }
    }
    out
}

/// Unit normals `2x - 1` (normalised; zero where degenerate) of a normal-map image.
fn unit_vectors(img: &[f32]) -> Vec<f32> {
    let mut out = vec![0.0; img.len()];
    for (o, px) in out.chunks_mut(3).zip(img.chunks(3)) {
        let v = [px[0] * 2.0 - 1.0, px[1] * 2.0 - 1.0, px[2] * 2.0 - 1.0];
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if n > 1e-6 {
            for c in 0..3 {
                o[c] = v[c] / n;
            }
        }
    }
    out
}

/// The normal-map image `(n + 1) / 2` of the normalised sum of unit normals.
fn encode_mean_normals(sum: &[f32]) -> Vec<f32> {
    let mut out = vec![0.5; sum.len()];
    for (o, v) in out.chunks_mut(3).zip(sum.chunks(3)) {
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if n > 1e-6 {
            for c in 0..3 {
                o[c] = (v[c] / n + 1.0) * 0.5;
            }
        }
    }
    out
}
