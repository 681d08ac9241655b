//! Deterministic training batches: each item is a random sample, a random square crop at
//! the training resolution, a random hole and one modality with its prompt.
//!
//! The random stream of micro-batch `m` of step `s` is `ChaCha8(seed, s, m)`, independent
//! of everything before it, so a resumed run draws exactly what an uninterrupted one draws.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::captions::{prompts_for, Modality};
use crate::crop::random_square_crop;
use crate::masks::{MaskConfig, MaskGenerator};
use crate::sample::PairSource;
use crate::train::FinetuneConfig;
use crate::FinetuneError;

/// One micro-batch on the host, channel-first.
#[derive(Debug, Clone, PartialEq)]
pub struct HostBatch {
    /// Items in the batch.
    pub size: usize,
    /// Side of the square images.
    pub resolution: usize,
    /// Images in `[0, 1]`, `[b, 3, r, r]`.
    pub images: Vec<f32>,
    /// Holes (1 = inpaint), `[b, 1, r, r]`.
    pub masks: Vec<f32>,
    /// One prompt per item.
    pub prompts: Vec<String>,
    /// The modality of each item.
    pub modalities: Vec<Modality>,
    /// Standard-normal noise `[b, 4 * (r/f)^2]` for the latents, item-major.
    pub noise: Vec<f32>,
    /// One training timestep per item, uniform over the schedule.
    pub timesteps: Vec<usize>,
}

/// The random stream of micro-batch `micro` of step `step`.
pub fn stream(seed: u64, step: usize, micro: usize) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(((step as u64) << 16) | micro as u64);
    rng
}

/// Draws `n` standard normals (Box-Muller on the given stream).
pub fn normals(rng: &mut impl Rng, n: usize) -> Vec<f32> {
    let mut out = Vec::with_capacity(n + 1);
    while out.len() < n {
        let u1: f64 = rng.random::<f64>().max(1e-12);
        let u2: f64 = rng.random::<f64>();
        let r = (-2.0 * u1.ln()).sqrt();
        let a = std::f64::consts::TAU * u2;
        out.push((r * a.cos()) as f32);
        out.push((r * a.sin()) as f32);
    }
    out.truncate(n);
    out
}

/// Builds micro-batch `micro` of step `step` from `source`.
///
/// `latent_channels` and `latent_size` are the VAE's latent channels and the side of the
/// latent (`resolution / vae_factor`), and `timesteps` the length of the training schedule.
pub fn make_batch(
    source: &dyn PairSource,
    cfg: &FinetuneConfig,
    step: usize,
    micro: usize,
    latent_channels: usize,
    latent_size: usize,
    timesteps: usize,
) -> Result<HostBatch, FinetuneError> {
    if source.is_empty() {
        return Err(FinetuneError::Config {
            field: "dataset".into(),
            message: "the training set has no samples".into(),
        });
    }
    let mut rng = stream(cfg.seed, step, micro);
    let r = cfg.resolution;
    let masks_gen = MaskGenerator::new(MaskConfig {
        min_coverage: cfg.mask_min_coverage,
        max_coverage: cfg.mask_max_coverage,
        ..MaskConfig::default()
    })?;
    let mut batch = HostBatch {
        size: cfg.batch,
        resolution: r,
        images: Vec::with_capacity(cfg.batch * 3 * r * r),
        masks: Vec::with_capacity(cfg.batch * r * r),
        prompts: Vec::with_capacity(cfg.batch),
        modalities: Vec::with_capacity(cfg.batch),
        noise: Vec::new(),
        timesteps: Vec::with_capacity(cfg.batch),
    };
    for _ in 0..cfg.batch {
        let index = rng.random_range(0..source.len());
        let sample = source.load(index)?;
        let crop = random_square_crop(&sample, r, &mut rng);
        let choices: Vec<(Modality, String)> = if cfg.rgb_only {
            vec![(Modality::Rgb, sample.caption.clone())]
        } else {
            prompts_for(cfg.mode, &sample.caption)
                .into_iter()
                .filter(|(m, _)| *m == Modality::Rgb || crop.normal.is_some())
                .collect()
        };
        if choices.is_empty() {
            return Err(FinetuneError::Invalid {
                path: sample.name.clone().into(),
                message: format!(
                    "sample has no normal map, and mode {:?} trains on normal maps only",
                    cfg.mode
                ),
            });
        }
        let (modality, prompt) = choices[rng.random_range(0..choices.len())].clone();
        let pixels = match modality {
            Modality::Rgb => &crop.rgb,
            Modality::Normal => crop.normal.as_ref().unwrap_or(&crop.rgb),
        };
        for c in 0..3 {
            batch.images.extend((0..r * r).map(|i| pixels[i * 3 + c]));
        }
        batch.masks.extend(masks_gen.sample(&mut rng, r, r));
        batch.prompts.push(prompt);
        batch.modalities.push(modality);
        batch.timesteps.push(rng.random_range(0..timesteps));
    }
    batch.noise = normals(
        &mut rng,
        cfg.batch * latent_channels * latent_size * latent_size,
    );
    Ok(batch)
}
