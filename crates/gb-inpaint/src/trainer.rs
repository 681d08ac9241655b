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

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::tensor::Tensor;
use gb_core::BackendKind;
use gb_diffusion::distill::prior_input::compose;
use gb_diffusion::distill::{
    DistillSettings, PriorInputMode, PromptCache, PromptEmbeddings, StepDiagnostics,
};
use gb_nerf::scene::Scene;
use gb_nerf::train::data::TrainData;
use gb_nerf::train::losses::psnr_from_mse;
use gb_nerf::train::{NerfConfig, NerfError, Trainer};
use indicatif::{ProgressBar, ProgressStyle};
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
use crate::prior::GuidancePrior;
use crate::reference::{CarriedSet, ReferenceState, ReferenceView};
use crate::resume::{self, GuidedState, RunTotals, SavedMap};
use crate::visibility::{gate_gradient, ObservedMap};
use gb_nerf::train::checkpoint::{self, CheckpointParts};

/// The guidance of a run: the prior, the resolved prompts and their embeddings, and the
/// per-view crop constants (computed on first use).
pub struct GuidanceState {
    /// The loaded prior.
    pub prior: GuidancePrior,
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
    device: burn::tensor::Device,
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
    /// Total loss (reconstruction + guidance terms); `null` when not finite.
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
        prior: GuidancePrior,
        prompts: Prompts,
        data: &TrainData,
        scene: &str,
        backend: BackendKind,
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
                    let e = cache.for_guidance(
                        prior.text.as_ref(),
                        guidance.as_ref(),
                        prompt,
                        negative,
                    )?;
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
            device: backend.device(),
        })
    }

    /// The prior's resolution.
    pub fn resolution(&self) -> usize {
        self.prior.resolution
    }
}

impl GuidedTrainer {
    /// A fresh trainer. `guidance` must be given exactly when the method needs a prior.
    pub fn new(
        scene: &Scene,
        config: NerfConfig,
        method: MethodConfig,
        guidance: Option<(GuidancePrior, Prompts)>,
        backend: BackendKind,
    ) -> Result<Self, InpaintError> {
        Self::from_base(
            Trainer::new(scene, config, backend)?,
            scene,
            method,
            guidance,
        )
    }

    /// [`Self::new`], with the pixels under `withheld` (one mask per training view, at the
    /// training resolution) kept from every loss (gb-nerf's `Trainer::withhold`): the
    /// pseudo-holes of [`crate::auto`].
    pub fn new_withholding(
        scene: &Scene,
        config: NerfConfig,
        method: MethodConfig,
        guidance: Option<(GuidancePrior, Prompts)>,
        backend: BackendKind,
        withheld: &[Option<gb_nerf::scene::Mask>],
    ) -> Result<Self, InpaintError> {
        let nerf = Self::withholding_base(scene, config, backend, withheld, None)?;
        Self::from_base(nerf, scene, method, guidance)
    }

    /// The reconstruction trainer of `scene` with the pixels `withheld` from every loss,
    /// restored from the checkpoint at `prefix` when given: one written by a trainer of the
    /// same scene, preset and withheld pixels (the auto-weight trials' shared unguided
    /// prefix, [`crate::auto`]), whose field, optimiser, occupancy grid, step and random
    /// stream it continues; `config`'s step count is where it stops.
    pub(crate) fn withholding_base(
        scene: &Scene,
        config: NerfConfig,
        backend: BackendKind,
        withheld: &[Option<gb_nerf::scene::Mask>],
        prefix: Option<&Path>,
    ) -> Result<Trainer, InpaintError> {
        let mut nerf = Trainer::new(scene, config, backend)?;
        nerf.withhold(withheld)?;
        Ok(match prefix {
            Some(path) => Trainer::restore(nerf, path, checkpoint::load(path)?)?,
            None => nerf,
        })
    }

    /// The prior, handed back when the trainer is done with it.
    pub fn into_prior(self) -> Option<GuidancePrior> {
        self.guidance.map(|g| g.prior)
    }

