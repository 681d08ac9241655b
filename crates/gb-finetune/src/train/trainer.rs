//! [`FinetuneTrainer`]: AdamW over LoRA adapters (or every weight), gradient accumulation,
//! global-norm clipping, NaN-safe steps, atomic checkpoints with the optimiser state, an
//! exact resume, and the LoRA export in the diffusers/PEFT format.

use std::path::Path;

use burn::module::{Lora, Module, ParamGroup};
use burn::optim::{AdamWConfig, GradientsAccumulator, GradientsParams, ModuleOptimizer};
use burn::store::ModuleRecord;
use burn::tensor::{Bytes, Device};

use gb_diffusion::checkpoint::keymap;
use gb_diffusion::lora::{collect_lora, write_peft_lora, LoraComponent, LoraExport};

use super::batch::make_batch;
use super::checkpoint::{self, CheckpointMeta, CheckpointParts};
use super::grad_clip::clip_global_norm;
use super::grad_sync::{mean_gradients, GradSync, SingleProcess};
use super::loss::inpainting_loss;
use super::models::{PriorModels, Trainable};
use super::{FinetuneConfig, TrainTarget};
use crate::sample::PairSource;
use crate::FinetuneError;

/// Regex of the U-Net weights that get LoRA adapters: the attention projections of every
/// transformer block (diffusers' `target_modules = ["to_k", "to_q", "to_v", "to_out.0"]`).
pub const UNET_LORA_TARGETS: &str = r"^unet\..*\.(to_q|to_k|to_v|to_out\.0)\.weight$";
/// Regex of the text-encoder weights that get LoRA adapters (`q/k/v/out_proj`).
pub const TEXT_LORA_TARGETS: &str = r"^text_encoder\..*\.(q_proj|k_proj|v_proj|out_proj)\.weight$";
/// Consecutive non-finite steps after which a run stops.
pub const MAX_NAN_STEPS: usize = 5;

/// What one optimiser step did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepStats {
    /// The step just completed (1-based).
    pub step: usize,
    /// Mean loss over the micro-batches.
    pub loss: f64,
    /// Global gradient norm before clipping.
    pub grad_norm: f64,
    /// Whether the update was skipped (non-finite loss or gradient).
    pub skipped: bool,
    /// Seconds spent exchanging gradients with the other ranks (0 in one process).
    pub exchange_seconds: f64,
    /// Gradient values each rank exchanged (`f32`; 0 in one process).
    pub exchanged_values: usize,
}

/// A fine-tuning run in memory.
pub struct FinetuneTrainer {
    /// The prior; `models.trainable` carries the adapters and lives on `device`.
    pub models: PriorModels,
    /// The recipe.
    pub config: FinetuneConfig,
    /// Optimiser steps completed.
    pub step: usize,
    /// Loss of each completed step.
    pub losses: Vec<f64>,
    optimizer: ModuleOptimizer,
    device: Device,
    nan_streak: usize,
    sync: Box<dyn GradSync + Send>,
}

fn optimizer(cfg: &FinetuneConfig) -> ModuleOptimizer {
    AdamWConfig::new()
        .with_weight_decay(cfg.weight_decay)
        .with_epsilon(1e-8)
        .init()
}

/// Attaches fresh LoRA adapters (rank, alpha of `cfg`) to the attention projections of the
/// U-Net and, when `cfg.train_text_encoder`, of the text encoder. Every base weight is frozen.
/// The `A` factors are drawn from the device RNG, seeded with `cfg.seed` first.
pub fn attach_lora(
    trainable: Trainable,
    cfg: &FinetuneConfig,
    device: &Device,
) -> Result<Trainable, FinetuneError> {
    let mut patterns = vec![UNET_LORA_TARGETS.to_string()];
    if cfg.train_text_encoder {
        patterns.push(TEXT_LORA_TARGETS.to_string());
    }
    let group = ParamGroup::from_regex(patterns.join("|")).map_err(|e| FinetuneError::Config {
        field: "lora targets".into(),
        message: format!("{e:?}"),
    })?;
    device.seed(cfg.seed);
    Ok(trainable.apply_lora(Lora::new(cfg.rank, cfg.alpha).set_param_group(group)))
}

