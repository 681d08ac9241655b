//! The reconstruction trainer: RGB loss on unmasked pixels, disparity loss on sparse points
//! or dense depth ([`DepthSupervision`]), Adam with an exponentially decaying learning rate,
//! occupancy-grid updates, progress bar, atomic checkpoints and resume.

use std::path::Path;
use std::time::Instant;

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::store::ModuleRecord;
use burn::tensor::{Bytes, Tensor, TensorData};
use gb_core::{read_f32, Devices};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::checkpoint::{self, CheckpointMeta, CheckpointParts, RngState};
use super::data::TrainData;
use super::losses::{disparity_loss, distortion_of, mse};
use super::{DepthSupervision, NerfConfig, NerfError};
use crate::field::NerfField;
use crate::render::image::{render_image, ImageRender, ImageSettings};
use crate::render::rays::camera_rays;
use crate::render::{render_profiles, render_rays, Background, RayProfile};
use crate::sampler::{sample_rays, OccupancyGrid, RayBatch, SceneSpace};
use crate::scene::{Camera, Mask, Scene};
use gb_core::psnr::{psnr_from_mse, LOG_MIN_MSE};

/// Loss and quality of one training step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepStats {
    /// Total loss.
    pub loss: f64,
    /// PSNR of the RGB loss on the batch, dB.
    pub psnr: f64,
    /// Field evaluations per ray (the dense budget is `samples_per_ray`).
    pub evaluations_per_ray: f32,
}

/// The reconstruction loss of one ray batch ([`Trainer::reconstruction_loss`]). Nothing in
/// it has been read from the device: a step reads once, all its values together.
pub struct ReconstructionLoss {
    /// RGB MSE plus the weighted disparity loss, with its graph.
    pub loss: Tensor<1>,
    /// The RGB MSE alone `[1]`, without a graph.
    pub rgb_mse: Tensor<1>,
    /// Field evaluations per ray of the batch.
    pub evaluations_per_ray: f32,
}

/// Summary of a [`Trainer::fit`] run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitSummary {
    /// Steps run in this call.
    pub steps_run: usize,
    /// Wall time of this call, seconds.
    pub seconds: f64,
    /// Stats of the last step.
    pub last: Option<StepStats>,
    /// Mean field evaluations per ray over the run.
    pub mean_evaluations_per_ray: f32,
}

/// The share of each batch's rays drawn through sparse points when the depth supervision is
/// sparse (DS-NeRF draws its depth rays as a separate batch; here they are part of the
/// batch, so a step costs the same with and without depth). Chosen a priori, not tuned.
pub const SPARSE_RAY_SHARE: f32 = 0.25;

/// The reconstruction state (see the module docs).
pub struct Trainer {
    /// The configuration.
    pub config: NerfConfig,
    /// Training views and pixels.
    pub data: TrainData,
    /// Scene parameterisation.
    pub space: SceneSpace,
    /// Near bound.
    pub near: f32,
    /// Far bound (also the background depth).
    pub far: f32,
    /// Background of empty rays.
    pub background: Background,
    /// The field, on the autodiff device.
    pub field: NerfField,
    /// Empty-space skipping.
    pub occupancy: Option<OccupancyGrid>,
    /// Steps completed.
    pub step: usize,
    /// The devices it runs on (the field lives on `devices.train`).
    pub devices: Devices,
    optimizer: ModuleOptimizer,
    rng: ChaCha8Rng,
    has_depth: bool,
    scene: String,
    data_fingerprint: u64,
}