    /// Restores a trainer from a checkpoint of the same scene (parameters, Adam state,
    /// occupancy grid, step, random stream, counters, visibility maps); the preset stored in
    /// the checkpoint is used, with `steps` overriding its step count when given. Refuses a
    /// checkpoint of another method (by name); [`Self::resume_matching`] checks everything.
    pub fn resume(
        scene: &Scene,
        path: &Path,
        method: MethodConfig,
        guidance: Option<(GuidancePrior, Prompts)>,
        backend: BackendKind,
        steps: Option<usize>,
    ) -> Result<Self, InpaintError> {
        let parts = checkpoint::load(path)?;
        let mut config = parts.meta.config(path)?;
        if let Some(s) = steps {
            config.train.steps = s;
        }
        Self::resume_parts(scene, path, parts, config, method, guidance, backend, false)
    }

    /// A trainer that only renders: the field, occupancy grid and preset of the checkpoint
    /// at `path`, written by a run of any method, under the `none` method (no prior, no
    /// guidance state), for the export of a finished run ([`crate::run::export_run`]).
    /// Rendering reads nothing else.
    pub fn for_rendering(
        scene: &Scene,
        path: &Path,
        backend: BackendKind,
    ) -> Result<Self, InpaintError> {
        let nerf = gb_nerf::train::Trainer::resume(scene, path, backend)?;
        Self::from_base(nerf, scene, MethodConfig::builtin("none")?, None)
    }

    /// The strict resume of `cargo xtask inpaint --resume` from `parts`, the checkpoint read
    /// from `path` ([`checkpoint::load`]): like [`Self::resume`], training with `config`, but
    /// a checkpoint written with another preset (any field but `train.steps` and
    /// `train.checkpoint_every`), method, prompts or prior is refused with one line naming
    /// the file and the first field that differs.
    #[allow(clippy::too_many_arguments)]
    pub fn resume_matching(
        scene: &Scene,
        path: &Path,
        parts: CheckpointParts,
        method: MethodConfig,
        guidance: Option<(GuidancePrior, Prompts)>,
        backend: BackendKind,
        config: NerfConfig,
    ) -> Result<Self, InpaintError> {
        resume::check_preset(path, &parts.meta.config(path)?, &config)?;
        Self::resume_parts(scene, path, parts, config, method, guidance, backend, true)
    }

    #[allow(clippy::too_many_arguments)]
    fn resume_parts(
        scene: &Scene,
        path: &Path,
        mut parts: CheckpointParts,
        config: NerfConfig,
        method: MethodConfig,
        guidance: Option<(GuidancePrior, Prompts)>,
        backend: BackendKind,
        strict: bool,
    ) -> Result<Self, InpaintError> {
        let bad = |reason: String| gb_nerf::train::NerfError::Checkpoint {
            path: path.to_path_buf(),
            reason,
        };
        let extra = std::mem::take(&mut parts.meta.extra);
        let state: Option<GuidedState> = if extra.is_null() {
            None
        } else {
            Some(serde_json::from_value(extra).map_err(|e| bad(format!("guided state: {e}")))?)
        };
        let identity = resume::identity(
            &method,
            guidance.as_ref().map(|(p, prompts)| (&p.info, prompts)),
        )
        .map_err(|e| bad(format!("run identity: {e}")))?;
        match &state {
            Some(st) => resume::check_identity(path, &st.identity_toml, &identity, strict)?,
            None if strict => {
                return Err(bad(
                    "written by the plain reconstruction trainer: it has no guided-run state \
                     (method, counters)"
                        .into(),
                )
                .into())
            }
            None => {}
        }
        let nerf = Trainer::resume_from(scene, path, parts, config, backend)?;
        let mut t = Self::from_base(nerf, scene, method, guidance)?;
        if let Some(st) = state {
            t.totals = st.totals;
            t.restored_carry = st.reference_carry;
            if let Some(g) = t.guidance.as_mut() {
                g.visibility = st.visibility.iter().map(SavedMap::to_map).collect();
            }
        }
        t.last_good_checkpoint = Some((path.to_path_buf(), t.nerf.step));
        Ok(t)
    }

