//! One score-distillation step at latent resolution: noise the latents, one batched U-Net
//! call, combine with the guidance, weight, mask, clean, clamp, and build the surrogate loss.

use burn::tensor::Tensor;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::alphas::AlphasCumprod;
use super::diagnostics::StepDiagnostics;
use super::eps::{EpsBatch, InpaintEpsPredictor};
use super::error::DistillError;
use super::gradient::{postprocess, surrogate_loss};
use super::guidance::{Branch, Guidance};
use super::guidance_method::GuidanceMethod;
use super::noise::normal_tensor;
use super::timestep::{fraction_to_index, weight, TimestepConfig, Weighting};

/// The text embeddings of one prompt set, each `[1, L, D]` (or `[B, L, D]`).
#[derive(Debug, Clone)]
pub struct PromptEmbeddings {
    /// Embedding of the prompt `y`.
    pub text: Tensor<3>,
    /// Embedding of the empty prompt (needed by SDS and CSD).
    pub unconditional: Option<Tensor<3>>,
    /// Embedding of the negative prompt (needed by CSD and BSD).
    pub negative: Option<Tensor<3>>,
}

impl PromptEmbeddings {
    /// The embedding of one branch, if supplied.
    pub fn get(&self, branch: Branch) -> Option<&Tensor<3>> {
        match branch {
            Branch::Text => Some(&self.text),
            Branch::Unconditional => self.unconditional.as_ref(),
            Branch::Negative => self.negative.as_ref(),
        }
    }
}

/// What a step distils: latents with their graph to the image, and the conditioning.
#[derive(Debug, Clone)]
pub struct LatentTarget<'a> {
    /// Encoder output `[B, C, h, w]`, carrying the autodiff graph back to the image.
    pub latents: Tensor<4>,
    /// Inpainting mask at latent resolution, `[B, 1, h, w]`; also multiplies the gradient.
    pub mask_latent: Tensor<4>,
    /// Latents of the masked image, `[B, C, h, w]` (cached per view).
    pub masked_image_latents: Tensor<4>,
    /// Text embeddings (cached per prompt).
    pub prompts: &'a PromptEmbeddings,
}

/// The result of one step.
#[derive(Debug)]
pub struct DistillOutput {
    /// `(latents * g.detach()).sum()`; call `backward()` on it.
    pub loss: Tensor<1>,
    /// The final latent gradient `g`, `[B, C, h, w]`, without a graph.
    pub gradient: Tensor<4>,
    /// Timestep, weight, call count, norms.
    pub diagnostics: StepDiagnostics,
}

/// Settings of a [`ScoreDistiller`]: a method config's `[rgb]` / `[normal]` table, whose
/// serde form is the flat table of [`super::settings_table`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(
    try_from = "super::settings_table::SettingsTable",
    into = "super::settings_table::SettingsTable"
)]
pub struct DistillSettings {
    /// Guidance method and weights.
    pub guidance: GuidanceMethod,
    /// Timestep range and schedule.
    pub timesteps: TimestepConfig,
    /// `w(t)`.
    pub weighting: Weighting,
    /// Optional symmetric clamp of the latent gradient (after masking).
    pub grad_clamp: Option<f32>,
}

impl DistillSettings {
    /// The paper's RGB setting: BSD (7.5, 6.5), t in [0.02, 0.98], w(t) = 1 - alpha_bar.
    pub fn paper_rgb() -> Self {
        Self {
            guidance: GuidanceMethod::paper_rgb(),
            timesteps: TimestepConfig::default(),
            weighting: Weighting::OneMinusAlphaBar,
            grad_clamp: None,
        }
    }

    /// Checks the timesteps, the weights (finite) and the clamp (finite, > 0).
    pub fn validate(&self) -> Result<(), DistillError> {
        self.timesteps.validate()?;
        self.guidance.build()?;
        match self.grad_clamp {
            Some(value) if !value.is_finite() => Err(DistillError::NonFiniteWeight {
                name: "grad_clamp",
                value,
            }),
            Some(c) if c <= 0.0 => Err(DistillError::BadClamp(c)),
            _ => Ok(()),
        }
    }

    /// The paper's normal-map setting: BSD (1.5, 0.5).
    pub fn paper_normals() -> Self {
        Self {
            guidance: GuidanceMethod::paper_normals(),
            ..Self::paper_rgb()
        }
    }
}

/// Runs score-distillation steps with one guidance, seeded and reproducible.
pub struct ScoreDistiller {
    guidance: Box<dyn Guidance>,
    timesteps: TimestepConfig,
    weighting: Weighting,
    grad_clamp: Option<f32>,
    alphas: AlphasCumprod,
    rng: ChaCha8Rng,
    iteration: usize,
}

impl ScoreDistiller {
    /// Validates `settings` and builds a distiller whose timesteps and noise come from `seed`.
    pub fn new(
        settings: &DistillSettings,
        alphas: AlphasCumprod,
        seed: u64,
    ) -> Result<Self, DistillError> {
        settings.validate()?;
        Ok(Self {
            guidance: settings.guidance.build()?,
            timesteps: settings.timesteps,
            weighting: settings.weighting,
            grad_clamp: settings.grad_clamp,
            alphas,
            rng: ChaCha8Rng::seed_from_u64(seed),
            iteration: 0,
        })
    }

    /// The guidance in use.
    pub fn guidance(&self) -> &dyn Guidance {
        self.guidance.as_ref()
    }

    /// The step counter (number of sampled steps so far).
    pub fn iteration(&self) -> usize {
        self.iteration
    }

    /// Sets the step counter (to resume the annealed schedule).
    pub fn set_iteration(&mut self, iteration: usize) {
        self.iteration = iteration;
    }