impl FinetuneTrainer {
    /// Starts a run: attaches LoRA adapters (LoRA target) or unfreezes the networks (full
    /// target; the text encoder stays frozen unless `train_text_encoder`). `models` must
    /// live on `device`, an autodiff device.
    pub fn new(
        mut models: PriorModels,
        config: FinetuneConfig,
        device: &Device,
    ) -> Result<Self, FinetuneError> {
        config.validate()?;
        let latent = config.resolution / models.vae_factor;
        let down = 1usize
            << models
                .unet_config
                .block_out_channels
                .len()
                .saturating_sub(1);
        if !config.resolution.is_multiple_of(models.vae_factor) || !latent.is_multiple_of(down) {
            return Err(FinetuneError::Config {
                field: "resolution".into(),
                message: format!(
                    "{} must be a multiple of the VAE factor {} times the U-Net's down-sampling {down}",
                    config.resolution, models.vae_factor
                ),
            });
        }
        models.trainable = match config.target {
            TrainTarget::Lora => attach_lora(models.trainable, &config, device)?,
            TrainTarget::Full => {
                let t = models.trainable;
                if config.train_text_encoder {
                    t
                } else {
                    Trainable {
                        unet: t.unet,
                        text_encoder: t.text_encoder.no_grad(),
                    }
                }
            }
        };
        Ok(Self {
            models,
            optimizer: optimizer(&config),
            config,
            step: 0,
            losses: Vec::new(),
            device: device.clone(),
            nan_streak: 0,
            sync: Box::new(SingleProcess),
        })
    }

    /// Trains as one rank of a data-parallel run: each step's gradients are replaced by their
    /// mean over the ranks of `sync` before the clip ([`super::grad_sync`]). The default is
    /// [`SingleProcess`].
    pub fn with_sync(mut self, sync: Box<dyn GradSync + Send>) -> Self {
        self.sync = sync;
        self
    }

    /// The ranks this trainer trains among ([`Self::with_sync`]).
    pub fn sync(&self) -> &dyn GradSync {
        self.sync.as_ref()
    }