    /// The guided trainer's state for a checkpoint ([`crate::resume`]).
    fn checkpoint_state(&self) -> Result<serde_json::Value, InpaintError> {
        let mut visibility: Vec<SavedMap> = self
            .guidance
            .as_ref()
            .map(|g| {
                g.visibility
                    .iter()
                    .map(|(v, m)| SavedMap::new(*v, m))
                    .collect()
            })
            .unwrap_or_default();
        visibility.sort_by_key(|m| m.view);
        let state_error = |reason: String| {
            InpaintError::Nerf(gb_nerf::train::NerfError::Checkpoint {
                path: PathBuf::from("(guided state)"),
                reason,
            })
        };
        // An empty identity would let any run resume this checkpoint: a failure is an error.
        let identity_toml = toml::to_string(&self.identity)
            .map_err(|e| state_error(format!("run identity: {e}")))?;
        let state = GuidedState {
            identity_toml,
            totals: self.totals.clone(),
            visibility,
            reference_carry: self.reference.as_ref().and_then(|r| r.carried.clone()),
        };
        serde_json::to_value(&state).map_err(|e| state_error(e.to_string()))
    }

    /// The guided trainer around the reconstruction trainer `nerf` (fresh or restored).
    pub(crate) fn from_base(
        nerf: Trainer,
        scene: &Scene,
        method: MethodConfig,
        guidance: Option<(GuidancePrior, Prompts)>,
    ) -> Result<Self, InpaintError> {
        if method.lambda_rgb.is_auto() || method.lambda_normal.is_auto() {
            return Err(InpaintError::MethodConfig {
                path: PathBuf::from(&method.name),
                reason: "a weight is still \"auto\": choose it first (gb_inpaint::auto)".into(),
            });
        }
        let identity = resume::identity(
            &method,
            guidance.as_ref().map(|(p, prompts)| (&p.info, prompts)),
        )
        .map_err(|e| InpaintError::MethodConfig {
            path: PathBuf::from(&method.name),
            reason: e,
        })?;
        let guidance = match (method.needs_prior(), guidance) {
            (true, Some((prior, prompts))) => Some(GuidanceState::new(
                &method,
                prior,
                prompts,
                &nerf.data,
                &scene.name,
                nerf.backend,
            )?),
            (true, None) => {
                return Err(InpaintError::PriorRequired {
                    method: method.name.clone(),
                })
            }
            (false, _) => None,
        };
        Ok(Self {
            nerf,
            method,
            guidance,
            reference: None,
            restored_carry: None,
            oracle: None,
            hidden_depth: None,
            totals: RunTotals::default(),
            identity,
            nan_streak: 0,
            last_good_checkpoint: None,
            inject_nan_from_step: std::env::var(INJECT_NAN_ENV)
                .ok()
                .and_then(|v| v.parse().ok()),
        })
    }

    /// Attaches the geometry term ([`crate::geometry`]): from now on every step holds the
    /// hidden pixels' depth to `targets`.
    pub fn set_hidden_depth(&mut self, targets: crate::geometry::HiddenDepth) {
        self.hidden_depth = Some(targets);
    }

    /// Attaches oracle guidance ([`crate::oracle`]): the RGB term's chosen branches are
    /// answered by the exact score of each guided view's object-free image.
    pub fn set_oracle(&mut self, targets: crate::oracle::OracleTargets) {
        self.oracle = Some(targets);
    }

    /// Attaches the run's reference views ([`crate::reference`], settings from the method's
    /// `[reference]` table); an empty list removes them. A resumed trainer gets back the
    /// carried pixels of its checkpoint. The guidance no longer draws the reference views
    /// (the reference fills their masks) unless every guided view has a reference.
    pub fn set_references(&mut self, views: Vec<ReferenceView>) {
        if views.is_empty() {
            self.reference = None;
            return;
        }
        let indices: Vec<usize> = views.iter().map(|r| r.view).collect();
        if let Some(g) = self.guidance.as_mut() {
            let rest: Vec<usize> = g
                .views
                .iter()
                .copied()
                .filter(|v| !indices.contains(v))
                .collect();
            if !rest.is_empty() {
                g.views = rest;
            }
        }
        self.reference = Some(ReferenceState {
            config: self.method.reference.clone(),
            views,
            carried: self.restored_carry.take(),
            carry_start: self
                .method
                .reference_start_for(self.nerf.config.train.steps),
        });
    }