impl Trainer {
    /// A fresh trainer for `scene`, on `devices` (a run's [`Devices`], or a [`gb_core::BackendKind`]).
    pub fn new(
        scene: &Scene,
        config: NerfConfig,
        devices: impl Into<Devices>,
    ) -> Result<Self, NerfError> {
        let devices = devices.into();
        let depth = config.train.depth;
        let data = TrainData::from_scene(scene, config.train.image_downscale, depth)?;
        if !(scene.near.is_finite() && scene.far.is_finite() && scene.near < scene.far) {
            return Err(NerfError::Scene {
                scene: scene.name.clone(),
                reason: format!("invalid bounds near {} far {}", scene.near, scene.far),
            });
        }
        let device = devices.train.clone();
        device.seed(config.train.seed);
        let field = config.field.init(&device);
        let space = SceneSpace::from_scene(scene);
        let has_depth = !data.sparse.is_empty() || data.views.iter().any(|v| v.depth.is_some());
        if depth != DepthSupervision::None && !has_depth {
            tracing::warn!(
                scene = %scene.name,
                "depth = \"{depth}\" but the scene has no {} depth for its training views \
                 outside the masks: training on colour alone",
                if depth == DepthSupervision::Sparse { "sparse (COLMAP sparse/0)" } else { "dense" }
            );
        } else if depth == DepthSupervision::Sparse {
            tracing::info!(points = data.sparse.len(), "sparse depth supervision");
        }
        let data_fingerprint = checkpoint::data_fingerprint(&data);
        let mut trainer = Self {
            data,
            space,
            near: scene.near,
            far: scene.far,
            background: Background {
                color: scene.background,
                depth: scene.far,
            },
            field,
            occupancy: None,
            step: 0,
            devices,
            optimizer: AdamConfig::new().with_epsilon(1e-15).init(),
            rng: ChaCha8Rng::seed_from_u64(config.train.seed),
            has_depth,
            scene: scene.name.clone(),
            data_fingerprint,
            config,
        };
        if let Some(occ) = trainer.config.sampler.occupancy.clone() {
            let typical = trainer.typical_delta();
            trainer.occupancy = Some(OccupancyGrid {
                early_stop_eps: occ.early_stop_eps,
                ..OccupancyGrid::new(
                    occ.resolution,
                    OccupancyGrid::threshold_for(occ.opacity_threshold, typical),
                )
            });
        }
        Ok(trainer)
    }

    /// Mean world-space sample interval over a fixed set of training rays.
    fn typical_delta(&mut self) -> f32 {
        let rays = self.batch_rays(256).0;
        let s = sample_rays::<ChaCha8Rng>(
            &rays,
            &self.space,
            self.config.sampler.samples_per_ray,
            None,
            None,
        );
        let valid: Vec<f32> = s
            .delta
            .iter()
            .copied()
            .filter(|d| *d > 0.0 && d.is_finite())
            .collect();
        if valid.is_empty() {
            1.0
        } else {
            valid.iter().sum::<f32>() / valid.len() as f32
        }
    }

    /// Draws a batch of `n` training rays: rays, target colours, and (near-scaled) target
    /// disparities with their validity. With sparse depth, [`SPARSE_RAY_SHARE`] of the rays
    /// go through random sparse points (their colour is the pixel the point falls in); the
    /// rest through random unmasked pixels.
    fn batch_rays(&mut self, n: usize) -> (RayBatch, Vec<f32>, Vec<f32>, Vec<f32>) {
        let mut rays = RayBatch::default();
        let mut rgb = Vec::with_capacity(n * 3);
        let mut disp = Vec::with_capacity(n);
        let mut valid = Vec::with_capacity(n);
        let n_sparse = if self.data.sparse.is_empty() {
            0
        } else {
            ((n as f32 * SPARSE_RAY_SHARE).round() as usize).clamp(1, n)
        };
        for k in 0..n {
            // the ray's view, continuous pixel position and ground-truth z-depth, if any
            let (view, px, depth) = if k < n_sparse {
                let p = self.data.sparse[self.rng.random_range(0..self.data.sparse.len())];
                (p.view, [p.x, p.y], Some(p.depth))
            } else {
                let p = self.data.pixels[self.rng.random_range(0..self.data.pixels.len())];
                let v = &self.data.views[p.view as usize];
                let d = v
                    .depth
                    .as_ref()
                    .map(|d| d[p.y as usize * v.image.width + p.x as usize])
                    .filter(|d| d.is_finite() && *d > 0.0);
                (p.view, [p.x as f32 + 0.5, p.y as f32 + 0.5], d)
            };
            let v = &self.data.views[view as usize];
            let r = camera_rays(&v.camera, &[px], &self.space, self.near, self.far);
            rays.origins.extend(r.origins);
            rays.dirs.extend(r.dirs);
            rays.near.extend(r.near);
            rays.far.extend(r.far);
            rgb.extend_from_slice(&v.image.get(px[0] as usize, px[1] as usize));
            disp.push(depth.map_or(0.0, |d| self.near / d));
            valid.push(if depth.is_some() { 1.0 } else { 0.0 });
        }
        (rays, rgb, disp, valid)
    }

