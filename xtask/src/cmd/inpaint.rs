//! `cargo xtask inpaint`: object removal with a NeRF, guided by a diffusion prior (GB-NeRF and
//! its baselines, `gb_inpaint`).
//!
//! ```text
//! cargo xtask inpaint [--scene DIR] [--method M] [--preset P] [--prior none|tiny|DIR|HUB_ID]
//!     [--lora FILE] [--prompt P] [--negative-prompt N] [--normal-prompt G] [--device D]
//!     [--precision f32|f16] [--out DIR] [--resume] [--steps N] [--seed N]
//!     [--depth sparse|dense|none] [--personalize STEPS] [--baseline DIR] [--weights DIR]
//!     [--orbit-frames N] [--reference VIEW=IMAGE|auto ...] [--export full|none] [--probe]
//! ```
//!
//! - `--method`: a built-in method (`configs/methods/`: gb-nerf, gb-nerf-unseen, bsd,
//!   mvip-nerf, spin-nerf-sds, csd, none, pre-inpainted) or a `.toml` file (a method file, or
//!   a run's `config.toml`, whose `[method]` table is used). Default `gb-nerf-unseen`, the
//!   method the README recommends; `none` is the no-prior baseline.
//! - `--preset`: fast, balanced, paper, or a `.toml` file (a preset, or a run's
//!   `config.toml`, whose `[preset]` table is used).
//! - `--prior`: `tiny` (the built-in prior, `assets/tiny-prior`, the default), a
//!   diffusers-layout folder, a Hugging Face hub id, or `none` (implies `--method none` unless
//!   a method is given). Methods without guidance ignore it.
//! - `--lora`: a LoRA file to attach (default: `PRIOR/pytorch_lora_weights.safetensors` for
//!   methods with `use_lora = true`).
//! - Prompts: the method's templates filled with the scene's captions (`scene.json` of a
//!   procedural scene), unless given.
//!
//! Everything a user can get wrong (method file, prior folder, LoRA file, a scene without
//! masks, missing pre-inpainted images) is reported before training starts; errors exit 2.
//!
//! Outputs under `--out`:
//! - `scene/` (only without `--scene`): the generated procedural `stairs` scene;
//! - `config.toml`: the resolved run (command to reproduce it, prior, LoRA, prompts, preset,
//!   method);
//! - `checkpoint.bin`: the atomic training checkpoint; `--resume` continues from it exactly
//!   (the resumed run's `metrics.json` equals an uninterrupted run's but for wall times),
//!   refuses one of another preset, method, prompts or prior (exit 2, naming the field;
//!   `--steps` may grow), and without one starts afresh with a warning;
//! - `train_log.jsonl`: one line per step (loss, PSNR, learning rate, skipped, and per
//!   guidance term: t, w(t), lambda * s(t), latent gradient norm, U-Net calls and batch, rays,
//!   time);
//! - `renders/NAME_{rgb,depth,normal}.png`: every test view;
//! - `metrics.json`: per-view and mean PSNR / SSIM over the whole image and over the mask's
//!   bounding box (when the view has a mask), disparity PSNR where ground-truth depth exists
//!   (gb-eval's 8-bit D-PSNR convention), timings of guided and unguided steps; and under
//!   `eval` every gb-eval metric that applies (`gb_inpaint::metrics`: PSNR / SSIM full, bbox
//!   and mask, ST-LPIPS with the weights of `--weights` or `$GB_TEST_DATA/weights`, D-PSNR,
//!   FID / D-FID from 8 test views, BRISQUE, NIMA), with the reason of each unavailable one;
//! - `export/` (only with `--export full`; `cargo xtask export --run OUT` writes it later from
//!   the checkpoint): the inpainted training views (RGB, 16-bit depth), `transforms.json` and
//!   the orbit's `camera_path.json` for nerfstudio (`gb_inpaint::export`);
//! - `orbit.gif`: the trained field along a closed path through the input cameras, at half
//!   the training resolution (`--orbit-frames`, default 24; 0 for none; `gb_inpaint::gif`);
//! - `probe/` (only with `--probe`): per test view, the mask box's render, truth,
//!   disparities, signed depth error and normals (`NAME_probe.png`), the weights along four
//!   hidden rays (`NAME_rays.svg`) and `probe.json` (`gb_inpaint::run::probe`);
//! - `report.html` (+ `report/`): ground truth, our render, the baseline (`--baseline DIR`,
//!   another run's folder; else the masked input, said so) and the difference per test view
//!   (masked training views for a scene without test views), the orbit, the metric table
//!   and the training curves as SVG (`gb_inpaint::report`).

use std::path::PathBuf;

use gb_core::{BackendKind, Precision};
use gb_inpaint::run::{run as run_spec, RunSpec, RunSummary};
use gb_inpaint::PromptOverrides;
use gb_nerf::train::DepthSupervision;