    /// One step with a sampled timestep and seeded noise; advances the step counter.
    pub fn step(
        &mut self,
        unet: &dyn InpaintEpsPredictor,
        target: LatentTarget<'_>,
    ) -> Result<DistillOutput, DistillError> {
        let timestep = self
            .timesteps
            .sample(self.iteration, self.alphas.len(), &mut self.rng);
        self.step_at_index(unet, target, timestep)
    }

    /// One step at an explicit timestep fraction `t` in (0, 1) (rejects 0 and 1) with seeded
    /// noise; advances the step counter.
    pub fn step_at(
        &mut self,
        unet: &dyn InpaintEpsPredictor,
        target: LatentTarget<'_>,
        t: f64,
    ) -> Result<DistillOutput, DistillError> {
        let timestep = fraction_to_index(t, self.alphas.len())?;
        self.step_at_index(unet, target, timestep)
    }

    fn step_at_index(
        &mut self,
        unet: &dyn InpaintEpsPredictor,
        target: LatentTarget<'_>,
        timestep: usize,
    ) -> Result<DistillOutput, DistillError> {
        let device = target.latents.clone().inner().device();
        let noise = normal_tensor(&mut self.rng, target.latents.dims(), &device);
        let out = self.step_with(unet, target, timestep, noise);
        self.iteration += 1;
        out
    }

    /// One step with the given timestep index and noise (deterministic; for tests).
    pub fn step_with(
        &self,
        unet: &dyn InpaintEpsPredictor,
        target: LatentTarget<'_>,
        timestep: usize,
        noise: Tensor<4>,
    ) -> Result<DistillOutput, DistillError> {
        let [b, c, h, w] = target.latents.dims();
        check_shape("noise", &noise.dims(), &[b, c, h, w])?;
        check_shape("mask_latent", &target.mask_latent.dims(), &[b, 1, h, w])?;
        check_shape(
            "masked_image_latents",
            &target.masked_image_latents.dims(),
            &[b, c, h, w],
        )?;
        if timestep == 0 || timestep >= self.alphas.len() {
            return Err(DistillError::TimestepOutOfRange {
                field: "timestep index / num_train_timesteps",
                value: timestep as f64 / self.alphas.len() as f64,
            });
        }

        let alpha_bar = self.alphas.at(timestep);
        let w_t = weight(self.weighting, alpha_bar);
        let z = target.latents.clone().inner();
        let mask = target.mask_latent.clone().inner();
        let masked_latents = target.masked_image_latents.clone().inner();
        let noisy =
            z.mul_scalar(alpha_bar.sqrt()) + noise.clone().mul_scalar((1.0 - alpha_bar).sqrt());

        let branches = self.guidance.branches();
        let mut texts = Vec::with_capacity(branches.len());
        for &branch in branches {
            let emb = target
                .prompts
                .get(branch)
                .ok_or(DistillError::MissingEmbedding {
                    method: self.guidance.name(),
                    branch,
                })?
                .clone()
                .inner();
            texts.push(expand_batch(emb, b)?);
        }
        let rows = branches.len();
        let batch = EpsBatch {
            noisy_latents: Tensor::cat(vec![noisy; rows], 0),
            timestep,
            text_embeddings: Tensor::cat(texts, 0),
            mask: Tensor::cat(vec![mask.clone(); rows], 0),
            masked_image_latents: Tensor::cat(vec![masked_latents; rows], 0),
        };
        let unet_batch = batch.batch_size();
        let eps = unet.predict_eps(batch)?;
        check_shape("predicted eps", &eps.dims(), &[rows * b, c, h, w])?;
        let per_branch: Vec<Tensor<4>> =
            (0..rows).map(|i| eps.clone().narrow(0, i * b, b)).collect();

        let direction = self.guidance.direction(&per_branch, &noise);
        let weighted = direction.mul_scalar(w_t);
        let non_finite: i64 = weighted
            .clone()
            .mul(mask.clone().repeat_dim(1, c))
            .is_finite()
            .bool_not()
            .int()
            .sum()
            .into_scalar::<i64>();
        let g = postprocess(weighted, &mask, self.grad_clamp);
        let sum_sq = g.clone().powi_scalar(2).sum().into_scalar::<f32>() as f64;
        let loss = surrogate_loss(&target.latents, &g);
        let numel = (b * c * h * w) as f64;
        let diagnostics = StepDiagnostics {
            method: self.guidance.name(),
            iteration: self.iteration,
            timestep,
            t: timestep as f64 / self.alphas.len() as f64,
            alpha_bar,
            weight: w_t,
            unet_calls: 1,
            unet_batch,
            grad_norm: sum_sq.sqrt(),
            loss: 0.5 * sum_sq / numel,
            non_finite_zeroed: non_finite as usize,
        };
        tracing::debug!(?diagnostics, "distill step");
        Ok(DistillOutput {
            loss,
            gradient: g,
            diagnostics,
        })
    }
}

/// Repeats a `[1, L, D]` embedding to `[b, L, D]`; a `[b, L, D]` one passes unchanged.
fn expand_batch(emb: Tensor<3>, b: usize) -> Result<Tensor<3>, DistillError> {
    match emb.dims()[0] {
        n if n == b => Ok(emb),
        1 => Ok(emb.repeat_dim(0, b)),
        _ => Err(DistillError::Shape {
            tensor: "text embedding",
            actual: emb.dims().to_vec(),
            expected: format!("[1 or {b}, L, D]"),
        }),
    }
}

fn check_shape(
    tensor: &'static str,
    actual: &[usize],
    expected: &[usize],
) -> Result<(), DistillError> {
    if actual == expected {
        Ok(())
    } else {
        Err(DistillError::Shape {
            tensor,
            actual: actual.to_vec(),
            expected: format!("{expected:?}"),
        })
    }
}