    /// Withholds the pixels under `masks` from every loss ([`TrainData::withhold`]), e.g. a
    /// pseudo-hole that no view may see; call it before the first step. The checkpoint's data
    /// fingerprint then covers which pixels are left.
    pub fn withhold(&mut self, masks: &[Option<Mask>]) -> Result<(), NerfError> {
        self.data.withhold(masks)?;
        let mut h = gb_core::fingerprint::Fnv64::default();
        h.word(checkpoint::data_fingerprint(&self.data));
        for p in &self.data.pixels {
            h.word((p.view as u64) << 40 | (p.y as u64) << 20 | p.x as u64);
        }
        self.data_fingerprint = h.finish();
        Ok(())
    }

    /// The reconstruction loss of one batch of unmasked training rays (RGB MSE, plus
    /// `depth_weight` times the disparity loss where depth exists), with its autodiff graph.
    /// Draws from the trainer's random stream; [`Self::apply_loss`] completes the step.
    /// Errors when early ray termination cannot read the field's densities.
    pub fn reconstruction_loss(&mut self) -> Result<ReconstructionLoss, NerfError> {
        let n = self.config.train.rays_per_batch;
        let (rays, rgb, disp, valid) = self.batch_rays(n);
        let device = self.field.device();
        let (out, samples) = render_rays(
            &self.field,
            &self.space,
            &rays,
            self.config.sampler.samples_per_ray,
            self.occupancy.as_ref(),
            self.background,
            Some(&mut self.rng),
        )?;
        let target = Tensor::<2>::from_data(TensorData::new(rgb, [n, 3]), &device);
        let rgb_loss = mse(out.rgb, target);
        let mut loss = rgb_loss.clone();
        if self.config.train.distortion_weight > 0.0 {
            let dl = distortion_of(out.weights.clone(), &rays, &samples, self.space.spacing());
            loss = loss + dl.mul_scalar(self.config.train.distortion_weight);
        }
        if self.has_depth && self.config.train.depth_weight > 0.0 {
            let gt = Tensor::<1>::from_data(TensorData::new(disp, [n]), &device);
            let valid = Tensor::<1>::from_data(TensorData::new(valid, [n]), &device);
            let dl = disparity_loss(out.disparity, gt, valid, self.near);
            loss = loss + dl.mul_scalar(self.config.train.depth_weight);
        }
        Ok(ReconstructionLoss {
            loss,
            rgb_mse: rgb_loss.detach(),
            evaluations_per_ray: samples.evaluations_per_ray(),
        })
    }

    /// Completes a step with `loss` (the reconstruction loss plus any extra terms): one
    /// backward pass, Adam at this step's learning rate, then the occupancy-grid update. The
    /// step counter advances either way; a non-finite `loss` skips the update and returns
    /// `false`. Errors when the occupancy grid cannot read the field's densities.
    pub fn apply_loss(&mut self, loss: Tensor<1>) -> Result<bool, NerfError> {
        let value = read_f32(loss.clone().detach(), "loss")?[0];
        self.apply_loss_valued(loss, value)
    }

    /// [`Self::apply_loss`] with the loss's value already read (`value`), so that a step
    /// reads once for everything it logs.
    pub fn apply_loss_valued(&mut self, loss: Tensor<1>, value: f32) -> Result<bool, NerfError> {
        let lr = self.config.lr_at(self.step);
        self.step += 1;
        if !value.is_finite() {
            return Ok(false);
        }
        let grads = GradientsParams::from_grads(loss.backward(), &self.field);
        self.field = self.optimizer.step(lr, self.field.clone(), grads);
        self.maybe_update_occupancy()?;
        Ok(true)
    }

    /// One optimisation step ([`Self::reconstruction_loss`] then [`Self::apply_loss`]), with
    /// one device read (loss and RGB MSE together), plus the occupancy grid's on its update
    /// steps.
    pub fn train_step(&mut self) -> Result<StepStats, NerfError> {
        let r = self.reconstruction_loss()?;
        let values = read_f32(
            Tensor::cat(vec![r.loss.clone().detach(), r.rgb_mse], 0),
            "loss and RGB MSE",
        )?;
        let (loss_value, rgb_mse) = (values[0], values[1]);
        self.apply_loss_valued(r.loss, loss_value)?;
        Ok(StepStats {
            loss: loss_value as f64,
            psnr: psnr_from_mse((rgb_mse as f64).max(LOG_MIN_MSE)),
            evaluations_per_ray: r.evaluations_per_ray,
        })
    }

