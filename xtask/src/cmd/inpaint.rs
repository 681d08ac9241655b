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
//!   time; the reference term's loss and rays, and the geometry term's, where the run has them);
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

use gb_inpaint::run::{run as run_spec, RunSpec, RunSummary};

/// Arguments of `cargo xtask inpaint`: the library's [`RunSpec`], whose fields are the flags.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The run.
    #[command(flatten)]
    pub spec: RunSpec,
}

/// Runs the command: one call of [`gb_inpaint::run::run`], then the means on stdout.
pub fn run(args: Args) -> anyhow::Result<()> {
    // progress bars are on from the command line (`RunSpec::progress` is skipped to true)
    let spec = RunSpec {
        program: crate::program_name().into(),
        ..args.spec
    };
    let summary: RunSummary = run_spec(&spec)?;
    println!("{}", serde_json::to_string_pretty(&summary.mean)?);
    println!(
        "wrote {} and {}",
        spec.out.join("metrics.json").display(),
        spec.out.join(&summary.report).display()
    );
    if summary.export.is_none() {
        println!(
            "for nerfstudio: {} export --run {}",
            crate::program_name(),
            gb_inpaint::run::shell_quote(&spec.out.display().to_string())
        );
    }
    Ok(())
}
