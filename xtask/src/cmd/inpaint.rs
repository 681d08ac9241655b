//! `cargo xtask inpaint`: object removal with a NeRF, guided by a diffusion prior (GB-NeRF and
//! its baselines, `gb_inpaint`).
//!
//! ```text
//! cargo xtask inpaint [--scene DIR] [--method M] [--preset P] [--prior none|tiny|DIR|HUB_ID]
//!     [--lora FILE] [--prompt P] [--negative-prompt N] [--normal-prompt G] [--device D]
//!     [--out DIR] [--resume] [--steps N] [--seed N] [--baseline DIR] [--weights DIR]
//!     [--orbit-frames N]
//! ```
//!
//! - `--method`: a built-in method (`configs/methods/`: gb-nerf, gb-nerf-unseen, bsd,
//!   mvip-nerf, spin-nerf-sds, csd, none, pre-inpainted) or a `.toml` file (a method file, or
//!   a run's `config.toml`, whose `[method]` table is used). Default `gb-nerf`; `none` is the no-prior
//!   baseline.
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
//! - `export/`: the inpainted training views (RGB, 16-bit depth), `transforms.json` and the
//!   orbit's `camera_path.json` for nerfstudio (`gb_inpaint::export`);
//! - `orbit.gif`: the trained field along a closed path through the input cameras, at half
//!   the training resolution (`--orbit-frames`, default 24; 0 for none; `gb_inpaint::gif`);
//! - `report.html` (+ `report/`): ground truth, our render, the baseline (`--baseline DIR`,
//!   another run's folder; else the masked input, said so) and the difference per test view
//!   (masked training views for a scene without test views), the orbit, the metric table
//!   and the training curves as SVG (`gb_inpaint::report`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context};
use gb_core::BackendKind;
use gb_eval::disparity::{disparity_to_rgb8, ScalarMap};
use gb_eval::{psnr, ssim, Region};
use gb_inpaint::metrics::{evaluate, evaluate_without_reference, MetricOptions, ViewPair};
use gb_inpaint::pre_inpainted;
use gb_inpaint::report::RunPage;
use gb_inpaint::{
    lora_for, FitOptions, GuidancePrior, GuidedTrainer, MethodConfig, PromptOverrides,
    SceneCaptions,
};
use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};
use gb_nerf::scene::{LoadOptions, Scene, Split};
use gb_nerf::train::data::prepare_view;
use gb_nerf::train::output::write_render_pngs;
use gb_nerf::train::NerfConfig;
use serde_json::json;

use super::finetune::resolve_prior;

/// Arguments of `cargo xtask inpaint`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene folder (LLFF / SPIn-NeRF or Blender layout). Default: generate the procedural
    /// `stairs` scene into OUT/scene.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Method: gb-nerf (default), gb-nerf-unseen, bsd, mvip-nerf, spin-nerf-sds, csd, none,
    /// pre-inpainted, or a .toml file.
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
    #[arg(long, value_parser = super::parse::device())]
    pub device: Option<BackendKind>,
    /// Continue from OUT/checkpoint.bin when it exists.
    #[arg(long)]
    pub resume: bool,
    /// Override the preset's number of training steps (at least 1).
    #[arg(long, value_parser = super::parse::at_least_one)]
    pub steps: Option<usize>,
    /// Override the preset's training seed (`[train] seed`: ray batches, the guidance's
    /// timesteps and noise); `bench quality --seeds` repeats a grid over seeds with it.
    #[arg(long)]
    pub seed: Option<u64>,
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
}

fn load_or_generate(args: &Args) -> anyhow::Result<(PathBuf, Scene)> {
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
    Ok((dir, scene))
}

/// The method name and prior spec of a run (see the module docs): by default `gb-nerf`
/// with the built-in tiny prior.
fn method_and_prior(args: &Args) -> (String, Option<String>) {
    match (&args.method, &args.prior) {
        (m, Some(p)) if p == "none" => (m.clone().unwrap_or_else(|| "none".into()), None),
        (m, Some(p)) => (
            m.clone().unwrap_or_else(|| "gb-nerf".into()),
            Some(p.clone()),
        ),
        (Some(m), None) => (m.clone(), Some("tiny".into())),
        (None, None) => ("gb-nerf".into(), Some("tiny".into())),
    }
}