    fn maybe_update_occupancy(&mut self) -> Result<(), NerfError> {
        let Some(cfg) = self.config.sampler.occupancy.clone() else {
            return Ok(());
        };
        let Some(grid) = self.occupancy.as_mut() else {
            return Ok(());
        };
        if self.step >= cfg.warmup_steps && self.step.is_multiple_of(cfg.update_every) {
            let valid = self.field.valid();
            grid.update(&valid, cfg.cells_per_update, cfg.decay, &mut self.rng)?;
        }
        Ok(())
    }

    /// Trains until `config.train.steps`, with a progress bar (when `progress`) and a
    /// checkpoint every `checkpoint_every` steps and at the end (when `checkpoint` is given).
    pub fn fit(
        &mut self,
        checkpoint: Option<&Path>,
        progress: bool,
    ) -> Result<FitSummary, NerfError> {
        let total = self.config.train.steps;
        let start = Instant::now();
        let first = self.step;
        let bar = gb_core::progress::training_bar(total as u64, self.step as u64, progress);
        let mut last = None;
        let mut evals = 0.0f64;
        while self.step < total {
            let s = self.train_step()?;
            evals += s.evaluations_per_ray as f64;
            let done = (self.step - first) as f64;
            bar.set_position(self.step as u64);
            bar.set_message(format!(
                "loss {:.5} psnr {:.2} dB {:.2} it/s evals/ray {:.1}",
                s.loss,
                s.psnr,
                done / start.elapsed().as_secs_f64().max(1e-9),
                s.evaluations_per_ray
            ));
            last = Some(s);
            let every = self.config.train.checkpoint_every;
            if let Some(path) = checkpoint {
                if (every > 0 && self.step.is_multiple_of(every)) || self.step == total {
                    self.save_checkpoint(path)?;
                }
            }
        }
        bar.finish();
        let steps_run = self.step - first;
        tracing::info!(
            steps_run,
            seconds = start.elapsed().as_secs_f64(),
            "training finished"
        );
        Ok(FitSummary {
            steps_run,
            seconds: start.elapsed().as_secs_f64(),
            last,
            mean_evaluations_per_ray: if steps_run > 0 {
                (evals / steps_run as f64) as f32
            } else {
                0.0
            },
        })
    }

    /// Writes a checkpoint atomically (module docs of [`checkpoint`]).
    pub fn save_checkpoint(&self, path: &Path) -> Result<(), NerfError> {
        self.save_checkpoint_with(path, serde_json::Value::Null)
    }

    /// Writes a checkpoint atomically with the caller's own state `extra` (read back with
    /// [`checkpoint::load`]: `meta.extra`).
    pub fn save_checkpoint_with(
        &self,
        path: &Path,
        extra: serde_json::Value,
    ) -> Result<(), NerfError> {
        let e = |r: String| NerfError::Checkpoint {
            path: path.to_path_buf(),
            reason: r,
        };
        let model = self
            .field
            .clone()
            .into_record()
            .into_bytes()
            .map_err(|x| e(x.to_string()))?;
        let optimizer = self.optimizer.into_bytes().map_err(|x| e(x.to_string()))?;
        checkpoint::save(
            path,
            &CheckpointParts {
                meta: CheckpointMeta {
                    step: self.step,
                    config_toml: checkpoint::config_to_toml(&self.config, path)?,
                    scene: self.scene.clone(),
                    data_fingerprint: format!("{:016x}", self.data_fingerprint),
                    rng: RngState::of(&self.rng),
                    occupancy_threshold_bits: self
                        .occupancy
                        .as_ref()
                        .map(|g| g.density_threshold.to_bits()),
                    extra,
                },
                model: model.to_vec(),
                optimizer: optimizer.to_vec(),
                occupancy: self
                    .occupancy
                    .as_ref()
                    .map(|g| g.density.clone())
                    .unwrap_or_default(),
                occupied: self
                    .occupancy
                    .as_ref()
                    .map(|g| g.occupied.clone())
                    .unwrap_or_default(),
            },
        )
    }

    /// Restores a trainer from a checkpoint of the same scene: parameters, optimiser state,
    /// occupancy grid, step and the exact position of the random stream, so that it
    /// continues as the uninterrupted run would. Errors (naming the file) when the
    /// checkpoint was written for other training data.
    pub fn resume(
        scene: &Scene,
        path: &Path,
        devices: impl Into<Devices>,
    ) -> Result<Self, NerfError> {
        let parts = checkpoint::load(path)?;
        let config = parts.meta.config(path)?;
        Self::resume_from(scene, path, parts, config, devices)
    }