    /// The reference term of `step` (refreshing the carried pixels when due), or `None`.
    fn reference_term(
        &mut self,
        step: usize,
    ) -> Result<Option<(crate::reference::ReferenceTerm, usize)>, InpaintError> {
        let Some(mut state) = self.reference.take() else {
            return Ok(None);
        };
        let seed = derive_seed(self.nerf.config.train.seed, step, REFERENCE_SALT);
        let ctx = self.render_context();
        let result = state
            .refresh(&ctx, &self.nerf.data.views, step)
            .and_then(|_| {
                state
                    .loss(&ctx, &self.nerf.data.views, seed)
                    .map_err(|e| InpaintError::from(gb_nerf::train::NerfError::from(e)))
            });
        let carried = state.carried.as_ref().map_or(0, |c| c.pixels.len());
        self.reference = Some(state);
        Ok(result?.map(|t| (t, carried)))
    }

    /// The first step of the normal guidance in this run.
    pub fn normal_start(&self) -> usize {
        self.method.normal_start_for(self.nerf.config.train.steps)
    }

    /// Consecutive non-finite losses so far.
    pub fn nan_streak(&self) -> usize {
        self.nan_streak
    }

    /// The last checkpoint written after a finite step (or resumed from), with its step.
    pub fn last_good_checkpoint(&self) -> Option<&(PathBuf, usize)> {
        self.last_good_checkpoint.as_ref()
    }