    /// One optimiser step: `grad_accum` micro-batches, the ranks' mean ([`Self::with_sync`]),
    /// global-norm clip, AdamW update. A
    /// non-finite loss or gradient skips the update (logged); [`MAX_NAN_STEPS`] in a row
    /// stop the run with [`FinetuneError::Diverged`].
    pub fn train_step(&mut self, source: &dyn PairSource) -> Result<StepStats, FinetuneError> {
        let cfg = &self.config;
        let latent = cfg.resolution / self.models.vae_factor;
        let channels = self.models.vae.latent_channels;
        let schedule = self.models.alphas_cumprod.len();
        let train_text = cfg.train_text_encoder;
        let mut accum = GradientsAccumulator::<Trainable>::new();
        let mut loss_sum = 0.0;
        let (rank, ranks) = (self.sync.rank(), self.sync.ranks());
        for micro in 0..cfg.grad_accum {
            // rank r draws the global step's micro-batches r, r + ranks, r + 2 ranks, ...: the
            // ranks together draw what one process with `grad_accum x ranks` draws
            let global = micro * ranks + rank;
            let batch = make_batch(source, cfg, self.step, global, channels, latent, schedule)?;
            let loss = inpainting_loss(
                &self.models,
                &self.models.trainable,
                &batch,
                &self.device,
                train_text,
            )?;
            loss_sum += loss.clone().into_scalar::<f64>();
            let loss = loss.div_scalar(cfg.grad_accum as f64);
            let grads = GradientsParams::from_grads(loss.backward(), &self.models.trainable);
            accum.accumulate(&self.models.trainable, grads);
        }
        let mut loss = loss_sum / cfg.grad_accum as f64;
        let mut grads = accum.grads();
        let exchange = std::time::Instant::now();
        let exchanged_values =
            mean_gradients(&self.models.trainable, &mut grads, self.sync.as_ref())?;
        if ranks > 1 {
            // every rank logs, and decides on a non-finite step from, the global batch's loss
            let mut mean = [loss as f32];
            self.sync.mean(&mut mean)?;
            loss = f64::from(mean[0]);
        }
        let exchange_seconds = if ranks > 1 {
            exchange.elapsed().as_secs_f64()
        } else {
            0.0
        };
        let norm = clip_global_norm(&self.models.trainable, &mut grads, cfg.clip_grad_norm);
        self.step += 1;
        let skipped = !(loss.is_finite() && norm.is_finite());
        if skipped {
            self.nan_streak += 1;
            tracing::warn!(
                step = self.step,
                loss,
                grad_norm = norm,
                "non-finite step skipped"
            );
            if self.nan_streak >= MAX_NAN_STEPS {
                return Err(FinetuneError::Diverged {
                    step: self.step,
                    message: format!(
                        "{MAX_NAN_STEPS} consecutive non-finite losses or gradients \
                         (last loss {loss}, gradient norm {norm}); lower the learning rate \
                         or resume from the last checkpoint"
                    ),
                });
            }
        } else {
            self.nan_streak = 0;
            let t = self.models.trainable.clone();
            self.models.trainable = self.optimizer.step(cfg.lr, t, grads);
        }
        self.losses.push(loss);
        Ok(StepStats {
            step: self.step,
            loss,
            grad_norm: norm,
            skipped,
            exchange_seconds,
            exchanged_values,
        })
    }

    /// Writes a checkpoint atomically (module record with ids, AdamW state, step, losses,
    /// non-finite streak, recipe; [`checkpoint`]).
    pub fn save_checkpoint(&self, path: &Path) -> Result<(), FinetuneError> {
        self.save_checkpoint_with(path, serde_json::Value::Null)
    }

    /// [`Self::save_checkpoint`] with the caller's own state `extra` (read back by
    /// [`Self::resume_with_extra`]). In a data-parallel run rank 0 alone writes, recording
    /// the number of ranks, and every rank waits for it.
    pub fn save_checkpoint_with(
        &self,
        path: &Path,
        extra: serde_json::Value,
    ) -> Result<(), FinetuneError> {
        if self.sync.rank() == 0 {
            self.write_checkpoint(path, extra)?;
        }
        self.sync.barrier()
    }

    fn write_checkpoint(&self, path: &Path, extra: serde_json::Value) -> Result<(), FinetuneError> {
        let bad = |m: String| FinetuneError::Invalid {
            path: path.to_path_buf(),
            message: m,
        };
        let model = self
            .models
            .trainable
            .clone()
            .into_record()
            .into_bytes()
            .map_err(|e| bad(format!("model record: {e}")))?;
        let optimizer = self
            .optimizer
            .into_bytes()
            .map_err(|e| bad(format!("optimizer record: {e}")))?;
        checkpoint::save(
            path,
            &CheckpointParts {
                meta: CheckpointMeta {
                    step: self.step,
                    config_toml: checkpoint::config_to_toml(&self.config, path)?,
                    nan_streak: self.nan_streak,
                    extra,
                    loss_bits: self.losses.iter().map(|l| l.to_bits()).collect(),
                    ranks: self.sync.ranks(),
                },
                model: model.to_vec(),
                optimizer: optimizer.to_vec(),
            },
        )
    }

    /// Continues a run from a checkpoint: `models` must be the same base prior (loaded
    /// fresh); the adapters, the optimiser state, the step, the loss log and the non-finite
    /// streak are restored, and the random stream of the next step is the one an
    /// uninterrupted run would draw (a pure function of the seed and the step).
    pub fn resume(
        models: PriorModels,
        path: &Path,
        device: &Device,
    ) -> Result<Self, FinetuneError> {
        Self::resume_with_extra(models, path, device).map(|(t, _)| t)
    }

