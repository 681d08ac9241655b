//! `cargo xtask finetune`: the geometric prior (GB-NeRF's LoRA on RGB / normal pairs), and
//! the tiny built-in prior's recipe.
//!
//! - `--diode DIR --base MODEL`: LoRA fine-tuning on a DIODE-layout folder (`val/` is the
//!   held-out set when present);
//! - `--synthetic --base MODEL`: the same on procedural RGB / normal pairs;
//! - `--pairs DIR --base MODEL`: on a folder written by `cargo xtask scene --pairs`;
//! - `--synthetic --from-scratch [--recipe configs/tiny-prior]`: the tiny prior's whole
//!   recipe (autoencoder, base prior from scratch, LoRA), into `--out`.
//!
//! Outputs (see `gb_finetune::run`): `checkpoint.gbft` (`--resume` continues exactly),
//! `config.toml`, `train_log.jsonl`, `validation.jsonl`, `pytorch_lora_weights.safetensors`.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use gb_core::BackendKind;
use gb_diffusion::pipeline::SdComponents;
use gb_finetune::captions::CaptionMode;
use gb_finetune::diode::{DiodeDataset, DiodeSplit};
use gb_finetune::run::{run_finetune_ranked, RunData, RunOptions};
use gb_finetune::sample::PairSource;
use gb_finetune::synthetic::SyntheticPairs;
use gb_finetune::tiny_prior::{run_recipe, SyntheticData};
use gb_finetune::train::grad_sync::{launched_ranks, GradSync, SingleProcess};
use gb_finetune::train::{FinetuneConfig, PriorModels};
use gb_finetune::validate_only::validate_prior;

use gb_grid::emit::Engine;
use gb_grid::finetune_job::{job_args, write_finetune_jobs, FinetuneJob};

use super::job_resources::JobResources;

/// Arguments of `cargo xtask finetune`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// DIODE folder (`train/` and optionally `val/`, each `{indoors,outdoor}/scene_*/scan_*/`).
    #[arg(long, conflicts_with_all = ["synthetic", "pairs"])]
    pub diode: Option<PathBuf>,
    /// Use procedural RGB / normal pairs (stairs and fence, seeds 1-6; held out: 101-102).
    #[arg(long)]
    pub synthetic: bool,
    /// A folder of pairs written by `cargo xtask scene --pairs` (`captions.jsonl`).
    #[arg(long, conflicts_with = "synthetic")]
    pub pairs: Option<PathBuf>,
    /// Base inpainting prior: a diffusers folder, a hub id, or `tiny` (the built-in prior).
    #[arg(long)]
    pub base: Option<String>,
    /// Run the tiny prior's recipe from scratch (needs `--synthetic`).
    #[arg(long, requires = "synthetic")]
    pub from_scratch: bool,
    /// Recipe folder for `--from-scratch`.
    #[arg(long, default_value = "configs/tiny-prior")]
    pub recipe: PathBuf,
    /// JSONL captions (`{"image": ..., "caption": ...}`) for DIODE images.
    #[arg(long)]
    pub captions: Option<PathBuf>,
    /// Prompt mode: captions (default), identifiers, normal-only.
    #[arg(long)]
    pub mode: Option<CaptionMode>,
    /// A TOML file with any `FinetuneConfig` fields (flags below override it).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Optimiser steps.
    #[arg(long)]
    pub steps: Option<usize>,
    /// Images per micro-batch.
    #[arg(long)]
    pub batch: Option<usize>,
    /// Micro-batches per step.
    #[arg(long)]
    pub grad_accum: Option<usize>,
    /// Learning rate.
    #[arg(long)]
    pub lr: Option<f64>,
    /// LoRA rank.
    #[arg(long)]
    pub rank: Option<usize>,
    /// LoRA alpha.
    #[arg(long)]
    pub alpha: Option<f64>,
    /// Training resolution (default: the prior's native resolution).
    #[arg(long)]
    pub resolution: Option<usize>,
    /// Seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// No LoRA on the text encoder.
    #[arg(long)]
    pub no_text_encoder: bool,
    /// Checkpoint every N steps.
    #[arg(long)]
    pub checkpoint_every: Option<usize>,
    /// Validate every N steps (0: at the end only).
    #[arg(long)]
    pub validate_every: Option<usize>,
    /// Held-out samples per validation.
    #[arg(long)]
    pub validation_samples: Option<usize>,
    /// Samples averaged per hole for the posterior-mean validation score (default 1).
    #[arg(long)]
    pub validation_average: Option<usize>,
    /// Only validate `--base` (with `--lora` when given, else the folder's own
    /// `pytorch_lora_weights.safetensors` when present) on the held-out pairs, write
    /// `OUT/validation.json`, and exit.
    #[arg(long)]
    pub validate_only: bool,
    /// A LoRA file for `--validate-only`.
    #[arg(long, requires = "validate_only")]
    pub lora: Option<PathBuf>,
    /// DDIM steps of the validation sampler.
    #[arg(long)]
    pub validation_ddim_steps: Option<usize>,
    /// Validation samples keep the known region (RePaint-style blending after each step).
    #[arg(long)]
    pub validation_blend_known: bool,
    /// Compute backend: ndarray, flex or wgpu.
    #[arg(long, default_value = "flex", value_enum)]
    pub device: BackendKind,
    /// Output folder.
    #[arg(long, default_value = "out/finetune")]
    pub out: PathBuf,
    /// Continue from OUT/checkpoint.gbft.
    #[arg(long)]
    pub resume: bool,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Data-parallel LoRA fine-tuning: `mpi` (each of `mpirun -n N`'s ranks trains on its
    /// share of every global batch, `batch x grad_accum x N`; needs the `mpi` feature). The
    /// default is `mpi` when an MPI launcher started this process among several ranks.
    #[arg(long, value_enum)]
    pub data_parallel: Option<DataParallel>,
    /// Only write the job files of a data-parallel run of this command line into OUT, and
    /// exit: slurm (`finetune-slurm.sh`), kubernetes (a Kubeflow `MPIJob`,
    /// `finetune-mpijob.yaml`); comma-separated, with --ranks.
    #[arg(long, value_delimiter = ',', requires = "ranks")]
    pub emit: Option<Vec<Engine>>,
    /// Ranks (MPI processes) of the emitted jobs, at least 2.
    #[arg(long, requires = "emit")]
    pub ranks: Option<usize>,
    /// The emitted jobs' image, cores and GPUs per rank.
    #[command(flatten)]
    pub jobs: JobResources,
}

