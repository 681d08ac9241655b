//! `cargo xtask inpaint`: object removal. With `--prior none` (the only prior available so
//! far) it is the no-prior baseline: the NeRF is trained on the unmasked pixels only and
//! fills the hole by interpolation. It renders every test view and writes `metrics.json`.
//!
//! Outputs under `--out`:
//! - `scene/` (only without `--scene`): the generated procedural `stairs` scene;
//! - `checkpoint.bin`: the atomic training checkpoint (`--resume` continues from it);
//! - `renders/NAME_{rgb,depth,normal}.png`: every test view;
//! - `metrics.json`: per-view and mean PSNR / SSIM over the whole image and over the mask's
//!   bounding box (when the view has a mask), disparity PSNR where ground-truth depth exists
//!   (gb-eval's 8-bit D-PSNR convention), training time, steps and field evaluations per ray.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context};
use gb_core::BackendKind;
use gb_eval::disparity::{disparity_to_rgb8, ScalarMap};
use gb_eval::{psnr, ssim, Region};
use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};
use gb_nerf::scene::{LoadOptions, Scene, Split};
use gb_nerf::train::data::prepare_view;
use gb_nerf::train::output::write_render_pngs;
use gb_nerf::train::{NerfConfig, Trainer};
use serde_json::json;

/// Arguments of `cargo xtask inpaint`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene folder (LLFF / SPIn-NeRF or Blender layout). Default: generate the procedural
    /// `stairs` scene into OUT/scene.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Preset name (fast, balanced, paper) or a path to a TOML config.
    #[arg(long, default_value = "fast")]
    pub preset: String,
    /// Output folder.
    #[arg(long, default_value = "out/inpaint")]
    pub out: PathBuf,
    /// Compute backend: ndarray, flex or wgpu.
    #[arg(long)]
    pub device: Option<BackendKind>,
    /// The prior guiding the hole: only `none` (no prior) is available so far.
    #[arg(long, default_value = "none")]
    pub prior: String,
    /// Continue from OUT/checkpoint.bin when it exists.
    #[arg(long)]
    pub resume: bool,
    /// Override the preset's number of training steps.
    #[arg(long)]
    pub steps: Option<usize>,
}

fn load_or_generate(args: &Args) -> anyhow::Result<Scene> {
    let dir = match &args.scene {
        Some(d) => d.clone(),
        None => {
            let dir = args.out.join("scene");
            if !dir.join("poses_bounds.npy").is_file() {
                let opts = ProceduralOptions {
                    name: SceneName::Stairs,
                    ..Default::default()
                };
                tracing::info!(dir = %dir.display(), "generating the procedural stairs scene");
                procedural::write(&opts, &dir).context("generating the stairs scene")?;
            }
            dir
        }
    };
    let (_, scene) = gb_nerf::scene::load(&dir, &LoadOptions::default())
        .with_context(|| format!("loading scene {}", dir.display()))?;
    for w in &scene.warnings {
        tracing::warn!("{w}");
    }
    Ok(scene)
}

fn finite_or_null(v: f64) -> serde_json::Value {
    if v.is_finite() {
        json!(v)
    } else {
        json!(null)
    }
}

fn disparity_map(depth: &[f32], w: usize, h: usize) -> ScalarMap {
    let data = depth
        .iter()
        .map(|d| {
            if d.is_finite() && *d > 0.0 {
                1.0 / d
            } else {
                0.0
            }
        })
        .collect();
    ScalarMap {
        width: w,
        height: h,
        data,
    }
}