    /// [`Self::resume`] from checkpoint parts already read from `path`, training with
    /// `config` (the caller has checked that it matches the checkpoint's wherever that
    /// matters; the step count may differ).
    pub fn resume_from(
        scene: &Scene,
        path: &Path,
        parts: CheckpointParts,
        config: NerfConfig,
        devices: impl Into<Devices>,
    ) -> Result<Self, NerfError> {
        Self::restore(Self::new(scene, config, devices)?, path, parts)
    }

    /// Restores the state of the checkpoint `parts` (read from `path`) into `t`, a fresh
    /// trainer of the same training data (withheld pixels included: see [`Self::withhold`]):
    /// parameters, optimiser state, occupancy grid, step and random stream. Errors (naming
    /// the file) when the checkpoint was written for other training data.
    pub fn restore(mut t: Self, path: &Path, parts: CheckpointParts) -> Result<Self, NerfError> {
        let e = |r: String| NerfError::Checkpoint {
            path: path.to_path_buf(),
            reason: r,
        };
        let fingerprint = format!("{:016x}", t.data_fingerprint);
        if parts.meta.scene != t.scene || parts.meta.data_fingerprint != fingerprint {
            return Err(e(format!(
                "written for other training data (scene '{}', fingerprint {}; this run: \
                 scene '{}', fingerprint {fingerprint})",
                parts.meta.scene, parts.meta.data_fingerprint, t.scene
            )));
        }
        let record = ModuleRecord::from_bytes(Bytes::from_bytes_vec(parts.model))
            .map_err(|x| e(format!("model: {x}")))?;
        t.field = t
            .field
            .clone()
            .try_load_record(record)
            .map_err(|x| e(format!("model: {x}")))?;
        t.optimizer = AdamConfig::new()
            .with_epsilon(1e-15)
            .init()
            .from_bytes(Bytes::from_bytes_vec(parts.optimizer))
            .map_err(|x| e(format!("optimizer: {x}")))?;
        match (t.occupancy.as_mut(), parts.meta.occupancy_threshold_bits) {
            (Some(grid), Some(bits)) => {
                if parts.occupancy.len() != grid.density.len() {
                    return Err(e(format!(
                        "occupancy grid has {} cells, config expects {}",
                        parts.occupancy.len(),
                        grid.density.len()
                    )));
                }
                grid.density = parts.occupancy;
                grid.occupied = parts.occupied;
                grid.density_threshold = f32::from_bits(bits);
            }
            (None, None) => {}
            (Some(_), None) => return Err(e("the checkpoint has no occupancy grid".into())),
            (None, Some(_)) => {
                return Err(e(
                    "the checkpoint has an occupancy grid, the config none".into()
                ))
            }
        }
        t.step = parts.meta.step;
        t.rng = parts.meta.rng.restore().ok_or_else(|| {
            e(format!(
                "rng: bad word position '{}'",
                parts.meta.rng.word_pos
            ))
        })?;
        Ok(t)
    }

    /// The settings of this field's image renders: its space, bounds, samples, occupancy
    /// grid, background, normals and chunk.
    pub fn image_settings(&self) -> ImageSettings<'_> {
        ImageSettings {
            space: &self.space,
            near: self.near,
            far: self.far,
            samples_per_ray: self.config.sampler.samples_per_ray,
            occupancy: self.occupancy.as_ref(),
            background: self.background,
            normals: self.config.render.normals,
            chunk: self.config.render.chunk,
        }
    }

    /// Renders a whole image (no autodiff) with the configured normals; errors when a
    /// rendered tensor does not hold `f32` values.
    pub fn render(&self, camera: &Camera) -> Result<ImageRender, NerfError> {
        Ok(render_image(&self.field, camera, &self.image_settings())?)
    }

    /// The compositing weights along the rays through `pixels` of `camera`, sampled exactly
    /// as [`Self::render`] samples them.
    pub fn ray_profiles(
        &self,
        camera: &Camera,
        pixels: &[[f32; 2]],
    ) -> Result<Vec<RayProfile>, NerfError> {
        Ok(render_profiles(
            &self.field,
            camera,
            pixels,
            &self.image_settings(),
        )?)
    }
}
