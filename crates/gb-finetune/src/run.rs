//! A whole fine-tuning run on disk: resume or start, train with a progress bar, checkpoint
//! atomically, validate against the untouched base and the fill baselines, and export.
//!
//! Files under the output folder:
//! - `checkpoint.gbft`: the latest checkpoint ([`crate::train::checkpoint`]); `resume`
//!   continues from it exactly: a run killed after a checkpoint and resumed writes the same
//!   adapters bit for bit, and the same `train_log.jsonl` and `validation.jsonl`, as an
//!   uninterrupted one;
//! - `config.toml`: the resolved recipe;
//! - `train_log.jsonl`: one `{"step", "loss"}` line per completed step (rewritten at each
//!   checkpoint, so it always matches the checkpoint);
//! - `validation.jsonl`: one line per validation pass, `{"step", "report"}`; step 0 is the
//!   base prior without any update. A fresh run starts the file anew; a resumed run drops
//!   the lines after its checkpoint's step (a validation pass runs before the checkpoint of
//!   its step, so the lines up to it are complete); the reports of the summary (base and
//!   final) are kept in the checkpoint, floats as bits, so a resumed run prints them too;
//! - LoRA runs: `pytorch_lora_weights.safetensors` (diffusers/PEFT format);
//!   full runs: `prior/`, a diffusers inpainting folder.

use std::io::Write;
use std::path::{Path, PathBuf};

use burn::tensor::Device;
use indicatif::{ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};

use crate::masks::MaskConfig;
use crate::sample::PairSource;
use crate::train::checkpoint::{exact_floats, from_exact_floats};
use crate::train::grad_sync::{trainable_values, GradSync, SingleProcess};
use crate::train::validate::{sampling_prior, validate, ValidationReport, ValidationSettings};
use crate::train::{FinetuneConfig, FinetuneTrainer, PriorModels, TrainTarget};
use crate::FinetuneError;

/// Where and how a run writes.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Output folder.
    pub out: PathBuf,
    /// Continue from `out/checkpoint.gbft` when it exists.
    pub resume: bool,
    /// Show a progress bar.
    pub progress: bool,
    /// The VAE config JSON to write with a full-run prior folder.
    pub vae_config_json: Option<serde_json::Value>,
}

/// What a run produced.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RunSummary {
    /// Steps completed.
    pub steps: usize,
    /// Mean loss of the first and the last 10% of steps.
    pub loss_start: f64,
    /// See `loss_start`.
    pub loss_end: f64,
    /// Seconds spent training in this process.
    pub train_seconds: f64,
    /// Steps per second in this process.
    pub steps_per_second: f64,
    /// Ranks of the run (1: one process).
    #[serde(default = "crate::train::checkpoint::one_rank")]
    pub ranks: usize,
    /// Seconds of `train_seconds` spent exchanging gradients with the other ranks.
    #[serde(default)]
    pub exchange_seconds: f64,
    /// Bytes of gradient each rank sends per step (and receives back averaged), against
    /// `trainable_bytes`, the adapters' size.
    #[serde(default)]
    pub exchanged_bytes_per_step: usize,
    /// Bytes of the values that train (`f32`): the adapters of a LoRA run.
    #[serde(default)]
    pub trainable_bytes: usize,
    /// Validation of the base (step 0) and of the final model.
    pub validation_base: Option<ValidationReport>,
    /// See `validation_base`.
    pub validation_final: Option<ValidationReport>,
    /// The exported LoRA file or prior folder.
    pub export: PathBuf,
}

/// The checkpoint file of a run folder.
pub fn checkpoint_path(out: &Path) -> PathBuf {
    out.join("checkpoint.gbft")
}

fn write_log(out: &Path, losses: &[f64]) -> Result<(), FinetuneError> {
    let mut text = String::new();
    for (i, l) in losses.iter().enumerate() {
        let loss = if l.is_finite() {
            serde_json::json!(l)
        } else {
            serde_json::Value::Null
        };
        text.push_str(&serde_json::json!({"step": i + 1, "loss": loss}).to_string());
        text.push('\n');
    }
    let path = out.join("train_log.jsonl");
    gb_core::write_atomic(&path, text.as_bytes()).map_err(|e| FinetuneError::io(&path, e))
}