/// A preset name or `.toml` file; a run's `config.toml` contributes its `[preset]` table.
fn load_preset(spec: &str) -> anyhow::Result<NerfConfig> {
    if spec.ends_with(".toml") {
        let path = Path::new(spec);
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        if let Ok(v) = text.parse::<toml::Table>() {
            if let Some(t) = v.get("preset").and_then(|p| p.as_table()) {
                return Ok(NerfConfig::from_toml(&toml::to_string(t)?, path)?);
            }
        }
    }
    Ok(NerfConfig::preset(spec)?)
}

/// A method name or `.toml` file; a run's `config.toml` contributes its `[method]` table.
fn load_method(spec: &str) -> anyhow::Result<MethodConfig> {
    if spec.ends_with(".toml") {
        let path = Path::new(spec);
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        if let Ok(v) = text.parse::<toml::Table>() {
            if let Some(t) = v.get("method").and_then(|p| p.as_table()) {
                return Ok(MethodConfig::from_toml(&toml::to_string(t)?, path)?);
            }
        }
    }
    Ok(MethodConfig::load(spec)?)
}

/// Errors when no training view has a non-empty mask, or when a training view's mask covers
/// the whole image (no pixel of that view is left to supervise the NeRF: an inverted mask).
fn require_masks(scene: &Scene) -> anyhow::Result<()> {
    let masked = scene
        .split(Split::Train)
        .filter(|v| v.mask.as_ref().is_some_and(|m| m.bbox().is_some()))
        .count();
    if masked == 0 {
        return Err(gb_inpaint::InpaintError::NoMasks {
            scene: scene.name.clone(),
        }
        .into());
    }
    for view in scene.split(Split::Train) {
        if let Some(m) = view.mask.as_ref().filter(|m| m.data.iter().all(|&b| b)) {
            bail!(
                "scene '{}': the mask of training view '{}' covers the whole {}x{} image, so no pixel \
                 of it is left to supervise the NeRF (an inverted mask? masks are non-zero on \
                 the object only)",
                scene.name,
                view.name,
                m.width,
                m.height
            );
        }
    }
    Ok(())
}

/// Fails when `--out` cannot be a folder: it, or the first of its ancestors that exists, is
/// not a folder. Checked before anything is loaded; creating it comes later.
fn check_out(out: &Path) -> anyhow::Result<()> {
    if let Some(existing) = out.ancestors().find(|p| p.exists()) {
        if !existing.is_dir() {
            bail!(
                "--out {}: {} is a file, not a folder, so the output folder cannot be created",
                out.display(),
                existing.display()
            );
        }
    }
    Ok(())
}

fn quote(s: &str) -> String {
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./:=+,".contains(c))
    {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', "'\\''"))
    }
}

/// Runs the command.
pub fn run(args: Args) -> anyhow::Result<()> {
    run_inpaint(&args).map(|_| ())
}