/// `--emit`: the job files of a data-parallel run of this command line
/// ([`gb_grid::finetune_job`]).
fn emit_jobs(args: &Args, engines: &[Engine]) -> anyhow::Result<()> {
    let ranks = args.ranks.unwrap_or(0);
    if ranks < 2 {
        bail!("--ranks {ranks}: a data-parallel job needs at least 2 ranks");
    }
    if args.from_scratch || args.validate_only {
        bail!("--emit: only LoRA fine-tuning runs data-parallel, not --from-scratch or --validate-only");
    }
    let argv: Vec<String> = std::env::args()
        .skip_while(|a| a != "finetune")
        .skip(1)
        .collect();
    let workdir = std::env::current_dir().context("reading the working folder")?;
    let job = FinetuneJob {
        args: job_args(&argv),
        ranks,
        workdir: workdir.clone(),
        out: workdir.join(&args.out),
    };
    for path in write_finetune_jobs(&job, engines, &args.jobs.emit_options())? {
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// How the ranks of a fine-tuning run share the work.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum DataParallel {
    /// One process.
    None,
    /// Ranks launched by `mpirun`, `srun` or an MPI operator, exchanging gradients over MPI.
    Mpi,
}

/// The gradient exchange the command line asks for ([`Args::data_parallel`]), with one clear
/// line for a launch it cannot serve.
fn grad_sync(args: &Args) -> anyhow::Result<Box<dyn GradSync + Send>> {
    let launched = launched_ranks(|k| std::env::var(k).ok()).filter(|&n| n > 1);
    let mpi = match args.data_parallel {
        Some(DataParallel::Mpi) => true,
        Some(DataParallel::None) => {
            if let Some(n) = launched {
                bail!(
                    "--data-parallel none, but an MPI launcher started {n} ranks: each would \
                     train alone into {}; use --data-parallel mpi, or start one process",
                    args.out.display()
                );
            }
            false
        }
        None => launched.is_some(),
    };
    if !mpi {
        return Ok(Box::new(SingleProcess));
    }
    if args.from_scratch || args.validate_only {
        bail!(
            "--data-parallel mpi: only LoRA fine-tuning (--diode, --synthetic or --pairs, \
             with --base) runs data-parallel, not --from-scratch or --validate-only"
        );
    }
    mpi_sync(launched)
}

#[cfg(feature = "mpi")]
fn mpi_sync(_launched: Option<usize>) -> anyhow::Result<Box<dyn GradSync + Send>> {
    let sync = gb_finetune::train::mpi_sync::MpiSync::init()?;
    tracing::info!(rank = sync.rank(), ranks = sync.ranks(), "MPI initialised");
    Ok(Box::new(sync))
}

#[cfg(not(feature = "mpi"))]
fn mpi_sync(launched: Option<usize>) -> anyhow::Result<Box<dyn GradSync + Send>> {
    let how = launched
        .map(|n| format!(" (an MPI launcher started {n} ranks)"))
        .unwrap_or_default();
    bail!(
        "--data-parallel mpi{how}: this gb-nerf was built without the `mpi` feature; rebuild \
         it with `cargo build --release -p xtask --features mpi` (needs Debian's \
         libopenmpi-dev, openmpi-bin and libclang-dev)"
    )
}

fn config_of(args: &Args, native: usize) -> anyhow::Result<FinetuneConfig> {
    let mut cfg = match &args.config {
        Some(p) => {
            let text =
                std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            FinetuneConfig::from_toml(&text, p)?
        }
        None => FinetuneConfig {
            resolution: native,
            ..FinetuneConfig::default()
        },
    };
    if let Some(v) = args.mode {
        cfg.mode = v;
    }
    macro_rules! set {
        ($($f:ident),*) => { $( if let Some(v) = args.$f { cfg.$f = v; } )* };
    }
    set!(
        steps,
        batch,
        grad_accum,
        lr,
        rank,
        alpha,
        resolution,
        seed,
        checkpoint_every,
        validate_every,
        validation_samples,
        validation_average,
        validation_ddim_steps
    );
    if args.no_text_encoder {
        cfg.train_text_encoder = false;
    }
    if args.validation_blend_known {
        cfg.validation_blend_known = true;
    }
    cfg.validate()?;
    Ok(cfg)
}

/// Runs the command.
pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(engines) = &args.emit {
        return emit_jobs(&args, engines);
    }
    let sync = grad_sync(&args)?;
    let device = args.device.autodiff_device();
    let plain = args.device.device();
    if args.from_scratch {
        let summary = run_recipe(
            &args.recipe,
            &args.out,
            &device,
            &plain,
            args.resume,
            !args.quiet,
        )?;
        println!("{}", serde_json::to_string_pretty(&summary)?);
        return Ok(());
    }
    let base = args
        .base
        .as_deref()
        .context("--base MODEL is required (a diffusers inpainting folder, a hub id, or `tiny`)")?;
    let base_dir = gb_diffusion::checkpoint::resolve_prior(base)?;
    let (train, val): (Box<dyn PairSource>, Option<Box<dyn PairSource>>) =
        if let Some(d) = &args.diode {
            let train = DiodeDataset::open(d, DiodeSplit::Train, args.captions.as_deref())?;
            let val = if d.join("val").is_dir() {
                Some(Box::new(DiodeDataset::open(
                    d,
                    DiodeSplit::Val,
                    args.captions.as_deref(),
                )?) as Box<dyn PairSource>)
            } else {
                None
            };
            (Box::new(train), val)
        } else if args.synthetic {
            let (train, val) = default_synthetic()?;
            (Box::new(train), Some(Box::new(val)))
        } else if let Some(p) = &args.pairs {
            (Box::new(SyntheticPairs::open(p)?), None)
        } else {
            bail!("choose the data: --diode DIR, --synthetic or --pairs DIR");
        };
    if args.validate_only {
        let val = val.context(
            "--validate-only needs held-out data (--synthetic, or --diode DIR with val/)",
        )?;
        return validate_only(&args, &base_dir, val.as_ref(), &plain);
    }
    let models = PriorModels::load(&base_dir, &device)?;
    let native = models.unet_config.native_resolution(models.vae_factor);
    let cfg = config_of(&args, native)?;
    let rank = sync.rank();
    let data = RunData {
        train: train.as_ref(),
        val: val.as_deref(),
    };
    let summary = run_finetune_ranked(
        models,
        cfg,
        data,
        &device,
        &plain,
        &RunOptions {
            out: args.out.clone(),
            resume: args.resume,
            progress: !args.quiet,
            vae_config_json: None,
        },
        sync,
    )?;
    if rank == 0 {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    }
    Ok(())
}

