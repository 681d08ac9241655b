//! The guided trainer: gb-nerf's reconstruction step plus the diffusion guidance, one
//! backward pass per step.
//!
//! Each step:
//! 1. the reconstruction loss of gb-nerf's [`Trainer`] on a batch of unmasked rays drawn from
//!    all training views (RGB MSE, plus `depth_weight` times the disparity loss where depth
//!    exists). The batch, its random stream and the update are those of
//!    `gb_nerf::train::Trainer::train_step`, so with no guidance the two trainers produce the
//!    same field bit for bit (a test checks it). (Decision: issue 8 speaks of "one training
//!    view" per step; the ray batch still spans every view, as in the reference's batched
//!    loader, and only the guidance works on one view);
//! 2. on every `guide_every`-th step, one training view with a mask (drawn with a per-step
//!    seed; the reference draws `img_i` at random too) is guided: its RGB crop with
//!    `lambda_rgb` (crate docs: [`crate::crop`], [`crate::guidance`]), and, from step
//!    `normal_start` (the method's `normal_start_step` scaled to the run), its normal map with
//!    `lambda_normal`. The normal guidance's masked-image conditioning is the current
//!    rendered normal map itself (detached), re-encoded every step, as in the reference
//!    (there is no ground-truth normal map);
//! 3. `loss = recon + rgb term + normal term` (each term `lambda * s(t) * (z * g).sum()`)
//!    goes through ONE `backward()`, then Adam with gb-nerf's decaying learning rate and the
//!    occupancy-grid update.
//!
//! **Non-finite losses**: a step whose total loss is NaN or infinite is skipped (no update;
//! the step counter still advances) and logged; after `max_consecutive_nan` such steps in a
//! row, [`GuidedTrainer::fit`] stops with [`InpaintError::NonFiniteLoss`], naming the last
//! checkpoint written while the losses were finite. Checkpoints are only written after a
//! finite step.
//!
//! **Determinism and an exact resume**: the ray batches, jitter and occupancy updates use
//! gb-nerf's stream, whose exact position the checkpoint stores; the guidance view, timestep
//! and noise of a step come from seeds derived from `(seed, step, modality)`, and the
//! annealed timestep schedule from the number of earlier guided steps. Checkpoints are
//! gb-nerf's format (`gb_nerf::train::checkpoint`) with the guided trainer's own state in
//! it ([`crate::resume`]: the run's identity, its counters and the visibility maps), so a run
//! killed after a checkpoint and resumed continues bit for bit as the uninterrupted run
//! would, and the log is cut back to the checkpoint's step before the resumed run appends.
//!
//! The files: this one holds the records and the trainer's type; `state.rs` builds it and
//! attaches its references, oracle and geometry term, `views.rs` prepares each guided view's
//! inputs, `fit.rs` runs the step and the loop, `checkpoint.rs` saves and resumes its state.

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::tensor::{Device, Tensor};
use gb_core::psnr::{psnr_from_mse, LOG_MIN_MSE};
use gb_core::Devices;
use gb_diffusion::distill::prior_input::compose;
use gb_diffusion::distill::{
    DistillSettings, PriorInputMode, PromptCache, PromptEmbeddings, StepDiagnostics,
};
use gb_nerf::scene::Scene;
use gb_nerf::train::data::TrainData;
use gb_nerf::train::{NerfConfig, NerfError, Trainer};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::crop::{
    has_guidance_crop, latent_mask, masked_image_latents, render_normal_input, render_rgb_input,
    RenderContext, ViewGuidance,
};
use crate::error::InpaintError;
use crate::guidance::{distiller_for, guidance_term, Modality, TermConditioning, TermOutput};
use crate::method::{MethodConfig, Prompts};
use crate::prior::SdPrior;
use crate::reference::{CarriedSet, ReferenceState, ReferenceView};
use crate::resume::{self, GuidedState, RunTotals, SavedMap};
use crate::visibility::{gate_gradient, ObservedMap};
use gb_nerf::train::checkpoint::{self as nerf_checkpoint, CheckpointParts};

mod checkpoint;
mod fit;
mod state;
mod views;

/// The guidance of a run: the prior, the resolved prompts and their embeddings, and the
/// per-view crop constants (computed on first use).
pub struct GuidanceState {
    /// The loaded prior.
    pub prior: SdPrior,
    /// The prompts of the run.
    pub prompts: Prompts,
    rgb: Option<(DistillSettings, PromptEmbeddings)>,
    normal: Option<(DistillSettings, PromptEmbeddings)>,
    /// Indices (into the training views) of the views with a mask.
    pub views: Vec<usize>,
    cache: HashMap<usize, ViewGuidance>,
    /// Per-view observed maps of the visibility-aware guidance (recomputed as they age).
    visibility: HashMap<usize, ObservedMap>,
    /// Plain device of the prior.
    device: Device,
}