    /// [`Self::resume`], also returning the caller's state saved with
    /// [`Self::save_checkpoint_with`] (`null` when none).
    pub fn resume_with_extra(
        models: PriorModels,
        path: &Path,
        device: &Device,
    ) -> Result<(Self, serde_json::Value), FinetuneError> {
        Self::resume_with_sync(models, path, device, Box::new(SingleProcess))
    }

    /// [`Self::resume_with_extra`] as one rank of a data-parallel run ([`Self::with_sync`]).
    /// A checkpoint written by another number of ranks is refused, naming both counts: the
    /// global batch, and so the run, would differ.
    pub fn resume_with_sync(
        models: PriorModels,
        path: &Path,
        device: &Device,
        sync: Box<dyn GradSync + Send>,
    ) -> Result<(Self, serde_json::Value), FinetuneError> {
        let mut parts = checkpoint::load(path)?;
        let extra = std::mem::take(&mut parts.meta.extra);
        let bad = |m: String| FinetuneError::Invalid {
            path: path.to_path_buf(),
            message: m,
        };
        if parts.meta.ranks != sync.ranks() {
            return Err(bad(format!(
                "written by a run of {} rank(s), and this run has {}: resume with {} \
                 (the global batch is the per-rank batch times the ranks)",
                parts.meta.ranks,
                sync.ranks(),
                parts.meta.ranks
            )));
        }
        let mut t = Self::new(models, parts.meta.config(path)?, device)?.with_sync(sync);
        let record = ModuleRecord::from_bytes(Bytes::from_bytes_vec(parts.model))
            .map_err(|e| bad(format!("model record: {e}")))?;
        t.models.trainable = t
            .models
            .trainable
            .clone()
            .try_load_record(record)
            .map_err(|e| bad(format!("model record does not fit this prior: {e}")))?;
        t.optimizer = optimizer(&t.config)
            .from_bytes(Bytes::from_bytes_vec(parts.optimizer))
            .map_err(|e| bad(format!("optimizer record: {e}")))?;
        t.step = parts.meta.step;
        t.nan_streak = parts.meta.nan_streak;
        t.losses = parts
            .meta
            .loss_bits
            .iter()
            .map(|b| f64::from_bits(*b))
            .collect();
        Ok((t, extra))
    }

    /// Writes the adapters as a diffusers/PEFT LoRA file (`unet.*` and `text_encoder.*`
    /// keys, `lora_A`/`lora_B`, alpha metadata) that diffusers' `load_lora_weights` and
    /// [`gb_diffusion::lora`] read.
    pub fn export_lora(&self, path: &Path) -> Result<usize, FinetuneError> {
        let err = |e: gb_diffusion::lora::LoraError| {
            FinetuneError::diffusion(format!("LoRA export to {}", path.display()), e)
        };
        let unet_section = if self.models.unet_config.use_linear_projection {
            keymap::UNET_LINEAR_PROJECTION
        } else {
            keymap::UNET
        };
        let unet = collect_lora(&self.models.trainable.unet).map_err(err)?;
        let text = collect_lora(&self.models.trainable.text_encoder).map_err(err)?;
        let count = unet.len() + text.len();
        let mut exports = vec![LoraExport {
            component: LoraComponent::Unet,
            section: &unet_section,
            factors: unet,
            alpha: self.config.alpha,
        }];
        if !text.is_empty() {
            exports.push(LoraExport {
                component: LoraComponent::TextEncoder,
                section: &keymap::TEXT_ENCODER,
                factors: text,
                alpha: self.config.alpha,
            });
        }
        write_peft_lora(path, &exports).map_err(err)?;
        Ok(count)
    }

    /// The device the run trains on.
    pub fn device(&self) -> &Device {
        &self.device
    }
}
