//! `cargo xtask bench pipeline`: the cost of one GB-NeRF training step (reconstruction rays,
//! the RGB crop and the normal-map crop through the prior, backward, Adam) at a preset's
//! settings, with a prior of SD-1.5-inpainting's shapes and random weights (`--prior sd15`,
//! the default: no checkpoint needed), the built-in tiny prior, or a prior folder.
//!
//! Each timed step runs the phases of `GuidedTrainer::train_step` one by one with a device
//! synchronisation after each, so that asynchronous backends (wgpu) are timed per phase:
//! reconstruction forward, RGB crop render, RGB guidance (VAE encoder forward, one batched
//! U-Net call), normal-map render, normal guidance (VAE encoder of the conditioning and of the
//! input, one batched U-Net call), then the single backward pass and Adam. The U-Net and the
//! VAE encoder forward+backward are also timed alone on the same prior, which splits the step
//! into NeRF, U-Net and VAE time. Peak memory: the process's resident set on CPU backends,
//! and `nvidia-smi`'s reading of the GPU, polled every 50 ms, where it exists.
//!
//! The projection to a full run multiplies the step time by the preset's step count. Every
//! timed step lies inside the occupancy grid's warm-up (all samples evaluated), so the
//! NeRF part is an upper bound. The floor compares the guidance's arithmetic (`--floor-tflop`,
//! 4 TFLOP per 512-pixel guidance step by default: two batched U-Net calls and the VAE
//! encoder passes of SD 1.5) with the device's peak (`--peak-tflops`, when given).

use std::io::BufRead;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context};
use burn::tensor::{Distribution, Tensor};
use gb_core::{BackendKind, Precision};
use gb_diffusion::config::ClipTextConfig;
use gb_diffusion::distill::{EpsBatch, InpaintEpsPredictor, LatentEncoder, PromptEncoder};
use gb_inpaint::{GuidedTrainer, MethodConfig, Modality, SceneCaptions};
use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};
use gb_nerf::scene::LoadOptions;
use gb_nerf::train::NerfConfig;
use serde_json::json;

/// Arguments of `cargo xtask bench pipeline`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The prior: `sd15` (SD-1.5-inpainting shapes, random weights), `tiny`, or a folder.
    #[arg(long, default_value = "sd15")]
    pub prior: String,
    /// NeRF preset (name or TOML file).
    #[arg(long, default_value = "paper")]
    pub preset: String,
    /// Method (name or TOML file); its normal guidance is switched on from the first step.
    #[arg(long, default_value = "gb-nerf")]
    pub method: String,
    /// Timed steps (after `--warmup` untimed ones).
    #[arg(long, default_value_t = 3)]
    pub steps: usize,
    /// Untimed steps first (kernel compilation and autotuning happen there).
    #[arg(long, default_value_t = 2)]
    pub warmup: usize,
    /// Backend.
    #[arg(long, value_enum)]
    pub device: Option<BackendKind>,
    /// The prior's precision (default: f16 on a GPU card, f32 elsewhere).
    #[arg(long, value_enum)]
    pub precision: Option<Precision>,
    /// Arithmetic of one guidance step at the prior's resolution, TFLOP.
    #[arg(long, default_value_t = 4.0)]
    pub floor_tflop: f64,
    /// The device's peak throughput for the floor, TFLOP/s (e.g. 67 for an H100 SXM in
    /// FP32, 989 in dense BF16); the floor is omitted without it.
    #[arg(long, value_delimiter = ',')]
    pub peak_tflops: Vec<f64>,
    /// Output folder.
    #[arg(long, default_value = "bench/results")]
    pub out: PathBuf,
}

/// SD-1.5's text encoder (CLIP ViT-L/14's text tower).
fn sd15_text_encoder() -> ClipTextConfig {
    ClipTextConfig {
        hidden_size: 768,
        intermediate_size: 3072,
        num_attention_heads: 12,
        projection_dim: 768,
        ..ClipTextConfig::default()
    }
}