/// One guidance term of a step, as logged.
#[derive(Debug, Clone, Serialize)]
pub struct TermRecord {
    /// RGB or normal map.
    pub modality: Modality,
    /// Training-view index guided.
    pub view: usize,
    /// Guidance formula.
    pub method: &'static str,
    /// Timestep index.
    pub timestep: usize,
    /// Timestep fraction.
    pub t: f64,
    /// `w(t)`.
    pub weight: f64,
    /// `lambda * s(t)`.
    pub scale: f64,
    /// L2 norm of the latent gradient `g` (before `lambda * s(t)`).
    pub grad_norm: f64,
    /// threestudio's logged loss `0.5 * mean(g^2)`.
    pub sds_loss: f64,
    /// The value of the injected term `lambda * s(t) * (z * g).sum()`.
    pub term: f64,
    /// U-Net calls (one batched call per term).
    pub unet_calls: usize,
    /// U-Net batch size.
    pub unet_batch: usize,
    /// Non-finite gradient values zeroed.
    pub non_finite_zeroed: usize,
    /// Rays rendered for this term.
    pub rays: usize,
    /// Wall time of the term (render, encoder, U-Net; without the shared backward), s.
    pub seconds: f64,
}

impl TermRecord {
    fn new(modality: Modality, view: usize, out: &TermOutput, rays: usize, seconds: f64) -> Self {
        let d: &StepDiagnostics = &out.diagnostics;
        let term = out.loss.clone().detach().into_scalar::<f32>() as f64;
        Self {
            modality,
            view,
            method: d.method,
            timestep: d.timestep,
            t: d.t,
            weight: d.weight,
            scale: out.scale,
            grad_norm: d.grad_norm,
            sds_loss: d.loss,
            term,
            unet_calls: d.unet_calls,
            unet_batch: d.unet_batch,
            non_finite_zeroed: d.non_finite_zeroed,
            rays,
            seconds,
        }
    }
}

/// One step, as logged in `train_log.jsonl`.
#[derive(Debug, Clone, Serialize)]
pub struct StepRecord {
    /// Step index (0-based: the step that ran).
    pub step: usize,
    /// Total loss (reconstruction, guidance, reference and geometry terms); `null` when not
    /// finite.
    pub loss: Option<f64>,
    /// Reconstruction part.
    pub recon_loss: Option<f64>,
    /// PSNR of the RGB loss on the ray batch, dB.
    pub psnr: f64,
    /// Learning rate.
    pub lr: f64,
    /// True when the step was skipped (non-finite loss).
    pub skipped: bool,
    /// Field evaluations per ray of the batch.
    pub evaluations_per_ray: f32,
    /// Wall time of the whole step, s.
    pub seconds: f64,
    /// The guidance terms of the step (empty on unguided steps).
    pub guidance: Vec<TermRecord>,
    /// The reference term of the step (absent in runs without a reference).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference: Option<ReferenceRecord>,
    /// The geometry term of the step (absent in runs without the term).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub geometry: Option<GeometryRecord>,
}

/// The geometry term of one step, as logged ([`crate::geometry`]).
#[derive(Debug, Clone, Serialize)]
pub struct GeometryRecord {
    /// `depth_weight` times the disparity loss plus `distortion_weight` times the distortion
    /// loss of the term's rays; `null` when not finite.
    pub loss: Option<f64>,
    /// Rays the term drew this step.
    pub rays: usize,
}

/// The reference term of one step, as logged ([`crate::reference`]).
#[derive(Debug, Clone, Serialize)]
pub struct ReferenceRecord {
    /// `weight * MSE` of the reference rays.
    pub loss: Option<f64>,
    /// Rays through the reference views' masked pixels.
    pub direct_rays: usize,
    /// Rays through pixels carried to other views.
    pub carried_rays: usize,
    /// Carried pixels available (0 before the carrying starts).
    pub carried_pixels: usize,
}

/// Summary of a [`GuidedTrainer::fit`] call: `steps_run` and `seconds` count this call
/// only; every other field covers the whole run (a resumed run includes the steps before its
/// checkpoint, restored from it), so that a resumed run reports what an uninterrupted one
/// does.
#[derive(Debug, Clone, Default, Serialize)]
pub struct FitSummary {
    /// Steps run in this call.
    pub steps_run: usize,
    /// Wall time of this call, s.
    pub seconds: f64,
    /// Steps skipped for a non-finite loss.
    pub skipped_steps: usize,
    /// Steps with at least one guidance term.
    pub guided_steps: usize,
    /// Total wall time of the guided steps, s.
    pub guided_seconds: f64,
    /// Steps without guidance.
    pub unguided_steps: usize,
    /// Total wall time of the unguided steps, s.
    pub unguided_seconds: f64,
    /// U-Net calls.
    pub unet_calls: usize,
    /// Mean field evaluations per ray of the ray batches.
    pub mean_evaluations_per_ray: f32,
}

