//! `cargo xtask bench nerf`: NeRF training speed per preset and backend, against the same
//! configuration in plain PyTorch on this machine (same run; `--torch-device cuda` on a GPU), written to
//! `bench/results/nerf-<timestamp>.json`.
//!
//! Speed: after 2 warm-up steps, `--steps` training steps on the procedural `stairs` scene
//! (200x150). The timed steps fall inside the occupancy grid's warm-up, so every sample is
//! evaluated, as in the PyTorch reference (`tools/nerf_parity/bench_torch.py`, dense
//! samples on random rays in a unit box).
//!
//! Accuracy (`--accuracy`, slow): each preset of `--accuracy-presets` trained to completion
//! on `--accuracy-device` (flex by default) on each scene of `--accuracy-scenes`, with the wall time and the test-view PSNR on
//! pixels outside the masks. `stairs` holds out its object-free test views; `fern`
//! (`$GB_TEST_DATA/data/fern`, or a path given as `fern=DIR`) holds out every 8th view, the
//! NeRF `llffhold = 8` convention. Each point is written as soon as it is measured.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use gb_core::BackendKind;
use gb_eval::{psnr, Region};
use gb_nerf::field::FieldConfig;
use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};
use gb_nerf::scene::{LoadOptions, Scene, Split};
use gb_nerf::train::data::prepare_view;
use gb_nerf::train::{NerfConfig, Trainer};
use serde_json::json;

/// Arguments of `cargo xtask bench nerf`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Comma-separated presets.
    #[arg(long, default_value = "fast,balanced,paper")]
    pub presets: String,
    /// Comma-separated backends.
    #[arg(long, default_value = "ndarray,flex,wgpu")]
    pub devices: String,
    /// Timed steps per preset and backend (0: no speed rows).
    #[arg(long, default_value_t = 5)]
    pub steps: usize,
    /// Python with torch for the reference (default: $GB_PYTHON, else python3 on PATH;
    /// `bash tools/bench/make_venv.sh` makes the pinned one).
    #[arg(long)]
    pub python: Option<PathBuf>,
    /// Device of the PyTorch reference: `cpu`, or `cuda` on a GPU machine.
    #[arg(long, default_value = "cpu")]
    pub torch_device: String,
    /// Backend that trains the accuracy points.
    #[arg(long, default_value = "flex", value_enum)]
    pub accuracy_device: BackendKind,
    /// Also train every preset to completion on flex and record PSNR against wall time.
    #[arg(long)]
    pub accuracy: bool,
    /// Presets of the accuracy points.
    #[arg(long, default_value = "fast,balanced")]
    pub accuracy_presets: String,
    /// Scenes of the accuracy points: `stairs`, `fern`, or `NAME=DIR` for an LLFF folder
    /// (every 8th view held out).
    #[arg(long, default_value = "stairs,fern")]
    pub accuracy_scenes: String,
    /// Also measure the test-view PSNR every this many steps of each accuracy run (0: only
    /// at the end): the held-out curve that shows where a preset stops improving. The
    /// evaluations are not counted in `train_seconds`.
    #[arg(long, default_value_t = 0)]
    pub curve_every: usize,
    /// Output folder.
    #[arg(long, default_value = "bench/results")]
    pub out: PathBuf,
}

/// Trains `t` to completion; with `every > 0` also records `(step, train seconds, test
/// PSNR)` every `every` steps (evaluation time excluded). Returns the training seconds.
fn train_with_curve(
    t: &mut Trainer,
    scene: &Scene,
    every: usize,
    curve: &mut Vec<serde_json::Value>,
) -> anyhow::Result<f64> {
    if every == 0 {
        return Ok(t.fit(None, true)?.seconds);
    }
    let steps = t.config.train.steps;
    let bar = gb_core::progress::bar(steps as u64);
    let mut seconds = 0.0;
    while t.step < steps {
        let t0 = std::time::Instant::now();
        let stats = t.train_step()?;
        seconds += t0.elapsed().as_secs_f64();
        bar.set_position(t.step as u64);
        bar.set_message(format!("psnr {:.2}", stats.psnr));
        if t.step.is_multiple_of(every) && t.step < steps {
            let psnr = test_psnr(t, scene)?;
            tracing::info!(step = t.step, psnr, seconds, "held-out curve");
            curve.push(
                json!({ "step": t.step, "train_seconds": seconds, "psnr_test_unmasked": psnr }),
            );
        }
    }
    bar.finish_and_clear();
    Ok(seconds)
}