/// Runs one inpainting job and returns its `metrics.json` (also used by `cargo xtask
/// ablate`, which calls it once per method).
pub fn run_inpaint(args: &Args) -> anyhow::Result<serde_json::Value> {
    let device = args.device.unwrap_or_default();
    check_out(&args.out)?;
    if let Some(b) = &args.baseline {
        if !b.is_dir() {
            bail!(
                "--baseline {}: not a folder (expected another run's output folder)",
                b.display()
            );
        }
    }
    let (method_name, prior_spec) = method_and_prior(args);
    let method = load_method(&method_name)?;
    let mut config = load_preset(&args.preset)?;
    if let Some(steps) = args.steps {
        config.train.steps = steps;
    }
    if let Some(seed) = args.seed {
        config.train.seed = seed;
    }

    // the prior and its LoRA: resolved and loaded before anything else runs
    let prior = if method.needs_prior() {
        let spec =
            prior_spec
                .as_deref()
                .ok_or_else(|| gb_inpaint::InpaintError::PriorRequired {
                    method: method.name.clone(),
                })?;
        let dir = resolve_prior(spec)?;
        let lora = lora_for(&method, &dir, args.lora.as_deref())?;
        tracing::info!(prior = %dir.display(), lora = ?lora, "loading the prior");
        Some(GuidancePrior::load(
            &dir,
            lora.as_deref(),
            &device.device(),
        )?)
    } else {
        if let Some(p) = args.prior.as_deref().filter(|p| *p != "none") {
            tracing::info!(prior = p, method = %method.name, "method has no guidance: prior not used");
        }
        if let Some(l) = &args.lora {
            bail!(
                "--lora {}: method '{}' has no guidance, so there is no prior to attach it to",
                l.display(),
                method.name
            );
        }
        None
    };

    let (scene_dir, mut scene) = load_or_generate(args)?;
    require_masks(&scene)?;
    let pre = if method.pre_inpainted {
        Some(pre_inpainted::apply(&mut scene, &scene_dir)?)
    } else {
        None
    };
    let overrides = PromptOverrides {
        appearance: args.prompt.clone(),
        negative: args.negative_prompt.clone(),
        geometry: args.normal_prompt.clone(),
    };
    let prompts = method.resolve_prompts(&SceneCaptions::read(&scene_dir), &overrides);
    let prior_info = prior.as_ref().map(|p| p.info.clone());

    std::fs::create_dir_all(&args.out).with_context(|| {
        format!(
            "--out {}: cannot create the output folder",
            args.out.display()
        )
    })?;
    let ckpt = args.out.join("checkpoint.bin");
    let resuming = args.resume && ckpt.is_file();
    if args.resume && !resuming {
        tracing::warn!(
            "--resume: no checkpoint at {}, so the run starts afresh",
            ckpt.display()
        );
    }
    let guidance = prior.map(|p| (p, prompts.clone()));
    let mut trainer = if resuming {
        tracing::info!(path = %ckpt.display(), "resuming");
        GuidedTrainer::resume_matching(&scene, &ckpt, method.clone(), guidance, device, config)?
    } else {
        GuidedTrainer::new(&scene, config, method.clone(), guidance, device)?
    };
    write_config(
        args,
        &scene_dir,
        &trainer,
        &method,
        &prompts,
        prior_spec.as_deref(),
        prior_info.as_ref(),
        pre.as_ref(),
        resuming,
    )?;
    tracing::info!(
        scene = %scene.name, preset = %trainer.config.name, method = %method.name,
        device = %device, train_views = trainer.data.views.len(),
        pixels = trainer.data.pixels.len(), steps = trainer.config.train.steps,
        guided_views = trainer.guidance.as_ref().map_or(0, |g| g.views.len()),
        normal_start = trainer.normal_start(),
        "training"
    );
    let summary = trainer.fit(&FitOptions {
        checkpoint: Some(ckpt.clone()),
        log: Some(args.out.join("train_log.jsonl")),
        append_log: resuming,
        progress: true,
    })?;

    let renders = args.out.join("renders");
    let mut per_view = Vec::new();
    let (mut sums, mut counts) = ([0.0f64; 5], [0usize; 5]);
    let render_start = Instant::now();
    let mut pairs = Vec::new();
    for view in scene.split(Split::Test) {
        let v = prepare_view(view, trainer.config.train.image_downscale);
        let r = trainer.render(&v.camera)?;
        write_render_pngs(&renders, &view.name, &r)?;
        pairs.push(ViewPair {
            name: view.name.clone(),
            pred: r.rgb.clone(),
            gt: v.image.clone(),
            mask: v.mask.as_ref().map(|m| m.data.clone()),
            disparity: v.depth.as_ref().map(|gt| {
                let (w, h) = (v.image.width, v.image.height);
                (disparity_map(&r.depth, w, h), disparity_map(gt, w, h))
            }),
        });
        let full = (
            psnr(&r.rgb, &v.image, &Region::Full)?,
            ssim(&r.rgb, &v.image, &Region::Full)?,
        );
        let bbox = match v.mask.as_ref().and_then(|m| m.bbox()) {
            Some((x0, y0, x1, y1)) => {
                let reg = Region::BBox { x0, y0, x1, y1 };
                // SSIM's 11x11 window does not fit a smaller box: reported as null
                let s = if x1 - x0 >= 11 && y1 - y0 >= 11 {
                    ssim(&r.rgb, &v.image, &reg)?
                } else {
                    f64::NAN
                };
                Some((psnr(&r.rgb, &v.image, &reg)?, s))
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
    // a scene without test views: its masked training views, scored without a reference
    let train_views = if pairs.is_empty() {
        gb_inpaint::report::render_masked_train_views(&args.out, &scene, &trainer)?
    } else {
        Vec::new()
    };
    let render_seconds = render_start.elapsed().as_secs_f64();
    let eval_start = Instant::now();
    let metric_options = MetricOptions::new(args.weights.clone(), device);
    let eval = if pairs.is_empty() {
        let renders: Vec<_> = train_views.iter().map(|t| t.render.clone()).collect();
        evaluate_without_reference(&renders, &metric_options)
    } else {
        evaluate(&pairs, &metric_options)
    };
    let eval_seconds = eval_start.elapsed().as_secs_f64();
    let orbit = gb_inpaint::gif::write_orbit(&args.out, &scene, &trainer, args.orbit_frames)?;
    let mut export = gb_inpaint::export::write_export(
        &args.out.join("export"),
        &scene,
        &trainer,
        args.orbit_frames,
    )?;
    // relative to the run folder, like `report`: metrics.json does not depend on where it lies
    export.folder = PathBuf::from("export");
    let mean = |i: usize| (counts[i] > 0).then(|| sums[i] / counts[i] as f64);
    let per_step = |secs: f64, n: usize| (n > 0).then(|| secs / n as f64);
    let metrics = json!({
        "method": method.name,
        "prior": prior_info.as_ref().map_or_else(|| json!("none"), |p| json!(p.folder)),
        "lora": prior_info.as_ref().and_then(|p| p.lora.clone()),
        "scene": scene.name,
        "preset": trainer.config.name,
        "device": device.name(),
        "steps": trainer.step,
        "train_seconds_this_run": summary.seconds,
        "render_seconds": render_seconds,
        "eval_seconds": eval_seconds,
        "export": export,
        "orbit": orbit.as_ref().map(|o| json!({"file": "orbit.gif", "frames": o.frames, "width": o.width, "height": o.height, "seconds": o.seconds})),
        "samples_per_ray": trainer.config.sampler.samples_per_ray,
        "mean_train_evaluations_per_ray": summary.mean_evaluations_per_ray,
        "guidance": {
            "guided_steps": summary.guided_steps,
            "unguided_steps": summary.unguided_steps,
            "skipped_steps": summary.skipped_steps,
            "seconds_per_guided_step": per_step(summary.guided_seconds, summary.guided_steps),
            "seconds_per_unguided_step": per_step(summary.unguided_seconds, summary.unguided_steps),
            "unet_calls": summary.unet_calls,
            "normal_start": trainer.normal_start(),
            "resolution": prior_info.as_ref().map(|p| p.resolution),
        },
        "test_views": per_view.len(),
        "mean": {
            "psnr": mean(0), "ssim": mean(1), "psnr_bbox": mean(2), "ssim_bbox": mean(3), "d_psnr": mean(4),
        },
        "views": per_view,
        "eval": eval.to_json(),
        "report": "report.html",
        "notes": "PSNR/SSIM: gb_eval (scikit-image conventions) on [0,1] RGB; *_bbox over the \
                  test view's mask bounding box; d_psnr: PSNR of 8-bit max-normalised disparity \
                  (gb_eval::disparity); infinite values are written as null; guidance counts \
                  and timings (wall time per step) cover the whole run, a resumed run's steps \
                  before its checkpoint included (train_log.jsonl has every step); `eval`: \
                  every gb-eval metric that applies (cargo xtask eval's keys and JSON: _bbox, \
                  _mask regions, lpips = ST-LPIPS, fid / d_fid, brisque, nima), unavailable ones \
                  null with the reason under eval.unavailable; a scene without test views is \
                  scored on its first masked training views (renders/train_*) by the \
                  no-reference metrics only: brisque / nima of the whole render and, as \
                  brisque_bbox / nima_bbox, of the mask's bounding box (the filled region)",
    });
    let path = args.out.join("metrics.json");
    write_json(&path, &metrics)?;
    let page = gb_inpaint::report::write_run_report(&RunPage {
        out: &args.out,
        scene: &scene,
        trainer: &trainer,
        pairs: &pairs,
        train_views: &train_views,
        eval: &eval,
        metrics: &metrics,
        baseline: args.baseline.as_deref(),
        orbit: orbit.is_some(),
    })?;
    println!("{}", serde_json::to_string_pretty(&metrics["mean"])?);
    println!("wrote {} and {}", path.display(), page.display());
    Ok(metrics)
}

/// Writes `OUT/config.toml`: the command that reproduces the run, then the resolved prior,
/// prompts, preset and method.
#[allow(clippy::too_many_arguments)]
fn write_config(
    args: &Args,
    scene_dir: &Path,
    trainer: &GuidedTrainer,
    method: &MethodConfig,
    prompts: &gb_inpaint::Prompts,
    prior_spec: Option<&str>,
    prior: Option<&gb_inpaint::PriorInfo>,
    pre: Option<&pre_inpainted::PreInpaintedReport>,
    resumed: bool,
) -> anyhow::Result<()> {
    let path = args.out.join("config.toml");
    let cfg = path.display().to_string();
    let mut cmd = vec![
        "cargo xtask inpaint".to_string(),
        format!("--scene {}", quote(&scene_dir.display().to_string())),
        format!("--preset {}", quote(&cfg)),
        format!("--method {}", quote(&cfg)),
        format!("--device {}", trainer.backend.name()),
        format!("--out {}", quote(&args.out.display().to_string())),
    ];
    match prior {
        Some(p) => {
            cmd.push(format!(
                "--prior {}",
                quote(&p.folder.display().to_string())
            ));
            if let Some(l) = &p.lora {
                cmd.push(format!("--lora {}", quote(&l.display().to_string())));
            }
        }
        None => cmd.push("--prior none".into()),
    }
    for (flag, v) in [
        ("--prompt", &args.prompt),
        ("--negative-prompt", &args.negative_prompt),
        ("--normal-prompt", &args.normal_prompt),
    ] {
        if let Some(v) = v {
            cmd.push(format!("{flag} {}", quote(v)));
        }
    }
    let mut run = toml::Table::new();
    run.insert("reproduce".into(), cmd.join(" ").into());
    run.insert("scene".into(), scene_dir.display().to_string().into());
    run.insert("method".into(), method.name.clone().into());
    run.insert("preset".into(), trainer.config.name.clone().into());
    run.insert("device".into(), trainer.backend.name().into());
    run.insert("steps".into(), (trainer.config.train.steps as i64).into());
    run.insert(
        "normal_start".into(),
        (trainer.normal_start() as i64).into(),
    );
    run.insert(
        "resumed_from_step".into(),
        (if resumed { trainer.step as i64 } else { 0 }).into(),
    );
    let mut sections: Vec<(&str, toml::Value)> = vec![("run", run.into())];
    let mut prior_t = toml::Table::new();
    prior_t.insert("spec".into(), prior_spec.unwrap_or("none").into());
    if let Some(p) = prior {
        let v = toml::Value::try_from(p)?;
        if let Some(t) = v.as_table() {
            prior_t.extend(t.clone());
        }
    }
    sections.push(("prior", prior_t.into()));
    sections.push(("prompts", toml::Value::try_from(prompts)?));
    if let Some(r) = pre {
        sections.push(("pre_inpainted", toml::Value::try_from(r)?));
    }
    sections.push(("preset", toml::Value::try_from(&trainer.config)?));
    sections.push(("method", toml::Value::try_from(method)?));
    let mut body = String::new();
    for (name, value) in sections {
        let mut one = toml::Table::new();
        one.insert(name.into(), value);
        body.push_str(&toml::to_string(&one)?);
        body.push('\n');
    }
    let text = format!(
        "# The resolved configuration of this run (cargo xtask inpaint). Reproduce it with\n#   {}\n{}",
        cmd.join(" "),
        body
    );
    gb_core::write_atomic(&path, text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))
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

fn write_json(path: &Path, v: &serde_json::Value) -> anyhow::Result<()> {
    let bytes = serde_json::to_vec_pretty(v)?;
    gb_core::write_atomic(path, &bytes).with_context(|| format!("writing {}", path.display()))
}