    fn render_context(&self) -> RenderContext<'_> {
        RenderContext {
            field: &self.nerf.field,
            space: &self.nerf.space,
            near: self.nerf.near,
            far: self.nerf.far,
            samples_per_ray: self.nerf.config.sampler.samples_per_ray,
            occupancy: self.nerf.occupancy.as_ref(),
            rgb_appearance_only: !self.method.rgb_moves_geometry,
            background: self.nerf.background,
            normals: self.nerf.config.render.normals,
        }
    }

    /// The cached crop constants of training view `view` (computed on first use).
    pub fn view_guidance(&mut self, view: usize) -> Result<&ViewGuidance, InpaintError> {
        let margin = self.method.crop_margin;
        let g = self
            .guidance
            .as_mut()
            .ok_or_else(|| InpaintError::PriorRequired {
                method: self.method.name.clone(),
            })?;
        if !g.cache.contains_key(&view) {
            let v = ViewGuidance::new(
                view,
                &self.nerf.data.views[view],
                margin,
                g.prior.resolution,
                g.prior.encoder.as_ref(),
                &g.device,
            )?;
            g.cache.insert(view, v);
        }
        g.cache.get(&view).ok_or(InpaintError::Distill(
            gb_diffusion::distill::DistillError::UnknownView(view),
        ))
    }

    /// The RGB prior input of training view `view` with its graph to the field, and the
    /// number of rays rendered.
    /// With visibility-aware guidance on, the gradient reaching observed pixels is scaled
    /// by the method's `visibility.observed_weight` ([`crate::visibility`]).
    pub fn rgb_prior_input(&mut self, view: usize) -> Result<(Tensor<4>, usize), InpaintError> {
        self.view_guidance(view)?;
        let mode = self.method.prior_input;
        let vg = self.cached(view)?;
        let (image, rays) = render_rgb_input(&self.render_context(), vg, mode)
            .map_err(gb_nerf::train::NerfError::from)?;
        Ok((self.gate_observed(view, image)?, rays))
    }

    /// The normal-map prior input of training view `view` with its graph to the field, and
    /// the number of rays rendered, gated like [`Self::rgb_prior_input`] (on the normal
    /// image: gating the depth under the plane fit instead measured worse on `fence`, D-PSNR
    /// 18.9 against 22.1 dB).
    pub fn normal_prior_input(&mut self, view: usize) -> Result<(Tensor<4>, usize), InpaintError> {
        self.view_guidance(view)?;
        let divisor = self.method.normal_render_divisor;
        let vg = self.cached(view)?;
        let (image, rays) = render_normal_input(&self.render_context(), vg, divisor)
            .map_err(gb_nerf::train::NerfError::from)?;
        Ok((self.gate_observed(view, image)?, rays))
    }

    /// The observed map of `view`, recomputed from the current field when it is missing or
    /// `visibility.refresh_every` steps old; `None` when visibility-aware guidance is off.
    /// Errors when the rendered depth cannot be read back.
    pub fn observed_map(&mut self, view: usize) -> Result<Option<&ObservedMap>, InpaintError> {
        let cfg = self.method.visibility.clone();
        if !cfg.enabled() || self.guidance.is_none() {
            return Ok(None);
        }
        let step = self.nerf.step;
        let stale = self.guidance.as_ref().is_some_and(|g| {
            g.visibility
                .get(&view)
                .is_none_or(|m| step >= m.step + cfg.refresh_every)
        });
        if stale {
            let margin = self.method.crop_margin;
            let references = self
                .reference
                .as_ref()
                .map(ReferenceState::view_indices)
                .unwrap_or_default();
            let computed = ObservedMap::compute(
                &self.render_context(),
                &self.nerf.data.views,
                view,
                margin,
                &cfg,
                step,
                &references,
            )
            .map_err(NerfError::from)?;
            let Some(map) = computed else {
                return Ok(None);
            };
            tracing::debug!(
                view,
                step,
                observed = map.observed_share(),
                "visibility map recomputed"
            );
            if let Some(g) = self.guidance.as_mut() {
                g.visibility.insert(view, map);
            }
        }
        Ok(self.guidance.as_ref().and_then(|g| g.visibility.get(&view)))
    }

    /// The first step of the visibility maps (`visibility.start_step` scaled to the run).
    pub fn visibility_start(&self) -> usize {
        self.method
            .visibility_start_for(self.nerf.config.train.steps)
    }

    /// The per-pixel gradient weights `[1, 1, r, r]` of `view`'s prior input (`None` when
    /// visibility-aware guidance is off): `observed_weight` everywhere before
    /// [`Self::visibility_start`], then from the view's observed map.
    fn observed_weights(
        &mut self,
        view: usize,
        r: usize,
    ) -> Result<Option<Tensor<4>>, InpaintError> {
        let weight = self.method.visibility.observed_weight;
        if !self.method.visibility.enabled() {
            return Ok(None);
        }
        let device = self.nerf.field.device();
        if self.nerf.step < self.visibility_start() {
            return Ok(Some(Tensor::<4>::full(
                [1, 1, r, r],
                weight as f32,
                &device,
            )));
        }
        Ok(self
            .observed_map(view)?
            .map(|map| map.weights(r, weight, &device)))
    }

    /// The prior's inpainting mask `[1, 1, R, R]` of `view` under visibility-aware
    /// conditioning (`visibility.condition_on_observed`): the crop's mask less the pixels
    /// that other training views observe. `None` when that conditioning is off or before
    /// the maps start (the crop's own mask applies).
    fn conditioning_mask(&mut self, view: usize) -> Result<Option<Tensor<4>>, InpaintError> {
        let vis = &self.method.visibility;
        if !(vis.enabled() && vis.condition_on_observed) || self.nerf.step < self.visibility_start()
        {
            return Ok(None);
        }
        let Ok(cached) = self.cached(view) else {
            return Ok(None);
        };
        let mask = cached.mask.clone();
        let r = mask.dims()[2];
        let device = mask.device();
        Ok(self
            .observed_map(view)?
            .map(|map| map.weights(r, 0.0, &device))
            .map(|unobserved| mask * unobserved))
    }

    /// `image` with the gradient on observed pixels scaled (identity when off).
    fn gate_observed(&mut self, view: usize, image: Tensor<4>) -> Result<Tensor<4>, InpaintError> {
        let r = image.dims()[2];
        Ok(match self.observed_weights(view, r)? {
            Some(w) => gate_gradient(image, w),
            None => image,
        })
    }

    fn cached(&self, view: usize) -> Result<&ViewGuidance, InpaintError> {
        self.guidance
            .as_ref()
            .and_then(|g| g.cache.get(&view))
            .ok_or(InpaintError::Distill(
                gb_diffusion::distill::DistillError::UnknownView(view),
            ))
    }

    /// One guidance term of `modality` on a prior input `image` of training view `view`, at
    /// step `step` (its seed and schedule position); `at` fixes the timestep and noise.
    pub fn term(
        &mut self,
        modality: Modality,
        view: usize,
        image: Tensor<4>,
        step: usize,
        at: Option<(usize, Tensor<4>)>,
    ) -> Result<TermOutput, InpaintError> {
        self.view_guidance(view)?;
        let seed = derive_seed(self.nerf.config.train.seed, step, modality.salt());
        let k = self.method.guide_every;
        let normal_start = self.normal_start();
        let unobserved_mask = self.conditioning_mask(view)?;
        let (lambda, chain) = match modality {
            Modality::Rgb => (
                self.method.lambda_rgb.value(),
                self.method.reference_chain_rule,
            ),
            Modality::Normal => (
                self.method.lambda_normal.value(),
                self.method.reference_chain_rule,
            ),
        };
        let g = self
            .guidance
            .as_ref()
            .ok_or_else(|| InpaintError::PriorRequired {
                method: self.method.name.clone(),
            })?;
        let vg = g.cache.get(&view).ok_or(InpaintError::Distill(
            gb_diffusion::distill::DistillError::UnknownView(view),
        ))?;
        let (settings, prompts, iteration) = match modality {
            Modality::Rgb => {
                let (s, p) = g.rgb.as_ref().ok_or_else(|| no_guidance("rgb"))?;
                (s, p, multiples_in(0, step, k))
            }
            Modality::Normal => {
                let (s, p) = g.normal.as_ref().ok_or_else(|| no_guidance("normal"))?;
                (s, p, multiples_in(normal_start, step, k))
            }
        };
        let mut distiller = distiller_for(settings, &g.prior, seed, iteration)?;
        let encoder = g.prior.encoder.as_ref();
        let (mask_latent, masked_latents) = match (unobserved_mask, modality) {
            // visibility-aware conditioning: the prior is told that only the unobserved
            // pixels are unknown, and sees the current render (detached) on the others
            (Some(mask), _) => {
                let current = image.clone().detach().inner();
                let known = match modality {
                    Modality::Rgb => compose(
                        current,
                        Some(&vg.ground_truth),
                        &vg.mask,
                        PriorInputMode::PasteOnGroundTruth,
                        view,
                    )?,
                    Modality::Normal => current,
                };
                let latent = latent_mask(mask.clone(), encoder.downsample_factor());
                (latent, masked_image_latents(encoder, known, &mask)?)
            }
            (None, Modality::Rgb) => (vg.mask_latent.clone(), vg.masked_image_latents.clone()),
            // no ground-truth normal map: the conditioning is the current normal map
            // itself (detached), masked, as in the reference
            (None, Modality::Normal) => {
                let current = image.clone().detach().inner();
                let latents = masked_image_latents(encoder, current, &vg.mask)?;
                (vg.mask_latent.clone(), latents)
            }
        };
        let oracle = match (modality, self.oracle.as_mut()) {
            (Modality::Rgb, Some(o)) => o
                .latents(view, &vg.geometry, g.prior.resolution, encoder, &g.device)?
                .map(|z| (z, o.branches.as_slice())),
            _ => None,
        };
        let cond = TermConditioning {
            mask_latent: &mask_latent,
            masked_image_latents: &masked_latents,
            prompts,
            oracle,
        };
        guidance_term(&mut distiller, &g.prior, image, &cond, lambda, chain, at)
    }

    /// The guidance terms of step `step` (empty when none is due).
    fn guidance_terms(
        &mut self,
        step: usize,
    ) -> Result<(Vec<TermOutput>, Vec<TermRecord>), InpaintError> {
        let mut outs = Vec::new();
        let mut records = Vec::new();
        let Some(g) = self.guidance.as_ref() else {
            return Ok((outs, records));
        };
        if !step.is_multiple_of(self.method.guide_every) {
            return Ok((outs, records));
        }
        // with visibility-aware guidance at weight 0, a term before the maps start would
        // carry no gradient: skip its U-Net calls
        let vis = &self.method.visibility;
        if vis.enabled() && vis.observed_weight == 0.0 && step < self.visibility_start() {
            return Ok((outs, records));
        }
        let do_rgb = g.rgb.is_some() && self.method.lambda_rgb.value() > 0.0;
        let do_normal = g.normal.is_some()
            && self.method.lambda_normal.value() > 0.0
            && step >= self.normal_start();
        if !(do_rgb || do_normal) || g.views.is_empty() {
            return Ok((outs, records));
        }
        let mut pick = ChaCha8Rng::seed_from_u64(derive_seed(self.nerf.config.train.seed, step, 0));
        let view = g.views[pick.random_range(0..g.views.len())];
        if do_rgb {
            let t0 = Instant::now();
            let (image, rays) = self.rgb_prior_input(view)?;
            let out = self.term(Modality::Rgb, view, image, step, None)?;
            records.push(TermRecord::new(
                Modality::Rgb,
                view,
                &out,
                rays,
                t0.elapsed().as_secs_f64(),
            ));
            outs.push(out);
        }
        if do_normal {
            let t0 = Instant::now();
            let (image, rays) = self.normal_prior_input(view)?;
            let out = self.term(Modality::Normal, view, image, step, None)?;
            records.push(TermRecord::new(
                Modality::Normal,
                view,
                &out,
                rays,
                t0.elapsed().as_secs_f64(),
            ));
            outs.push(out);
        }
        Ok((outs, records))
    }

    /// One optimisation step (module docs); a non-finite loss skips the update.
    pub fn train_step(&mut self) -> Result<StepRecord, InpaintError> {
        let start = Instant::now();
        let step = self.nerf.step;
        let recon = self.nerf.reconstruction_loss()?;
        let (terms, records) = self.guidance_terms(step)?;
        let reference = self.reference_term(step)?;
        let geometry = match self.hidden_depth.as_ref() {
            Some(h) => {
                let seed = derive_seed(self.nerf.config.train.seed, step, GEOMETRY_SALT);
                h.loss(&self.render_context(), &self.nerf.data.views, seed)
                    .map_err(gb_nerf::train::NerfError::from)?
            }
            None => None,
        };
        let mut loss = recon.loss.clone();
        if let Some(g) = geometry {
            loss = loss + g;
        }
        for t in terms {
            loss = loss + t.loss;
        }
        if let Some((t, _)) = &reference {
            loss = loss + t.loss.clone();
        }
        if self.inject_nan_from_step.is_some_and(|s| step >= s) {
            loss = loss.add_scalar(f32::NAN);
        }
        let mut read = vec![recon.loss.detach(), loss.clone().detach(), recon.rgb_mse];
        if let Some((t, _)) = &reference {
            read.push(t.loss.clone().detach());
        }
        // one read for the step's own values (the guidance terms read their diagnostics)
        let values = gb_core::read_f32(Tensor::cat(read, 0), "step losses")
            .map_err(gb_nerf::train::NerfError::from)?;
        let (recon_value, loss_value, rgb_mse) = (values[0], values[1], values[2]);
        let finite = |v: f32| v.is_finite().then_some(v as f64);
        let mut record = StepRecord {
            step,
            loss: finite(loss_value),
            recon_loss: finite(recon_value),
            psnr: psnr_from_mse(rgb_mse as f64),
            lr: self.nerf.config.lr_at(step),
            skipped: false,
            evaluations_per_ray: recon.evaluations_per_ray,
            seconds: 0.0,
            guidance: records,
            reference: reference.map(|(t, carried)| ReferenceRecord {
                loss: values.get(3).copied().and_then(finite),
                direct_rays: t.direct_rays,
                carried_rays: t.carried_rays,
                carried_pixels: carried,
            }),
        };
        if self.nerf.apply_loss_valued(loss, loss_value)? {
            self.nan_streak = 0;
        } else {
            self.nan_streak += 1;
            record.skipped = true;
            tracing::warn!(
                step,
                loss = loss_value,
                streak = self.nan_streak,
                "non-finite loss: step skipped"
            );
        }
        record.seconds = start.elapsed().as_secs_f64();
        Ok(record)
    }

    fn stop_message(&self) -> String {
        match &self.last_good_checkpoint {
            Some((p, s)) => format!(
                "the last good checkpoint is {} (step {s}); continue from it with --resume, \
                 e.g. with a lower lambda or learning rate",
                p.display()
            ),
            None => "no checkpoint was written before the failure".into(),
        }
    }

    /// Trains until `config.train.steps` (module docs), writing the log, checkpoints and a
    /// progress bar as `opts` says.
    pub fn fit(&mut self, opts: &FitOptions) -> Result<FitSummary, InpaintError> {
        let total = self.nerf.config.train.steps;
        let start = Instant::now();
        let first = self.nerf.step;
        let bar = if opts.progress {
            gb_core::progress::bar(total as u64)
        } else {
            ProgressBar::hidden()
        };
        bar.set_style(
            ProgressStyle::with_template(
                "{bar:30} {pos}/{len} [{elapsed_precise}<{eta_precise}] {msg}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar.set_position(self.nerf.step as u64);
        let mut log = match &opts.log {
            Some(path) => {
                if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                    std::fs::create_dir_all(dir).map_err(|e| InpaintError::io(dir, e))?;
                }
                if opts.append_log {
                    resume::truncate_log(path, self.nerf.step)
                        .map_err(|e| InpaintError::io(path, e))?;
                }
                let file = std::fs::OpenOptions::new()
                    .create(true)
                    .write(true)
                    .append(opts.append_log)
                    .truncate(!opts.append_log)
                    .open(path)
                    .map_err(|e| InpaintError::io(path, e))?;
                Some((path.clone(), std::io::LineWriter::new(file)))
            }
            None => None,
        };
        while self.nerf.step < total {
            let rec = self.train_step()?;
            let totals = &mut self.totals;
            totals.evaluations_per_ray_sum += rec.evaluations_per_ray as f64;
            if rec.skipped {
                totals.skipped_steps += 1;
            }
            if rec.guidance.is_empty() {
                totals.unguided_steps += 1;
                totals.unguided_seconds += rec.seconds;
            } else {
                totals.guided_steps += 1;
                totals.guided_seconds += rec.seconds;
                totals.unet_calls += rec.guidance.iter().map(|g| g.unet_calls).sum::<usize>();
            }
            if let Some((path, w)) = log.as_mut() {
                let line = serde_json::to_string(&rec).unwrap_or_default();
                writeln!(w, "{line}").map_err(|e| InpaintError::io(path.as_path(), e))?;
            }
            let done = (self.nerf.step - first) as f64;
            let guide = rec
                .guidance
                .iter()
                .map(|g| format!(" {:?} t={:.2} |g|={:.2e}", g.modality, g.t, g.grad_norm))
                .collect::<String>();
            bar.set_position(self.nerf.step as u64);
            bar.set_message(format!(
                "loss {} psnr {:.2} dB {:.2} it/s{guide}",
                rec.loss
                    .map_or_else(|| "NaN (skipped)".to_string(), |l| format!("{l:.5}")),
                rec.psnr,
                done / start.elapsed().as_secs_f64().max(1e-9),
            ));
            if self.nan_streak >= self.method.max_consecutive_nan {
                bar.abandon();
                return Err(InpaintError::NonFiniteLoss {
                    step: rec.step,
                    count: self.nan_streak,
                    checkpoint: self.stop_message(),
                });
            }
            let every = self.nerf.config.train.checkpoint_every;
            if let Some(path) = &opts.checkpoint {
                let due =
                    (every > 0 && self.nerf.step.is_multiple_of(every)) || self.nerf.step == total;
                if due && self.nan_streak == 0 {
                    let state = self.checkpoint_state()?;
                    self.nerf.save_checkpoint_with(path, state)?;
                    self.last_good_checkpoint = Some((path.clone(), self.nerf.step));
                }
            }
        }
        bar.finish();
        let t = &self.totals;
        let counted = t.guided_steps + t.unguided_steps;
        let summary = FitSummary {
            steps_run: self.nerf.step - first,
            seconds: start.elapsed().as_secs_f64(),
            skipped_steps: t.skipped_steps,
            guided_steps: t.guided_steps,
            guided_seconds: t.guided_seconds,
            unguided_steps: t.unguided_steps,
            unguided_seconds: t.unguided_seconds,
            unet_calls: t.unet_calls,
            mean_evaluations_per_ray: if counted > 0 {
                (t.evaluations_per_ray_sum / counted as f64) as f32
            } else {
                0.0
            },
        };
        tracing::info!(
            steps_run = summary.steps_run,
            guided = summary.guided_steps,
            skipped = summary.skipped_steps,
            seconds = summary.seconds,
            "training finished"
        );
        Ok(summary)
    }
}

fn no_guidance(table: &str) -> InpaintError {
    InpaintError::MethodConfig {
        path: PathBuf::from(format!("[{table}]")),
        reason: "this modality has method = \"none\"".into(),
    }
}