/// Keeps the lines of `validation.jsonl` up to `step` (module docs).
fn validation_up_to(out: &Path, step: usize) -> Result<(), FinetuneError> {
    let path = out.join("validation.jsonl");
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(FinetuneError::io(&path, e)),
    };
    let mut kept = String::new();
    for line in text.lines() {
        let earlier = serde_json::from_str::<serde_json::Value>(line)
            .ok()
            .and_then(|v| v.get("step").and_then(|s| s.as_u64()))
            .is_some_and(|s| s as usize <= step);
        if earlier {
            kept.push_str(line);
            kept.push('\n');
        }
    }
    if kept.len() != text.len() {
        gb_core::write_atomic(&path, kept.as_bytes()).map_err(|e| FinetuneError::io(&path, e))?;
    }
    Ok(())
}

/// The validation reports of a run by step, kept in its checkpoints (floats as bits, see
/// [`crate::train::checkpoint::exact_floats`]) so that a resumed run's summary has the
/// base and final reports an uninterrupted run's has.
#[derive(Debug, Clone, Default)]
struct Validations(Vec<(usize, ValidationReport)>);

impl Validations {
    fn of(&self, step: usize) -> Option<ValidationReport> {
        self.0
            .iter()
            .find(|(s, _)| *s == step)
            .map(|(_, r)| r.clone())
    }

    fn to_checkpoint(&self) -> Result<serde_json::Value, FinetuneError> {
        let mut reports = Vec::with_capacity(self.0.len());
        for (s, r) in &self.0 {
            let r = serde_json::to_value(r).map_err(|e| FinetuneError::Invalid {
                path: PathBuf::from("(checkpoint validations)"),
                message: format!("step {s}: {e}"),
            })?;
            reports.push(serde_json::json!({"step": s, "report": exact_floats(r)}));
        }
        Ok(serde_json::json!({ "validations": reports }))
    }

    /// The reports kept in a checkpoint (`ckpt` names it in errors); a checkpoint without
    /// them has none, an unreadable one is an error rather than a lost report.
    fn from_checkpoint(extra: &serde_json::Value, ckpt: &Path) -> Result<Self, FinetuneError> {
        let bad = |message: String| FinetuneError::Invalid {
            path: ckpt.to_path_buf(),
            message,
        };
        let Some(reports) = extra.get("validations") else {
            return Ok(Self::default());
        };
        let reports = reports
            .as_array()
            .ok_or_else(|| bad("`validations` is not a list".into()))?;
        let mut out = Vec::with_capacity(reports.len());
        for (i, v) in reports.iter().enumerate() {
            let step = v["step"]
                .as_u64()
                .ok_or_else(|| bad(format!("validations[{i}]: no step")))?
                as usize;
            let report = serde_json::from_value(from_exact_floats(v["report"].clone()))
                .map_err(|e| bad(format!("validations[{i}] (step {step}): {e}")))?;
            out.push((step, report));
        }
        Ok(Self(out))
    }
}

fn append_validation(
    out: &Path,
    step: usize,
    report: &ValidationReport,
) -> Result<(), FinetuneError> {
    let path = out.join("validation.jsonl");
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .map_err(|e| FinetuneError::io(&path, e))?;
    writeln!(f, "{}", serde_json::json!({"step": step, "report": report}))
        .map_err(|e| FinetuneError::io(&path, e))
}

/// Validation settings of a recipe.
pub fn validation_settings(cfg: &FinetuneConfig) -> ValidationSettings {
    ValidationSettings {
        resolution: cfg.resolution,
        samples: cfg.validation_samples,
        ddim_steps: cfg.validation_ddim_steps,
        average: cfg.validation_average,
        blend_known: cfg.validation_blend_known,
        mode: cfg.mode,
        normals: !cfg.rgb_only,
        seed: cfg.seed ^ 0x7661_6c69,
        mask: MaskConfig {
            min_coverage: cfg.mask_min_coverage,
            max_coverage: cfg.mask_max_coverage,
            ..MaskConfig::default()
        },
    }
}

