//! `cargo xtask bench nerf`: NeRF training speed per preset and backend, against the same
//! configuration in plain PyTorch on this CPU (same run), written to
//! `bench/results/nerf-<timestamp>.json`.
//!
//! Speed: after 2 warm-up steps, `--steps` training steps on the procedural `stairs` scene
//! (200x150). The timed steps fall inside the occupancy grid's warm-up, so every sample is
//! evaluated, as in the PyTorch reference (`tools/nerf_parity/bench_torch.py`, dense
//! samples on random rays in a unit box).
//!
//! Accuracy (`--accuracy`, slow): each preset trained to completion on flex, with the wall
//! time and the test-view PSNR on pixels outside the masks.

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
    /// Timed steps per preset and backend.
    #[arg(long, default_value_t = 5)]
    pub steps: usize,
    /// Python with torch for the reference (default: $GB_PYTHON, then /work/pyref/bin/python).
    #[arg(long)]
    pub python: Option<PathBuf>,
    /// Also train every preset to completion on flex and record PSNR against wall time.
    #[arg(long)]
    pub accuracy: bool,
    /// Output folder.
    #[arg(long, default_value = "bench/results")]
    pub out: PathBuf,
}

fn stairs(dir: &std::path::Path) -> anyhow::Result<Scene> {
    let opts = ProceduralOptions {
        name: SceneName::Stairs,
        ..Default::default()
    };
    procedural::write(&opts, dir).context("generating stairs")?;
    Ok(gb_nerf::scene::load(dir, &LoadOptions::default())?.1)
}

fn torch_reference(
    python: &std::path::Path,
    cfg: &NerfConfig,
    steps: usize,
) -> anyhow::Result<serde_json::Value> {
    let FieldConfig::Hash {
        grid,
        hidden,
        geo_features,
        dir_freqs,
    } = &cfg.field
    else {
        anyhow::bail!("the PyTorch reference covers hash fields only");
    };
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
    let tmp = tempfile::tempdir()?;
    let scene = stairs(&tmp.path().join("stairs"))?;
    let python = args
        .python
        .clone()
        .or_else(|| std::env::var_os("GB_PYTHON").map(PathBuf::from))
        .unwrap_or_else(|| PathBuf::from("/work/pyref/bin/python"));
    let devices: Vec<BackendKind> = args
        .devices
        .split(',')
        .map(|s| s.parse())
        .collect::<Result<_, _>>()?;
    let mut rows = Vec::new();
    for preset in args.presets.split(',') {
        let cfg = NerfConfig::preset(preset.trim())?;
        for &device in &devices {
            let mut t = Trainer::new(&scene, cfg.clone(), device)?;
            for _ in 0..2 {
                t.train_step();
            }
            let start = Instant::now();
            let mut evals = 0.0;
            for _ in 0..args.steps {
                evals += t.train_step().evaluations_per_ray;
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
        let torch = torch_reference(&python, &cfg, args.steps)
            .unwrap_or_else(|e| json!({ "unavailable": e.to_string() }));
        if let Some(ts) = torch["steps_per_s"].as_f64() {
            for r in rows.iter_mut().filter(|r| r["preset"] == preset) {
                let s = r["steps_per_s"].as_f64().unwrap_or(0.0);
                r["ratio_vs_torch_cpu"] = json!(s / ts);
            }
        }
        rows.push(json!({ "preset": preset, "device": "pytorch-cpu", "reference": torch }));
    }
    let mut accuracy = Vec::new();
    if args.accuracy {
        for preset in args.presets.split(',') {
            let cfg = NerfConfig::preset(preset.trim())?;
            let mut t = Trainer::new(&scene, cfg, BackendKind::Flex)?;
            let s = t.fit(None, true)?;
            let mut vals = Vec::new();
            for view in scene.split(Split::Test) {
                let v = prepare_view(view, t.config.train.image_downscale);
                let r = t.render(&v.camera);
                let region = match &v.mask {
                    Some(m) => Region::Mask(m.data.iter().map(|b| !b).collect()),
                    None => Region::Full,
                };
                vals.push(psnr(&r.rgb, &v.image, &region)?);
            }
            let mean = vals.iter().sum::<f64>() / vals.len().max(1) as f64;
            accuracy.push(
                json!({ "preset": preset, "scene": "stairs", "device": "flex",
                "train_seconds": s.seconds, "psnr_unmasked": mean }),
            );
        }
    }
    let stamp = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)?
        .as_secs();
    let path = args.out.join(format!("nerf-{stamp}.json"));
    let report = json!({
        "benchmark": "nerf", "machine": super::bench::machine_description(),
        "scene": "stairs 200x150 (procedural)", "timed_steps": args.steps,
        "speed": rows, "accuracy": accuracy,
    });
    gb_core::write_atomic(&path, &serde_json::to_vec_pretty(&report)?)?;
    println!("{}", serde_json::to_string_pretty(&report)?);
    println!("wrote {}", path.display());
    Ok(())
}