/// Polls `nvidia-smi` for the GPU memory in use (MiB) until dropped; `None` without one.
pub struct GpuMemoryPoll {
    child: std::process::Child,
    peak: Arc<AtomicU64>,
    first: Arc<AtomicU64>,
}

impl GpuMemoryPoll {
    /// Starts polling; `None` without `nvidia-smi`.
    pub fn start() -> Option<Self> {
        let mut child = std::process::Command::new("nvidia-smi")
            .args([
                "--query-gpu=memory.used",
                "--format=csv,noheader,nounits",
                "-lms",
                "50",
            ])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::null())
            .spawn()
            .ok()?;
        let stdout = child.stdout.take()?;
        let peak = Arc::new(AtomicU64::new(0));
        let first = Arc::new(AtomicU64::new(u64::MAX));
        let (p, f) = (peak.clone(), first.clone());
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(stdout)
                .lines()
                .map_while(Result::ok)
            {
                if let Ok(mb) = line.trim().parse::<u64>() {
                    p.fetch_max(mb, Ordering::Relaxed);
                    let _ = f.compare_exchange(u64::MAX, mb, Ordering::Relaxed, Ordering::Relaxed);
                }
            }
        });
        Some(Self { child, peak, first })
    }

    /// `(at start, peak)` in MiB.
    pub fn read(&self) -> (Option<u64>, u64) {
        let first = self.first.load(Ordering::Relaxed);
        (
            (first != u64::MAX).then_some(first),
            self.peak.load(Ordering::Relaxed),
        )
    }
}

impl Drop for GpuMemoryPoll {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Waits for the device: reads one number that depends on `t`.
fn sync<const D: usize>(t: Tensor<D>) -> f32 {
    t.sum().into_scalar::<f32>()
}

/// Seconds since `start`, restarting it.
fn lap(start: &mut Instant) -> f64 {
    let s = start.elapsed().as_secs_f64();
    *start = Instant::now();
    s
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

const PHASES: [&str; 6] = [
    "recon_forward",
    "rgb_render",
    "rgb_guidance",
    "normal_render",
    "normal_guidance",
    "backward_adam",
];

/// One profiled training step: the seconds of each of [`PHASES`].
fn profiled_step(t: &mut GuidedTrainer, view: usize) -> anyhow::Result<[f64; 6]> {
    let step = t.nerf.step;
    let mut clock = Instant::now();
    let recon = t.nerf.reconstruction_loss()?;
    let recon_s = lap(&mut clock);
    let (rgb, _) = t.rgb_prior_input(view)?;
    sync(rgb.clone());
    let rgb_render_s = lap(&mut clock);
    let rgb_term = t.term(Modality::Rgb, view, rgb, step, None)?;
    sync(rgb_term.loss.clone());
    let rgb_guidance_s = lap(&mut clock);
    let (normal, _) = t.normal_prior_input(view)?;
    sync(normal.clone());
    let normal_render_s = lap(&mut clock);
    let normal_term = t.term(Modality::Normal, view, normal, step, None)?;
    sync(normal_term.loss.clone());
    let normal_guidance_s = lap(&mut clock);
    let loss = recon.loss + rgb_term.loss + normal_term.loss;
    t.nerf.apply_loss(loss)?;
    sync(t.nerf.field.density(&[[0.5, 0.5, 0.5]]));
    let backward_s = lap(&mut clock);
    Ok([
        recon_s,
        rgb_render_s,
        rgb_guidance_s,
        normal_render_s,
        normal_guidance_s,
        backward_s,
    ])
}

/// Median seconds of `f` over `repeats` calls after one untimed call.
fn time_median(repeats: usize, mut f: impl FnMut() -> anyhow::Result<()>) -> anyhow::Result<f64> {
    f()?;
    let mut v = Vec::new();
    for _ in 0..repeats.max(1) {
        let s = Instant::now();
        f()?;
        v.push(s.elapsed().as_secs_f64());
    }
    Ok(median(&mut v))
}

/// Runs the benchmark and writes `bench/results/pipeline-<prior>-<preset>-<device>.json`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if args.steps == 0 {
        bail!("--steps must be at least 1");
    }
    let kind = args.device.unwrap_or_default();
    let device = kind.device();
    let precision = Precision::resolve(args.precision, &device).context("--precision")?;
    let gpu = GpuMemoryPoll::start();
    let tmp = tempfile::tempdir()?;
    let scene_dir = tmp.path().join("stairs");
    procedural::write(
        &ProceduralOptions {
            name: SceneName::Stairs,
            ..Default::default()
        },
        &scene_dir,
    )
    .context("generating stairs")?;
    let (_, scene) = gb_nerf::scene::load(&scene_dir, &LoadOptions::default())?;