/// The samples a run trains on, and validates on (none: no validation).
#[derive(Clone, Copy)]
pub struct RunData<'a> {
    /// The training pairs.
    pub train: &'a dyn PairSource,
    /// The validation pairs.
    pub val: Option<&'a dyn PairSource>,
}

/// Runs (or resumes) a fine-tuning run. `models` must be loaded on `device` (autodiff);
/// `plain` is the same backend without autodiff, used for validation sampling.
pub fn run_finetune(
    models: PriorModels,
    config: FinetuneConfig,
    train: &dyn PairSource,
    val: Option<&dyn PairSource>,
    device: &Device,
    plain: &Device,
    opts: &RunOptions,
) -> Result<RunSummary, FinetuneError> {
    let data = RunData { train, val };
    run_finetune_ranked(
        models,
        config,
        data,
        device,
        plain,
        opts,
        Box::new(SingleProcess),
    )
}

/// [`run_finetune`] as one rank of a data-parallel run ([`crate::train::grad_sync`]): every
/// rank trains on its share of each global batch (`batch x grad_accum` per rank, times the
/// ranks), and rank 0 alone validates and writes the folder's files (the checkpoint, the
/// logs, the export) while the others wait for it at a barrier. A resume needs as many ranks
/// as the checkpoint's run had. Every rank returns the same summary, but only rank 0's has
/// the validation reports.
pub fn run_finetune_ranked(
    models: PriorModels,
    config: FinetuneConfig,
    data: RunData<'_>,
    device: &Device,
    plain: &Device,
    opts: &RunOptions,
    sync: Box<dyn GradSync + Send>,
) -> Result<RunSummary, FinetuneError> {
    let RunData { train, val } = data;
    let (rank, ranks) = (sync.rank(), sync.ranks());
    let writer = rank == 0;
    // the other ranks neither validate nor write
    let val = val.filter(|_| writer);
    if writer {
        std::fs::create_dir_all(&opts.out).map_err(|e| FinetuneError::io(&opts.out, e))?;
    }
    if ranks > 1 {
        tracing::info!(
            rank,
            ranks,
            "data-parallel: global batch {} = {} per rank ({} x {} micro-batches) x {ranks} ranks",
            config.batch * config.grad_accum * ranks,
            config.batch * config.grad_accum,
            config.batch,
            config.grad_accum
        );
    }
    let ckpt = checkpoint_path(&opts.out);
    let settings = validation_settings(&config);
    let mut reports = Validations::default();
    // every rank sees the same folder: each decides alike whether to resume
    let resuming = opts.resume && ckpt.is_file();
    sync.barrier()?;
    if !resuming && writer {
        let path = opts.out.join("validation.jsonl");
        match std::fs::remove_file(&path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(FinetuneError::io(&path, e))
            }
            _ => {}
        }
    }
    if let (Some(v), false) = (val, resuming) {
        let prior = sampling_prior(&models, &models.trainable, plain);
        let report = validate(&prior, v, &settings)?;
        tracing::info!(?report, "validation of the base prior (step 0)");
        append_validation(&opts.out, 0, &report)?;
        reports.0.push((0, report));
    }
    let mut trainer = if resuming {
        let (mut t, extra) = FinetuneTrainer::resume_with_sync(models, &ckpt, device, sync)?;
        if writer {
            validation_up_to(&opts.out, t.step)?;
        }
        reports = Validations::from_checkpoint(&extra, &ckpt)?;
        // `steps` and the checkpoint / validation cadence may change on resume (to extend a
        // run); any other difference would break the exact continuation, so the
        // checkpoint's recipe wins.
        let mut same = config.clone();
        same.steps = t.config.steps;
        same.checkpoint_every = t.config.checkpoint_every;
        same.validate_every = t.config.validate_every;
        if same == t.config {
            t.config.steps = config.steps.max(t.step);
            t.config.checkpoint_every = config.checkpoint_every;
            t.config.validate_every = config.validate_every;
        } else if t.config != config {
            tracing::warn!(
                "resuming with the checkpoint's recipe, which differs from the one given \
                 (only steps, checkpoint_every and validate_every may change on resume)"
            );
        }
        tracing::info!(step = t.step, "resumed from {}", ckpt.display());
        t
    } else {
        FinetuneTrainer::new(models, config, device)?.with_sync(sync)
    };
    let cfg = trainer.config.clone();
    let toml_text = toml::to_string(&cfg).map_err(|e| FinetuneError::Config {
        field: "config".into(),
        message: e.to_string(),
    })?;
    let cfg_path = opts.out.join("config.toml");
    if writer {
        gb_core::write_atomic(&cfg_path, toml_text.as_bytes())
            .map_err(|e| FinetuneError::io(&cfg_path, e))?;
    }

    let bar = if opts.progress && writer {
        let b = gb_core::progress::bar(cfg.steps as u64);
        b.set_style(
            ProgressStyle::with_template("{bar:30} {pos}/{len} {per_sec} eta {eta} {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        b.set_position(trainer.step as u64);
        b
    } else {
        ProgressBar::hidden()
    };
    let start = std::time::Instant::now();
    let first = trainer.step;
    let (mut exchange_seconds, mut exchanged_values) = (0.0, 0);
    while trainer.step < cfg.steps {
        let s = trainer.train_step(train)?;
        exchange_seconds += s.exchange_seconds;
        exchanged_values = s.exchanged_values;
        bar.set_position(s.step as u64);
        bar.set_message(format!("loss {:.4} |g| {:.3}", s.loss, s.grad_norm));
        let last = s.step == cfg.steps;
        // validation first: a checkpoint of step s implies that its validation line is
        // written, so a resumed run neither repeats nor misses one
        if let Some(v) = val {
            if last || (cfg.validate_every > 0 && s.step % cfg.validate_every == 0) {
                let prior = sampling_prior(&trainer.models, &trainer.models.trainable, plain);
                let report = validate(&prior, v, &settings)?;
                tracing::info!(step = s.step, ?report, "validation");
                append_validation(&opts.out, s.step, &report)?;
                reports.0.push((s.step, report));
            }
        }
        if last || (cfg.checkpoint_every > 0 && s.step % cfg.checkpoint_every == 0) {
            trainer.save_checkpoint_with(&ckpt, reports.to_checkpoint()?)?;
            if writer {
                write_log(&opts.out, &trainer.losses)?;
            }
        }
    }
    bar.finish_and_clear();
    let secs = start.elapsed().as_secs_f64();
    let done = trainer.step - first;
    let export = match cfg.target {
        TrainTarget::Lora => opts.out.join(gb_diffusion::lora::LORA_FILE_NAME),
        TrainTarget::Full => opts.out.join("prior"),
    };
    if writer {
        match cfg.target {
            TrainTarget::Lora => {
                let n = trainer.export_lora(&export)?;
                tracing::info!(adapters = n, "LoRA written to {}", export.display());
            }
            TrainTarget::Full => {
                let vae_json = opts
                    .vae_config_json
                    .clone()
                    .unwrap_or_else(|| serde_json::json!({"_class_name": "AutoencoderKL"}));
                trainer.models.save_folder(&export, &vae_json)?;
            }
        }
    }
    // the others return once the export is on disk
    trainer.sync().barrier()?;
    let n = trainer.losses.len();
    let k = (n / 10).max(1);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    Ok(RunSummary {
        steps: trainer.step,
        loss_start: mean(&trainer.losses[..k.min(n)]),
        loss_end: mean(&trainer.losses[n.saturating_sub(k)..]),
        train_seconds: secs,
        steps_per_second: if secs > 0.0 { done as f64 / secs } else { 0.0 },
        ranks,
        exchange_seconds,
        exchanged_bytes_per_step: exchanged_values * std::mem::size_of::<f32>(),
        trainable_bytes: trainable_values(&trainer.models.trainable) * std::mem::size_of::<f32>(),
        validation_base: reports.of(0),
        validation_final: reports.of(trainer.step).filter(|_| trainer.step > 0),
        export,
    })
}
