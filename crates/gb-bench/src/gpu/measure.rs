//! What `bench gpu` times: the U-Net and the VAE encoder, the pipeline step, the NeRF, and
//! the diffusers reference.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use anyhow::Context;
use burn::module::Module;
use burn::tensor::{Distribution, Tensor};
use gb_core::{BackendKind, Precision};
use gb_diffusion::config::{AutoencoderKLConfig, UNet2DConditionConfig};
use gb_diffusion::models::{AutoencoderKL, UNet2DConditionModel};
use gb_diffusion::precision::cast_frozen;
use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};
use gb_nerf::scene::LoadOptions;
use gb_nerf::train::{NerfConfig, Trainer};
use serde_json::{json, Value};

/// The sizes measured: SD-1.5's on a GPU, the tiny prior's in a smoke run.
pub(super) struct Sizes {
    pub(super) unet: UNet2DConditionConfig,
    pub(super) vae: AutoencoderKLConfig,
    pub(super) latent: usize,
    pub(super) vae_side: usize,
    pub(super) pipeline_prior: &'static str,
    pub(super) pipeline_preset: &'static str,
    pub(super) nerf_presets: &'static [&'static str],
    pub(super) nerf_steps: usize,
    pub(super) repeats: usize,
}

impl Sizes {
    pub(super) fn new(smoke: bool) -> anyhow::Result<Self> {
        if smoke {
            let tiny = gb_core::tiny_prior_dir();
            Ok(Self {
                unet: UNet2DConditionConfig::from_file(&tiny.join("unet/config.json"))?,
                vae: AutoencoderKLConfig::from_file(&tiny.join("vae/config.json"))?,
                latent: 8,
                vae_side: 32,
                pipeline_prior: "tiny",
                pipeline_preset: "fast",
                nerf_presets: &["fast"],
                nerf_steps: 2,
                repeats: 1,
            })
        } else {
            Ok(Self {
                unet: crate::unet::sd15_inpainting_unet()?,
                vae: crate::unet::sd15_vae()?,
                latent: 64,
                vae_side: 512,
                pipeline_prior: "sd15",
                pipeline_preset: "paper",
                nerf_presets: &["fast", "balanced"],
                nerf_steps: 20,
                repeats: 3,
            })
        }
    }
}

/// A timed call: the first (cold: kernel compilation and autotuning happen there) apart from
/// the fastest of the steady repeats after it.
#[derive(Debug, Clone, Copy)]
pub(super) struct Timing {
    /// Seconds of the first call.
    pub(super) first_s: f64,
    /// Seconds of the fastest later call.
    pub(super) steady_s: f64,
    /// How many later calls were timed.
    pub(super) repeats: usize,
}

impl Timing {
    /// The report's object: `{first_call_s, steady_s, repeats}`.
    pub(super) fn to_json(self) -> Value {
        json!({ "first_call_s": self.first_s, "steady_s": self.steady_s, "repeats": self.repeats })
    }
}

/// One cold call, then the fastest of `repeats` timed calls.
fn time_best(repeats: usize, mut f: impl FnMut() -> anyhow::Result<()>) -> anyhow::Result<Timing> {
    let s = Instant::now();
    f()?;
    let first_s = s.elapsed().as_secs_f64();
    let mut best = f64::INFINITY;
    for _ in 0..repeats.max(1) {
        let s = Instant::now();
        f()?;
        best = best.min(s.elapsed().as_secs_f64());
    }
    Ok(Timing {
        first_s,
        steady_s: best,
        repeats: repeats.max(1),
    })
}

/// Waits for the device: reads one number that depends on `t`.
fn sync<const D: usize>(t: Tensor<D>) -> f32 {
    t.sum().into_scalar::<f32>()
}

/// U-Net forward seconds, batch 2, random weights, in `precision`.
pub(super) fn unet_forward(
    sizes: &Sizes,
    kind: BackendKind,
    precision: Precision,
) -> anyhow::Result<Timing> {
    let device = kind.device();
    let unet = cast_frozen(UNet2DConditionModel::new(&sizes.unet, &device), precision);
    let ctx = sizes.unet.cross_attention_dim;
    let x = Tensor::<4>::random(
        [2, sizes.unet.in_channels, sizes.latent, sizes.latent],
        Distribution::Normal(0.0, 1.0),
        &device,
    );
    let ehs = Tensor::<3>::random([2, 77, ctx], Distribution::Normal(0.0, 1.0), &device);
    let t = vec![500.0f32; 2];
    time_best(sizes.repeats, || {
        sync(unet.forward(x.clone(), &t, ehs.clone()));
        Ok(())
    })
}