/// `--validate-only`: the base with and without its LoRA, and the fill baselines, on the
/// held-out pairs ([`validate_prior`]), written to `OUT/validation.json`.
fn validate_only(
    args: &Args,
    base_dir: &Path,
    val: &dyn PairSource,
    plain: &burn::tensor::Device,
) -> anyhow::Result<()> {
    let prior = SdComponents::load_inpainting(base_dir, plain)
        .with_context(|| format!("loading the prior {}", base_dir.display()))?;
    let native = prior.unet_config.native_resolution(prior.vae_factor());
    let mut cfg = config_of(args, native)?;
    if args.config.is_none() && args.validation_samples.is_none() {
        cfg.validation_samples = val.len();
    }
    let report = validate_prior(&prior, base_dir, args.lora.as_deref(), val, &cfg, plain)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let path = args.out.join("validation.json");
    gb_core::write_atomic(&path, &serde_json::to_vec_pretty(&report)?)
        .with_context(|| format!("writing {}", path.display()))?;
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}

/// The procedural pairs `--synthetic` trains and validates on: the built-in prior's
/// ([`SyntheticData::builtin`]).
pub fn default_synthetic() -> anyhow::Result<(SyntheticPairs, SyntheticPairs)> {
    Ok(SyntheticData::builtin().generate()?)
}

#[cfg(all(test, not(feature = "mpi")))]
mod tests {
    use super::*;

    #[test]
    fn an_mpi_launch_of_a_build_without_the_feature_says_how_to_rebuild() {
        let e = mpi_sync(Some(2)).err().unwrap().to_string();
        assert!(
            e.starts_with("--data-parallel mpi (an MPI launcher started 2 ranks)"),
            "{e}"
        );
        assert!(e.contains("--features mpi") && !e.contains('\n'), "{e}");
    }
}