    tracing::info!(prior = %args.prior, device = %kind, "building the prior");
    let build = Instant::now();
    let prior = match args.prior.as_str() {
        "sd15" => gb_inpaint::prior::random_prior(
            &super::unet::sd15_inpainting_unet()?,
            &super::unet::sd15_vae()?,
            &sd15_text_encoder(),
            &gb_core::assets_dir().join("clip-tokenizer"),
            precision,
            &device,
        )?,
        spec => {
            let dir = gb_diffusion::checkpoint::resolve_prior(spec)?;
            gb_inpaint::prior::load_prior(
                &dir,
                &gb_inpaint::prior::PriorOptions {
                    precision: Some(precision),
                    ..Default::default()
                },
                &device,
            )?
        }
    };
    let build_s = build.elapsed().as_secs_f64();
    let res = prior.resolution;

    // component timings on the same prior
    let f = prior.encoder.downsample_factor();
    let lat = res / f;
    let ad = device.clone().autodiff();
    let vae_s = time_median(args.steps, || {
        let img = Tensor::<4>::random([1, 3, res, res], Distribution::Uniform(-1.0, 1.0), &ad)
            .require_grad();
        let z = prior.encoder.encode(img.clone())?;
        let grads = z.sum().backward();
        if let Some(g) = img.grad(&grads) {
            sync(g);
        }
        Ok(())
    })?;
    let vae_fwd_s = time_median(args.steps, || {
        let img = Tensor::<4>::random([1, 3, res, res], Distribution::Uniform(-1.0, 1.0), &device);
        sync(prior.encoder.encode(img)?);
        Ok(())
    })?;
    let text = prior.text.encode_prompt("a photo")?;
    let c = 4;
    let unet_s = time_median(args.steps, || {
        let batch = EpsBatch {
            noisy_latents: Tensor::random(
                [2, c, lat, lat],
                Distribution::Normal(0.0, 1.0),
                &device,
            ),
            timestep: 500,
            text_embeddings: Tensor::cat(vec![text.clone(), text.clone()], 0),
            mask: Tensor::ones([2, 1, lat, lat], &device),
            masked_image_latents: Tensor::zeros([2, c, lat, lat], &device),
        };
        sync(prior.unet.predict_eps(batch)?);
        Ok(())
    })?;
    tracing::info!(vae_s, vae_fwd_s, unet_s, "components");