/// Runs the command.
pub fn run(args: Args) -> anyhow::Result<()> {
    if args.prior != "none" {
        bail!(
            "--prior {}: only `none` is available so far (the diffusion prior is not built yet)",
            args.prior
        );
    }
    let device = args.device.unwrap_or_default();
    let mut config = NerfConfig::preset(&args.preset)?;
    if let Some(steps) = args.steps {
        config.train.steps = steps;
    }
    let scene = load_or_generate(&args)?;
    let ckpt = args.out.join("checkpoint.bin");
    let mut trainer = if args.resume && ckpt.is_file() {
        tracing::info!(path = %ckpt.display(), "resuming");
        let mut t = Trainer::resume(&scene, &ckpt, device)?;
        t.config.train.steps = config.train.steps;
        t
    } else {
        Trainer::new(&scene, config, device)?
    };
    tracing::info!(
        scene = %scene.name, preset = %trainer.config.name, device = %device,
        train_views = trainer.data.views.len(), pixels = trainer.data.pixels.len(),
        "training (prior: none)"
    );
    let summary = trainer.fit(Some(&ckpt), true)?;
    let renders = args.out.join("renders");
    let mut per_view = Vec::new();
    let (mut sums, mut counts) = ([0.0f64; 5], [0usize; 5]);
    let render_start = Instant::now();
    for view in scene.split(Split::Test) {
        let v = prepare_view(view, trainer.config.train.image_downscale);
        let r = trainer.render(&v.camera);
        write_render_pngs(&renders, &view.name, &r)?;
        let full = (
            psnr(&r.rgb, &v.image, &Region::Full)?,
            ssim(&r.rgb, &v.image, &Region::Full)?,
        );
        let bbox = match v.mask.as_ref().and_then(|m| m.bbox()) {
            Some((x0, y0, x1, y1)) => {
                let reg = Region::BBox { x0, y0, x1, y1 };
                Some((psnr(&r.rgb, &v.image, &reg)?, ssim(&r.rgb, &v.image, &reg)?))
            }
            None => None,
        };
        let (w, h) = (v.image.width, v.image.height);
        let dpsnr = match &v.depth {
            Some(gt) => {
                let pred = disparity_to_rgb8(&disparity_map(&r.depth, w, h))?;
                let gt = disparity_to_rgb8(&disparity_map(gt, w, h))?;
                Some(psnr(&pred, &gt, &Region::Full)?)
            }
            None => None,
        };
        let vals = [
            Some(full.0),
            Some(full.1),
            bbox.map(|b| b.0),
            bbox.map(|b| b.1),
            dpsnr,
        ];
        for (i, v) in vals.iter().enumerate() {
            if let Some(v) = v.filter(|v| v.is_finite()) {
                sums[i] += v;
                counts[i] += 1;
            }
        }
        tracing::info!(view = %view.name, psnr = full.0, ssim = full.1, "test view");
        per_view.push(json!({
            "view": view.name,
            "psnr": finite_or_null(full.0),
            "ssim": finite_or_null(full.1),
            "psnr_bbox": bbox.map(|b| finite_or_null(b.0)),
            "ssim_bbox": bbox.map(|b| finite_or_null(b.1)),
            "d_psnr": dpsnr.map(finite_or_null),
            "evaluations_per_ray": r.evaluations_per_ray,
        }));
    }
    let mean = |i: usize| (counts[i] > 0).then(|| sums[i] / counts[i] as f64);
    let metrics = json!({
        "prior": "none",
        "scene": scene.name,
        "preset": trainer.config.name,
        "device": device.name(),
        "steps": trainer.step,
        "train_seconds_this_run": summary.seconds,
        "render_seconds": render_start.elapsed().as_secs_f64(),
        "samples_per_ray": trainer.config.sampler.samples_per_ray,
        "mean_train_evaluations_per_ray": summary.mean_evaluations_per_ray,
        "test_views": per_view.len(),
        "mean": {
            "psnr": mean(0), "ssim": mean(1), "psnr_bbox": mean(2), "ssim_bbox": mean(3), "d_psnr": mean(4),
        },
        "views": per_view,
        "notes": "PSNR/SSIM: gb_eval (scikit-image conventions) on [0,1] RGB; *_bbox over the \
                  test view's mask bounding box; d_psnr: PSNR of 8-bit max-normalised disparity \
                  (gb_eval::disparity); infinite values are written as null",
    });
    let path = args.out.join("metrics.json");
    write_json(&path, &metrics)?;
    println!("{}", serde_json::to_string_pretty(&metrics["mean"])?);
    println!("wrote {}", path.display());
    Ok(())
}

fn write_json(path: &Path, v: &serde_json::Value) -> anyhow::Result<()> {
    let bytes = serde_json::to_vec_pretty(v)?;
    gb_core::write_atomic(path, &bytes).with_context(|| format!("writing {}", path.display()))
}