/// Arguments of `cargo xtask inpaint`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene folder (LLFF / SPIn-NeRF or Blender layout). Default: generate the procedural
    /// `stairs` scene into OUT/scene.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Method: gb-nerf-unseen (default, the recommended one), gb-nerf (the paper), bsd,
    /// mvip-nerf, spin-nerf-sds, csd, none, pre-inpainted, or a .toml file.
    #[arg(long)]
    pub method: Option<String>,
    /// Preset name (fast, balanced, paper) or a path to a TOML config.
    #[arg(long, default_value = "fast")]
    pub preset: String,
    /// The diffusion prior: tiny (default), a diffusers folder, a hub id, or none.
    #[arg(long)]
    pub prior: Option<String>,
    /// A LoRA file (.safetensors) to attach to the prior's U-Net and text encoder.
    #[arg(long)]
    pub lora: Option<PathBuf>,
    /// Appearance prompt (RGB guidance).
    #[arg(long)]
    pub prompt: Option<String>,
    /// Negative prompt of the RGB guidance.
    #[arg(long)]
    pub negative_prompt: Option<String>,
    /// Geometry prompt (normal-map guidance).
    #[arg(long)]
    pub normal_prompt: Option<String>,
    /// Output folder.
    #[arg(long, default_value = "out/inpaint")]
    pub out: PathBuf,
    /// Compute backend: ndarray, flex or wgpu.
    #[arg(long, value_enum)]
    pub device: Option<BackendKind>,
    /// The prior's precision: f16 (half-precision weights and activations; norms, softmax
    /// and the gradient to the NeRF in f32) or f32. Default: f16 on a GPU card, f32 on the
    /// CPU backends and on lavapipe. ndarray has f32 only.
    #[arg(long, value_enum)]
    pub precision: Option<Precision>,
    /// Continue from OUT/checkpoint.bin when it exists.
    #[arg(long)]
    pub resume: bool,
    /// Override the preset's number of training steps (at least 1).
    #[arg(long, value_parser = gb_core::cli::at_least_one)]
    pub steps: Option<usize>,
    /// Override the preset's training seed (`[train] seed`: ray batches, the guidance's
    /// timesteps and noise); `bench quality --seeds` repeats a grid over seeds with it.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Depth supervision: sparse (COLMAP's points in `sparse/0`, the preset default), dense
    /// (per-pixel depth maps, an oracle real captures lack) or none.
    #[arg(long)]
    pub depth: Option<DepthSupervision>,
    /// Personalise the prior to the scene first: fine-tune a per-scene LoRA for this many
    /// steps on the training views' unmasked patches (cached in OUT/personalize/; 0: off;
    /// default: the method's `[personalize] steps`).
    #[arg(long, value_name = "STEPS")]
    pub personalize: Option<usize>,
    /// A reference view, repeatable: VIEW (a training view's file name) with the object
    /// removed, as IMAGE (a clean plate or any 2D fill, at the scene's image size). It
    /// supervises the colour inside VIEW's mask and is carried to the other views through
    /// the rendered depth; the guidance acts only where no reference reaches. `auto`: the
    /// middle masked training view filled by `fill --with fsr`, written into OUT.
    #[arg(long = "reference", value_name = "VIEW=IMAGE|auto")]
    pub references: Vec<String>,
    /// The nerfstudio export of the inpainted scene, `OUT/export/`: full (every training view
    /// rendered, with depth and cameras) or none, the default (on a real capture it takes
    /// about as long as the training on a CPU; `cargo xtask export --run OUT` writes it later
    /// from the checkpoint).
    #[arg(long, default_value = "none", value_name = "full|none")]
    pub export: gb_inpaint::export::ExportMode,
    /// Another run's output folder (or its `renders/`): its test-view renders are the
    /// baseline column of `report.html` (default: the masked input, said so on the page).
    #[arg(long)]
    pub baseline: Option<PathBuf>,
    /// Folder of metric weights (ST-LPIPS, FID, BRISQUE, NIMA; default
    /// `$GB_TEST_DATA/weights` when it exists). Metrics without weights are reported
    /// unavailable, with the reason.
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Frames of the orbit animation `orbit.gif` (0: none).
    #[arg(long, default_value_t = 24)]
    pub orbit_frames: usize,
    /// Also write `OUT/probe/`: per test view, the hidden region's depth error against the
    /// truth, its normals and the weights along a few hidden rays (a diagnosis of the
    /// filled geometry; needs a scene with true depth).
    #[arg(long)]
    pub probe: bool,
}

impl Args {
    /// The library's run specification of these flags.
    pub fn spec(&self) -> RunSpec {
        RunSpec {
            scene: self.scene.clone(),
            method: self.method.clone(),
            preset: self.preset.clone(),
            prior: self.prior.clone(),
            lora: self.lora.clone(),
            prompts: PromptOverrides {
                appearance: self.prompt.clone(),
                negative: self.negative_prompt.clone(),
                geometry: self.normal_prompt.clone(),
            },
            device: self.device.unwrap_or_default(),
            precision: self.precision,
            seed: self.seed,
            steps: self.steps,
            depth: self.depth,
            personalize: self.personalize,
            references: self.references.clone(),
            out: self.out.clone(),
            resume: self.resume,
            baseline: self.baseline.clone(),
            weights: self.weights.clone(),
            orbit_frames: self.orbit_frames,
            export: self.export,
            probe: self.probe,
            progress: true,
            program: crate::program_name().into(),
        }
    }
}

/// Runs the command: one call of [`gb_inpaint::run::run`], then the means on stdout.
pub fn run(args: Args) -> anyhow::Result<()> {
    let summary: RunSummary = run_spec(&args.spec())?;
    println!("{}", serde_json::to_string_pretty(&summary.mean)?);
    println!(
        "wrote {} and {}",
        args.out.join("metrics.json").display(),
        args.out.join(&summary.report).display()
    );
    if summary.export.is_none() {
        println!(
            "for nerfstudio: {} export --run {}",
            crate::program_name(),
            gb_inpaint::run::shell_quote(&args.out.display().to_string())
        );
    }
    Ok(())
}