    let mut method = MethodConfig::load(&args.method)?;
    method.normal_start_step = 0;
    if !method.needs_prior() {
        bail!("method '{}' has no guidance to time", method.name);
    }
    let config = NerfConfig::preset(&args.preset)?;
    let total_steps = config.train.steps;
    let prompts = method.resolve_prompts(&SceneCaptions::read(&scene_dir), &Default::default());
    let mut trainer = GuidedTrainer::new(&scene, config, method, Some((prior, prompts)), kind)?;
    let view = trainer
        .guidance
        .as_ref()
        .and_then(|g| g.views.first().copied())
        .context("no guided view")?;
    let mut per_phase: Vec<Vec<f64>> = vec![Vec::new(); PHASES.len()];
    let mut totals = Vec::new();
    // A device that runs out of memory panics inside the backend: the components measured
    // so far are still written, with the failure.
    let steps_result =
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| -> anyhow::Result<()> {
            for i in 0..args.warmup + args.steps {
                let times = profiled_step(&mut trainer, view)?;
                let total: f64 = times.iter().sum();
                tracing::info!(step = i, total, ?times, "profiled step");
                if i >= args.warmup {
                    for (k, s) in times.iter().enumerate() {
                        per_phase[k].push(*s);
                    }
                    totals.push(total);
                }
            }
            Ok(())
        }));
    let failure = match steps_result {
        Ok(Ok(())) => None,
        Ok(Err(e)) => Some(format!("{e:#}")),
        Err(panic) => Some(
            panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "panic".into()),
        ),
    };
    let phases: serde_json::Map<String, serde_json::Value> = PHASES
        .iter()
        .zip(per_phase.iter_mut())
        .map(|(name, v)| (name.to_string(), json!(median(v))))
        .collect();
    let step_s = median(&mut totals);
    // two batched U-Net calls; the VAE encoder forward+backward on both inputs plus the
    // forward of the normal map's conditioning
    let unet_part = 2.0 * unet_s;
    let vae_part = 2.0 * vae_s + vae_fwd_s;
    let nerf_part = (step_s - unet_part - vae_part).max(0.0);
    let floors: Vec<_> = args
        .peak_tflops
        .iter()
        .map(|p| {
            let floor_s = args.floor_tflop / p;
            json!({ "peak_tflops": p, "floor_s_per_step": floor_s,
                "step_over_floor": step_s / floor_s,
                "floor_s_for_run": floor_s * total_steps as f64 })
        })
        .collect();
    let (gpu_start, gpu_peak) = gpu.as_ref().map(|g| g.read()).unwrap_or((None, 0));
    let doc = json!({
        "benchmark": "pipeline step",
        "machine": super::machine_description(),
        "gpu": gpu_name(),
        "device": kind.name(),
        "precision": precision.name(),
        "profile": if cfg!(debug_assertions) { "dev (deps at opt-level 3)" } else { "release" },
        "prior": args.prior, "prior_resolution": res, "prior_build_s": build_s,
        "preset": args.preset, "method": args.method, "scene": "stairs (procedural)",
        "warmup_steps": args.warmup, "timed_steps": args.steps,
        "evaluations_per_ray": "all samples (occupancy warm-up)",
        "step_s_median": step_s,
        "phases_s_median": phases,
        "components_s": { "unet_batch2": unet_s, "vae_encoder_fwd_bwd": vae_s, "vae_encoder_fwd": vae_fwd_s },
        "split_s": { "nerf": nerf_part, "unet": unet_part, "vae": vae_part },
        "split_fraction": { "nerf": nerf_part / step_s, "unet": unet_part / step_s, "vae": vae_part / step_s },
        "run_steps": total_steps,
        "projected_run_s": step_s * total_steps as f64,
        "projected_run_h": step_s * total_steps as f64 / 3600.0,
        "floor": { "tflop_per_guidance_step": args.floor_tflop, "at_peak": floors },
        "steps_failed": failure,
        "peak_rss_mb": super::peak_rss_mb(),
        "gpu_memory_mib": gpu.as_ref().map(|_| json!({ "at_start": gpu_start, "peak": gpu_peak })),
    });
    let preset_name = std::path::Path::new(&args.preset)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| args.preset.clone());
    let prior_name = if matches!(args.prior.as_str(), "sd15" | "tiny") {
        args.prior.clone()
    } else {
        "folder".to_string()
    };
    let name = format!("pipeline-{prior_name}-{preset_name}-{}.json", kind.name());
    super::write_report(&args.out, &name, &doc)?;
    Ok(())
}

/// The GPU's name from `nvidia-smi`, when there is one.
pub fn gpu_name() -> Option<String> {
    let out = std::process::Command::new("nvidia-smi")
        .args(["--query-gpu=name,driver_version", "--format=csv,noheader"])
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}