/// VAE encoder forward and backward seconds (frozen weights in `precision`, gradient to the
/// image).
pub(super) fn vae_encoder_fwd_bwd(
    sizes: &Sizes,
    kind: BackendKind,
    precision: Precision,
) -> anyhow::Result<Timing> {
    let ad = kind.autodiff_device();
    let vae = cast_frozen(AutoencoderKL::new(&sizes.vae, &ad), precision).no_grad();
    let side = sizes.vae_side;
    time_best(sizes.repeats, || {
        let img = Tensor::<4>::random([1, 3, side, side], Distribution::Uniform(-1.0, 1.0), &ad)
            .require_grad();
        let grads = vae.encode_mean(img.clone()).sum().backward();
        let g = img.grad(&grads).context("no image gradient")?;
        sync(g);
        Ok(())
    })
}

/// `bench pipeline` at the sizes' prior and preset, into a temporary folder; its report.
pub(super) fn pipeline_step(sizes: &Sizes, kind: BackendKind) -> anyhow::Result<Value> {
    let tmp = tempfile::tempdir()?;
    let args = crate::pipeline::Args {
        prior: sizes.pipeline_prior.into(),
        preset: sizes.pipeline_preset.into(),
        method: "gb-nerf".into(),
        steps: sizes.repeats,
        warmup: 1,
        device: Some(kind),
        precision: None,
        floor_tflop: 4.0,
        peak_tflops: Vec::new(),
        out: tmp.path().to_path_buf(),
    };
    crate::pipeline::run(args)?;
    let file = std::fs::read_dir(tmp.path())?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|e| e == "json"))
        .context("bench pipeline wrote no report")?;
    let text = std::fs::read_to_string(&file)?;
    let mut doc: Value = serde_json::from_str(&text)?;
    if let Some(o) = doc.as_object_mut() {
        o.remove("machine");
    }
    Ok(doc)
}

/// NeRF training steps/s per preset on `kind` and on flex (stairs, in the occupancy
/// warm-up: every sample evaluated), with the ratio.
pub(super) fn nerf_speed(sizes: &Sizes, kind: BackendKind) -> anyhow::Result<Value> {
    let tmp = tempfile::tempdir()?;
    let dir = tmp.path().join("stairs");
    let options = ProceduralOptions {
        name: SceneName::Stairs,
        ..Default::default()
    };
    procedural::write(&options, &dir).context("generating stairs")?;
    let (_, scene) = gb_nerf::scene::load(&dir, &LoadOptions::default())?;
    let mut rows = Vec::new();
    for preset in sizes.nerf_presets {
        let cfg = NerfConfig::preset(preset)?;
        // (steps/s, seconds of the first two steps: the cold start)
        let speed = |device: BackendKind| -> anyhow::Result<(f64, f64)> {
            let mut t = Trainer::new(&scene, cfg.clone(), device)?;
            let s = Instant::now();
            for _ in 0..2 {
                t.train_step()?;
            }
            let cold = s.elapsed().as_secs_f64();
            let s = Instant::now();
            for _ in 0..sizes.nerf_steps {
                t.train_step()?;
            }
            Ok((sizes.nerf_steps as f64 / s.elapsed().as_secs_f64(), cold))
        };
        let (on_device, device_cold) = speed(kind)?;
        let (on_flex, flex_cold) = speed(BackendKind::Flex)?;
        rows.push(json!({
            "preset": preset,
            "device": kind.name(),
            "steps_per_s": { "device": on_device, "flex": on_flex },
            "first_two_steps_s": { "device": device_cold, "flex": flex_cold },
            "device_over_flex": on_device / on_flex,
        }));
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    Ok(json!({
        "scene": "stairs (procedural)",
        "timed_steps": sizes.nerf_steps,
        "flex_cores": cores,
        "presets": rows,
    }))
}

/// `tools/bench/unet_bench.py` on the GPU (`--device cuda --fp16`): U-Net fp32 and fp16 and
/// the VAE encoder.
pub(super) fn diffusers_reference(python: &Path, sizes: &Sizes) -> anyhow::Result<Value> {
    let out = Command::new(python)
        .arg("tools/bench/unet_bench.py")
        .args(["--latent", &sizes.latent.to_string(), "--batch", "2"])
        .args([
            "--repeats",
            &sizes.repeats.to_string(),
            "--device",
            "cuda",
            "--fp16",
        ])
        .args(["--vae-sizes", &sizes.vae_side.to_string()])
        .output()
        .with_context(|| format!("{}: cannot start", python.display()))?;
    if !out.status.success() {
        let stderr = String::from_utf8_lossy(&out.stderr);
        anyhow::bail!(
            "{} tools/bench/unet_bench.py: {}",
            python.display(),
            stderr.lines().last().unwrap_or("failed")
        );
    }
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(text.lines().last().unwrap_or(""))
        .context("tools/bench/unet_bench.py: unparsable output")
}