fn stairs(dir: &std::path::Path) -> anyhow::Result<Scene> {
    let opts = ProceduralOptions {
        name: SceneName::Stairs,
        ..Default::default()
    };
    procedural::write(&opts, dir).context("generating stairs")?;
    Ok(gb_nerf::scene::load(dir, &LoadOptions::default())?.1)
}

/// An accuracy scene by name: the generated `stairs`, or an LLFF folder with every 8th view
/// held out (`fern` is `$GB_TEST_DATA/data/fern`).
fn accuracy_scene(spec: &str, stairs_scene: &Scene) -> anyhow::Result<Scene> {
    let (name, dir) = match spec.split_once('=') {
        Some((n, d)) => (n, PathBuf::from(d)),
        None if spec == "stairs" => return Ok(stairs_scene.clone()),
        None if spec == "fern" => ("fern", gb_core::test_data_dir().join("data/fern")),
        None => anyhow::bail!("unknown accuracy scene '{spec}': use stairs, fern or NAME=DIR"),
    };
    let mut opts = LoadOptions::default();
    opts.llff.holdout_every = Some(8);
    let (_, scene) = gb_nerf::scene::load(&dir, &opts)
        .with_context(|| format!("loading accuracy scene {name} from {}", dir.display()))?;
    Ok(scene)
}

/// Mean test-view PSNR on pixels outside the masks.
fn test_psnr(t: &Trainer, scene: &Scene) -> anyhow::Result<f64> {
    let mut vals = Vec::new();
    for view in scene.split(Split::Test) {
        let v = prepare_view(view, t.config.train.image_downscale);
        let r = t.render(&v.camera)?;
        let region = match &v.mask {
            Some(m) => Region::Mask(m.data.iter().map(|b| !b).collect()),
            None => Region::Full,
        };
        vals.push(psnr(&r.rgb, &v.image, &region)?);
    }
    anyhow::ensure!(!vals.is_empty(), "the scene has no test views");
    Ok(vals.iter().sum::<f64>() / vals.len() as f64)
}