/// Where [`GuidedTrainer::fit`] writes.
#[derive(Debug, Clone, Default)]
pub struct FitOptions {
    /// Checkpoint file (written every `checkpoint_every` steps and at the end).
    pub checkpoint: Option<PathBuf>,
    /// `train_log.jsonl` (one [`StepRecord`] per line).
    pub log: Option<PathBuf>,
    /// Append to the log instead of truncating it (resume).
    pub append_log: bool,
    /// Show a progress bar.
    pub progress: bool,
}

/// The guided reconstruction (see the module docs).
pub struct GuidedTrainer {
    /// gb-nerf's trainer: field, data, scene parameterisation, Adam, ray stream, step.
    /// `GuidedTrainer` dereferences to it.
    pub nerf: Trainer,
    /// The method.
    pub method: MethodConfig,
    /// The guidance (`None` for methods without a prior).
    pub guidance: Option<GuidanceState>,
    /// The reference views ([`Self::set_references`]; `None`: no reference).
    pub reference: Option<ReferenceState>,
    /// Carried pixels restored from a checkpoint, handed to the references when they are set.
    restored_carry: Option<CarriedSet>,
    /// Oracle guidance ([`Self::set_oracle`]; `None`: the prior answers).
    oracle: Option<crate::oracle::OracleTargets>,
    /// The geometry term's targets ([`Self::set_hidden_depth`]; `None`: no term).
    hidden_depth: Option<crate::geometry::HiddenDepth>,
    /// Counters of the whole run (restored on resume).
    pub totals: RunTotals,
    /// The run's identity ([`resume::identity`]), stored in checkpoints.
    identity: toml::Value,
    nan_streak: usize,
    last_good_checkpoint: Option<(PathBuf, usize)>,
    /// Fault injection for the tests of the non-finite-loss policy, never set by a config:
    /// from this step on the total loss is made NaN. Initialised from
    /// [`INJECT_NAN_ENV`] (for the end-to-end test of the command).
    #[doc(hidden)]
    pub inject_nan_from_step: Option<usize>,
}

/// The environment variable that sets [`GuidedTrainer::inject_nan_from_step`] (tests only).
#[doc(hidden)]
pub const INJECT_NAN_ENV: &str = "GB_TEST_INJECT_NAN_FROM_STEP";

impl std::ops::Deref for GuidedTrainer {
    type Target = Trainer;
    fn deref(&self) -> &Trainer {
        &self.nerf
    }
}

impl std::ops::DerefMut for GuidedTrainer {
    fn deref_mut(&mut self) -> &mut Trainer {
        &mut self.nerf
    }
}

/// The salt of the reference term's random stream.
const REFERENCE_SALT: u64 = 0x5EF;
/// The salt of the geometry term's random stream.
const GEOMETRY_SALT: u64 = 0x6E0;

/// A seed for `(seed, step, salt)` (SplitMix64 finaliser).
fn derive_seed(seed: u64, step: usize, salt: u64) -> u64 {
    let mut z = seed
        .wrapping_add((step as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15))
        .wrapping_add(salt.wrapping_mul(0xD1B5_4A32_D192_ED03));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Multiples of `k` in `[from, to)`.
fn multiples_in(from: usize, to: usize, k: usize) -> usize {
    if to <= from {
        0
    } else {
        to.div_ceil(k) - from.div_ceil(k)
    }
}

impl GuidanceState {
    /// Builds the guidance of `method` with `prior` and `prompts` for the views of `data`;
    /// errors when no training view has a mask.
    pub fn new(
        method: &MethodConfig,
        prior: SdPrior,
        prompts: Prompts,
        data: &TrainData,
        scene: &str,
        device: Device,
    ) -> Result<Self, InpaintError> {
        let views: Vec<usize> = data
            .views
            .iter()
            .enumerate()
            .filter(|(_, v)| has_guidance_crop(v))
            .map(|(i, _)| i)
            .collect();
        if views.is_empty() {
            return Err(InpaintError::NoMasks {
                scene: scene.to_string(),
            });
        }
        let mut cache = PromptCache::new();
        let mut embed = |settings: Option<DistillSettings>, prompt: &str, negative: &str| {
            settings
                .map(|s| -> Result<_, InpaintError> {
                    let guidance = s.guidance.build()?;
                    let e = cache.for_guidance(&prior.text, guidance.as_ref(), prompt, negative)?;
                    Ok((s, e))
                })
                .transpose()
        };
        let rgb = embed(method.rgb.clone(), &prompts.appearance, &prompts.negative)?;
        let normal = embed(
            method.normal.clone(),
            &prompts.geometry,
            &prompts.geometry_negative,
        )?;
        Ok(Self {
            prior,
            prompts,
            rgb,
            normal,
            views,
            cache: HashMap::new(),
            visibility: HashMap::new(),
            device,
        })
    }

    /// The prior's resolution.
    pub fn resolution(&self) -> usize {
        self.prior.resolution
    }
}