fn torch_reference(
    python: &std::path::Path,
    cfg: &NerfConfig,
    steps: usize,
    device: &str,
) -> anyhow::Result<serde_json::Value> {
    let FieldConfig::Hash {
        grid,
        hidden,
        geo_features,
        dir_freqs,
        ..
    } = &cfg.field
    else {
        anyhow::bail!("the PyTorch reference covers hash fields only");
    };
    if let FieldConfig::Hash { density_bias, .. } = &cfg.field {
        if *density_bias != 0.0 {
            anyhow::bail!(
                "the PyTorch reference has no density bias (density_bias = {density_bias})"
            );
        }
    }
    let conf = json!({
        "levels": grid.levels, "features_per_level": grid.features_per_level,
        "log2_table_size": grid.log2_table_size, "base_resolution": grid.base_resolution,
        "max_resolution": grid.max_resolution, "hidden": hidden, "geo_features": geo_features,
        "dir_freqs": dir_freqs, "samples_per_ray": cfg.sampler.samples_per_ray,
        "rays_per_batch": cfg.train.rays_per_batch,
    });
    let tmp = tempfile::NamedTempFile::new()?;
    std::fs::write(tmp.path(), serde_json::to_vec(&conf)?)?;
    let out = std::process::Command::new(python)
        .arg("tools/nerf_parity/bench_torch.py")
        .arg("--config")
        .arg(tmp.path())
        .arg("--steps")
        .arg(steps.to_string())
        .arg("--device")
        .arg(device)
        .output()
        .with_context(|| format!("running {}", python.display()))?;
    if !out.status.success() {
        anyhow::bail!(
            "torch reference failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let line = String::from_utf8_lossy(&out.stdout);
    Ok(serde_json::from_str(
        line.trim().lines().last().unwrap_or("{}"),
    )?)
}

/// Runs the benchmark.
pub fn run(args: Args) -> anyhow::Result<()> {
    // The speed rows time the PyTorch reference too: check its packages before any timing.
    let python = match args.steps {
        0 => None,
        _ => Some(super::python::reference_python(
            args.python.as_deref(),
            &["torch", "numpy"],
        )?),
    };
    let tmp = tempfile::tempdir()?;
    let scene = stairs(&tmp.path().join("stairs"))?;
    let devices: Vec<BackendKind> = args
        .devices
        .split(',')
        .map(|s| s.parse())
        .collect::<Result<_, _>>()?;
    let mut rows = Vec::new();
    // `--steps 0` skips the speed rows (accuracy points only).
    let speed_presets: Vec<&str> = match args.steps {
        0 => Vec::new(),
        _ => args.presets.split(',').collect(),
    };
    for preset in speed_presets {
        let cfg = NerfConfig::preset(preset.trim())?;
        for &device in &devices {
            let mut t = Trainer::new(&scene, cfg.clone(), device)?;
            for _ in 0..2 {
                t.train_step()?;
            }
            let start = Instant::now();
            let mut evals = 0.0;
            for _ in 0..args.steps {
                evals += t.train_step()?.evaluations_per_ray;
            }
            let secs = start.elapsed().as_secs_f64();
            let sps = args.steps as f64 / secs;
            tracing::info!(preset, %device, steps_per_s = sps, "nerf speed");
            rows.push(json!({
                "preset": preset, "device": device.name(), "steps_per_s": sps,
                "rays_per_s": sps * cfg.train.rays_per_batch as f64,
                "evaluations_per_ray": evals as f64 / args.steps as f64,
                "samples_per_ray": cfg.sampler.samples_per_ray,
            }));
        }
        let torch = python
            .as_deref()
            .context("no reference Python")
            .and_then(|py| torch_reference(py, &cfg, args.steps, &args.torch_device))
            .unwrap_or_else(|e| json!({ "unavailable": e.to_string() }));
        let ratio_key = format!("ratio_vs_torch_{}", args.torch_device);
        if let Some(ts) = torch["steps_per_s"].as_f64() {
            for r in rows.iter_mut().filter(|r| r["preset"] == preset) {
                let s = r["steps_per_s"].as_f64().unwrap_or(0.0);
                r[&ratio_key] = json!(s / ts);
            }
        }
        rows.push(
            json!({ "preset": preset, "device": format!("pytorch-{}", args.torch_device),
            "reference": torch }),
        );
    }
    let stamp = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)?
        .as_secs();
    let path = args.out.join(format!("nerf-{stamp}.json"));
    let mut report = json!({
        "benchmark": "nerf", "machine": super::machine_description(),
        "scene": "stairs 200x150 (procedural)", "timed_steps": args.steps,
        "speed": rows, "accuracy": [],
    });
    if args.accuracy {
        for spec in args.accuracy_scenes.split(',') {
            let acc_scene = accuracy_scene(spec.trim(), &scene)?;
            let name = spec.split('=').next().unwrap_or(spec).trim();
            for preset in args.accuracy_presets.split(',') {
                let cfg = NerfConfig::preset(preset.trim())?;
                let mut t = Trainer::new(&acc_scene, cfg, args.accuracy_device)?;
                let mut curve = Vec::new();
                let seconds = train_with_curve(&mut t, &acc_scene, args.curve_every, &mut curve)?;
                let mean = test_psnr(&t, &acc_scene)?;
                if args.curve_every > 0 {
                    curve.push(json!({ "step": t.step, "train_seconds": seconds,
                        "psnr_test_unmasked": mean }));
                }
                tracing::info!(scene = name, preset, psnr = mean, seconds, "nerf accuracy");
                if let Some(a) = report["accuracy"].as_array_mut() {
                    a.push(json!({ "preset": preset, "scene": name,
                        "device": args.accuracy_device.name(),
                        "steps": t.config.train.steps, "train_seconds": seconds,
                        "test_views": acc_scene.split(Split::Test).count(),
                        "psnr_test_unmasked": mean, "curve": curve }));
                }
                gb_core::write_atomic(&path, &serde_json::to_vec_pretty(&report)?)?;
            }
        }
    }
    gb_core::write_atomic(&path, &serde_json::to_vec_pretty(&report)?)?;
    println!("{}", serde_json::to_string_pretty(&report)?);
    println!("wrote {}", path.display());
    Ok(())
}
