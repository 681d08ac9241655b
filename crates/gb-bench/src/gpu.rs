//! `cargo xtask bench gpu [--smoke] [--out FILE]`: every GPU figure of the project in one
//! file, in one command sized for a short lease of a fresh GPU machine.
//!
//! Without `--smoke` (on the GPU machine) it first makes what it needs:
//! - the Vulkan loader (`libvulkan1`, through apt when missing; the NVIDIA driver brings its
//!   own ICD) and a venv with the pinned torch and diffusers (`tools/bench/gpu_setup.sh`);
//! - a release build with Burn's `vulkan` feature (SPIR-V; the default WGSL build when that
//!   fails to build or to run a first kernel): from a debug build it re-runs itself with
//!   `cargo run --release`.
//!
//! Then it measures, on `--device` (wgpu by default):
//! - the U-Net forward at SD-1.5-inpainting shapes (batch 2, 64x64 latent, random weights),
//!   against diffusers fp32 and fp16 on the same GPU in the same run
//!   (`tools/bench/unet_bench.py --device cuda --fp16`), with the ratios;
//! - the VAE encoder forward and backward at 512 px, against diffusers;
//! - one full gb-nerf step at the `paper` preset with an SD-1.5-sized prior, split into NeRF,
//!   U-Net and VAE (`bench pipeline`), and the projected 10k-step time;
//! - NeRF `fast` and `balanced` steps/s on the device against flex on this machine's cores;
//! - the peak GPU memory (`nvidia-smi`) over the whole run.
//!
//! Without `--smoke` it measures a GPU card or nothing: an adapter that is no card (a CPU
//! backend, or Mesa's lavapipe, a CPU behind Vulkan) is refused with its name before anything
//! runs. The report records the adapter (name, type, kernel target, backend, driver) and
//! takes its file name from the adapter's name.
//!
//! `--smoke` runs the same code at tiny sizes (the built-in tiny prior's U-Net and VAE, its
//! prior in the pipeline step, a few NeRF steps, no Python reference, no setup), on any
//! device, lavapipe included, so that GPU time is never spent finding a bug.
//!
//! The U-Net and the VAE encoder are timed in f32 and, where the device has f16 tensors, in
//! f16 (`--precision f16`: f16 weights and activations, norms and softmax in f32). The
//! pipeline step runs in the device's default precision: f16 on a GPU card.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{bail, Context};
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

use super::pipeline::GpuMemoryPoll;
use super::{machine_description, today, write_report};

/// Arguments of `cargo xtask bench gpu`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Tiny sizes, no setup, no Python reference: checks the whole command on any device.
    #[arg(long)]
    pub smoke: bool,
    /// The report (default: `bench/results/gpu-<gpu>-<date>.json`, or `gpu-smoke-<device>-<date>.json`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The device measured.
    #[arg(long, default_value = "wgpu", value_enum)]
    pub device: BackendKind,
    /// Python with torch and diffusers for the reference (default: the venv that the setup
    /// makes, else $GB_PYTHON, else python3); `none` skips it. Never used with `--smoke`.
    #[arg(long)]
    pub python: Option<PathBuf>,
    /// Skips the setup (packages, venv) and the release re-run.
    #[arg(long)]
    pub no_setup: bool,
}

/// The sizes measured: SD-1.5's on a GPU, the tiny prior's in a smoke run.
struct Sizes {
    unet: UNet2DConditionConfig,
    vae: AutoencoderKLConfig,
    latent: usize,
    vae_side: usize,
    pipeline_prior: &'static str,
    pipeline_preset: &'static str,
    nerf_presets: &'static [&'static str],
    nerf_steps: usize,
    repeats: usize,
}

impl Sizes {
    fn new(smoke: bool) -> anyhow::Result<Self> {
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
                unet: super::unet::sd15_inpainting_unet()?,
                vae: super::unet::sd15_vae()?,
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

/// Runs the benchmark (see the module docs).
pub fn run(args: Args) -> anyhow::Result<()> {
    // a CPU backend is refused at once; a wgpu adapter is checked by the process that
    // measures (after the setup, which may install the Vulkan loader), so that this one holds
    // no GPU context while the release run measures the card's memory
    let cpu_backend = args.device != BackendKind::Wgpu;
    if !args.smoke && !args.no_setup && !cpu_backend {
        return setup_then_rerun(&args);
    }
    let adapter = Adapter::open(args.device);
    if !args.smoke && !adapter.is_card {
        let cause = adapter
            .error
            .as_deref()
            .map(|e| format!("; it did not open: {e}"))
            .unwrap_or_default();
        bail!(
            "--device {}: the adapter '{}' is no GPU card ({}{cause}): bench gpu would time a \
             CPU. Run it on a GPU card, or add --smoke to check the command on any device",
            args.device.name(),
            adapter.name,
            adapter.kind()
        );
    }
    let sizes = Sizes::new(args.smoke)?;
    let gpu = GpuMemoryPoll::start();
    let started = Instant::now();
    let kind = args.device;
    let reference = match (&args.python, args.smoke) {
        (_, true) => None,
        (Some(p), _) if p.as_os_str() == "none" => None,
        (explicit, false) => Some(super::python::reference_python(
            explicit
                .as_deref()
                .or(Some(Path::new(VENV_PYTHON)).filter(|p| p.exists())),
            &["torch", "diffusers"],
        )?),
    };

    tracing::info!(device = %kind, smoke = args.smoke, "U-Net and VAE encoder");
    let f16 = kind.device().supports_dtype(burn::tensor::DType::F16);
    let unet = unet_forward(&sizes, kind, Precision::F32)?;
    let unet_f16 = f16
        .then(|| unet_forward(&sizes, kind, Precision::F16))
        .transpose()?;
    let vae = vae_encoder_fwd_bwd(&sizes, kind, Precision::F32)?;
    let vae_f16 = f16
        .then(|| vae_encoder_fwd_bwd(&sizes, kind, Precision::F16))
        .transpose()?;
    let python = match reference.as_deref() {
        Some(py) => diffusers_reference(py, &sizes),
        None => json!({ "skipped": if args.smoke { "--smoke" } else { "--python none" } }),
    };
    let ratio = |rust: f64, key: &str| -> Value {
        match python.get(key).and_then(Value::as_f64) {
            Some(p) if p > 0.0 => json!(rust / p),
            _ => Value::Null,
        }
    };
    let vae_key = sizes.vae_side.to_string();
    let vae_ref = python
        .get("vae_encoder_fwd_bwd_s")
        .and_then(|v| v.get(&vae_key))
        .and_then(Value::as_f64);

    tracing::info!("one gb-nerf step with the prior");
    let pipeline = pipeline_step(&sizes, kind)?;
    tracing::info!("NeRF steps/s on the device and on flex");
    let nerf = nerf_speed(&sizes, kind)?;

    let (gpu_start, gpu_peak) = gpu.as_ref().map(|g| g.read()).unwrap_or((None, 0));
    let gpu_label = super::pipeline::gpu_name();
    let step_s = pipeline["step_s_median"].as_f64();
    let doc = json!({
        "benchmark": "gpu",
        "smoke": args.smoke,
        "date": today(),
        "machine": machine_description(),
        "gpu": gpu_label,
        "adapter": adapter.to_json(),
        "device": kind.name(),
        "wgpu_compiler": WGPU_COMPILER,
        "profile": if cfg!(debug_assertions) { "dev (deps at opt-level 3)" } else { "release" },
        "unet": {
            "shape": if args.smoke { "the tiny prior's U-Net" } else { "SD-1.5-inpainting (859.5M parameters, random weights)" },
            "batch": 2, "latent": sizes.latent,
            "unet_forward_f32_s": unet,
            "unet_forward_f16_s": unet_f16,
            "unet_f16_status": if f16 { "measured (--precision f16: f16 weights and activations, f32 norms and softmax)" } else { "the device has no f16 tensors" },
            "diffusers_unet_forward_fp32_s": python.get("unet_forward_s"),
            "diffusers_unet_forward_fp16_s": python.get("unet_forward_fp16_s"),
            "unet_f32_ratio_vs_diffusers_fp32": ratio(unet, "unet_forward_s"),
            "unet_f16_ratio_vs_diffusers_fp16": unet_f16.map_or(Value::Null, |s| ratio(s, "unet_forward_fp16_s")),
        },
        "vae_encoder": {
            "side": sizes.vae_side,
            "vae_encoder_fwd_bwd_s": vae,
            "vae_encoder_fwd_bwd_f16_s": vae_f16,
            "diffusers_vae_encoder_fwd_bwd_s": vae_ref,
            "vae_ratio_vs_diffusers": vae_ref.filter(|p| *p > 0.0).map(|p| vae / p),
        },
        "pipeline_step": pipeline,
        "projected_10k_steps_s": step_s.map(|s| s * 10_000.0),
        "projected_10k_steps_h": step_s.map(|s| s * 10_000.0 / 3600.0),
        "nerf": nerf,
        "diffusers": python,
        "gpu_memory_mib": gpu.as_ref().map(|_| json!({ "at_start": gpu_start, "peak": gpu_peak })),
        "peak_rss_mb": super::peak_rss_mb(),
        "wall_s": started.elapsed().as_secs_f64(),
    });
    let name = match (&args.out, args.smoke) {
        (Some(_), _) => String::new(),
        (None, true) => format!(
            "gpu-smoke-{}-{}-{}.json",
            kind.name(),
            slug(Some(&adapter.name)),
            today()
        ),
        (None, false) => format!("gpu-{}-{}.json", slug(Some(&adapter.name)), today()),
    };
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("bench/results").join(name));
    let dir = out.parent().unwrap_or(Path::new("."));
    let file = out
        .file_name()
        .context("--out names no file")?
        .to_string_lossy()
        .into_owned();
    write_report(dir, &file, &doc)?;
    Ok(())
}

/// The adapter that a backend opens (module docs).
#[derive(Debug, Clone)]
pub struct Adapter {
    /// The backend.
    pub backend: BackendKind,
    /// The name the device gives itself (`NVIDIA H100 80GB HBM3`, `llvmpipe (LLVM 15.0.6,
    /// 256 bits)`), or the backend's for a CPU backend.
    pub name: String,
    /// What its kernels are compiled for (CubeCL's fingerprint), when it reports one.
    pub target: Option<String>,
    /// Whether it is a GPU card ([`gb_core::backend::is_gpu_card`]).
    pub is_card: bool,
    /// Why it could not be opened, when it could not.
    pub error: Option<String>,
}

impl Adapter {
    /// Opens `backend`'s device and reads who it is; a device that fails to open (no Vulkan
    /// loader) is an adapter that is no card, with the failure.
    pub fn open(backend: BackendKind) -> Self {
        let opened = std::panic::catch_unwind(|| backend.device().identity());
        let (identity, error) = match opened {
            Ok(id) => (id, None),
            Err(e) => (
                None,
                Some(
                    e.downcast_ref::<String>()
                        .cloned()
                        .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
                        .unwrap_or_else(|| "the device failed to open".into()),
                ),
            ),
        };
        Self {
            backend,
            name: match (&identity, &error) {
                (Some(id), _) => id.name.clone(),
                (None, Some(_)) => format!("{} (did not open)", backend.name()),
                (None, None) => format!("{} (CPU backend)", backend.name()),
            },
            target: identity.as_ref().map(|id| id.fingerprint.clone()),
            is_card: identity.is_some_and(|id| id.physical.is_some()),
            error,
        }
    }

    /// Its type in words.
    pub fn kind(&self) -> &'static str {
        match (self.is_card, self.backend) {
            (true, _) => "gpu card",
            (false, BackendKind::Wgpu) => {
                "no card: a CPU or a software rasterizer such as lavapipe"
            }
            (false, _) => "cpu",
        }
    }

    /// The report's `adapter` section: name, type, kernel target, backend, shader compiler,
    /// and the driver (`nvidia-smi`'s, on a card that has it).
    pub fn to_json(&self) -> Value {
        let driver = if self.is_card {
            super::pipeline::gpu_name()
                .and_then(|g| g.split(',').nth(1).map(|d| d.trim().to_string()))
        } else {
            None
        };
        json!({
            "name": self.name,
            "type": self.kind(),
            "is_gpu_card": self.is_card,
            "target": self.target,
            "backend": self.backend.name(),
            "shader_compiler": (self.backend == BackendKind::Wgpu).then_some(WGPU_COMPILER),
            "driver": driver,
            "error": self.error,
        })
    }
}

/// The shader compiler `--device wgpu` uses on a Vulkan adapter in this build.
pub const WGPU_COMPILER: &str = if cfg!(feature = "vulkan") {
    "spir-v (the `vulkan` feature: cooperative-matrix matmul and implicit-GEMM convolutions for f16)"
} else {
    "wgsl (the default build; `--features vulkan` selects SPIR-V)"
};

/// The venv `tools/bench/gpu_setup.sh` makes.
const VENV_PYTHON: &str = ".venv-gpu/bin/python";

/// Installs what the GPU run needs, then runs this benchmark again in release with
/// `--no-setup` and the same arguments.
fn setup_then_rerun(args: &Args) -> anyhow::Result<()> {
    let python_given = args.python.is_some();
    if !python_given {
        let status = Command::new("bash")
            .arg("tools/bench/gpu_setup.sh")
            .status()
            .context("tools/bench/gpu_setup.sh: cannot start bash")?;
        if !status.success() {
            bail!("tools/bench/gpu_setup.sh failed ({status})");
        }
    }
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    // Burn's `vulkan` feature (SPIR-V, tensor-core matmul and convolutions for f16) when it
    // builds and its first kernels run on this adapter (Mesa 22.3's lavapipe crashes creating
    // a SPIR-V pipeline); otherwise the default WGSL build, with a warning
    let vulkan = Command::new(&cargo)
        .args(["run", "--quiet", "--release", "--package", "xtask"])
        .args([
            "--features",
            "vulkan",
            "--",
            "devices",
            "--device",
            args.device.name(),
        ])
        .status()
        .is_ok_and(|s| s.success());
    if !vulkan {
        tracing::warn!(
            "the `vulkan` feature did not build or run on this adapter: measuring the WGSL build"
        );
    }
    let mut cmd = Command::new(&cargo);
    cmd.args(["run", "--quiet", "--release", "--package", "xtask"]);
    if vulkan {
        cmd.args(["--features", "vulkan"]);
    }
    cmd.arg("--")
        .args(["bench", "gpu", "--no-setup", "--device", args.device.name()]);
    if let Some(out) = &args.out {
        cmd.arg("--out").arg(out);
    }
    if let Some(py) = &args.python {
        cmd.arg("--python").arg(py);
    }
    let status = cmd.status().context("cannot start cargo")?;
    if !status.success() {
        bail!("the release run of bench gpu failed ({status})");
    }
    Ok(())
}

/// Fastest of `repeats` timed calls after one warm-up call.
fn time_best(repeats: usize, mut f: impl FnMut() -> anyhow::Result<()>) -> anyhow::Result<f64> {
    f()?;
    let mut best = f64::INFINITY;
    for _ in 0..repeats.max(1) {
        let s = Instant::now();
        f()?;
        best = best.min(s.elapsed().as_secs_f64());
    }
    Ok(best)
}

/// Waits for the device: reads one number that depends on `t`.
fn sync<const D: usize>(t: Tensor<D>) -> f32 {
    t.sum().into_scalar::<f32>()
}

/// U-Net forward seconds, batch 2, random weights, in `precision`.
fn unet_forward(sizes: &Sizes, kind: BackendKind, precision: Precision) -> anyhow::Result<f64> {
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
fn vae_encoder_fwd_bwd(
    sizes: &Sizes,
    kind: BackendKind,
    precision: Precision,
) -> anyhow::Result<f64> {
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
fn pipeline_step(sizes: &Sizes, kind: BackendKind) -> anyhow::Result<Value> {
    let tmp = tempfile::tempdir()?;
    let args = super::pipeline::Args {
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
    super::pipeline::run(args)?;
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
fn nerf_speed(sizes: &Sizes, kind: BackendKind) -> anyhow::Result<Value> {
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
        let speed = |device: BackendKind| -> anyhow::Result<f64> {
            let mut t = Trainer::new(&scene, cfg.clone(), device)?;
            for _ in 0..2 {
                t.train_step()?;
            }
            let s = Instant::now();
            for _ in 0..sizes.nerf_steps {
                t.train_step()?;
            }
            Ok(sizes.nerf_steps as f64 / s.elapsed().as_secs_f64())
        };
        let on_device = speed(kind)?;
        let on_flex = speed(BackendKind::Flex)?;
        rows.push(json!({
            "preset": preset,
            "device": kind.name(),
            "steps_per_s": { "device": on_device, "flex": on_flex },
            "device_over_flex": on_device / on_flex,
        }));
    }
    Ok(json!({ "scene": "stairs (procedural)", "timed_steps": sizes.nerf_steps, "presets": rows }))
}

/// `tools/bench/unet_bench.py` on the GPU (`--device cuda --fp16`): U-Net fp32 and fp16 and
/// the VAE encoder; on failure the object says why.
fn diffusers_reference(python: &Path, sizes: &Sizes) -> Value {
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
        .output();
    match out {
        Ok(out) if out.status.success() => {
            let text = String::from_utf8_lossy(&out.stdout);
            serde_json::from_str(text.lines().last().unwrap_or(""))
                .unwrap_or_else(|e| json!({ "error": format!("unparsable output: {e}") }))
        }
        Ok(out) => json!({ "error": String::from_utf8_lossy(&out.stderr)
            .lines().last().unwrap_or("failed").to_string() }),
        Err(e) => json!({ "error": format!("{}: {e}", python.display()) }),
    }
}

/// A file-name form of the GPU's name (`NVIDIA H200, 570.1` -> `nvidia-h200`).
fn slug(gpu: Option<&str>) -> String {
    let name = gpu.and_then(|g| g.split(',').next()).unwrap_or("unknown");
    let s: String = name
        .trim()
        .to_ascii_lowercase()
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .collect();
    s.split('-')
        .filter(|p| !p.is_empty())
        .collect::<Vec<_>>()
        .join("-")
}

#[cfg(test)]
mod tests {
    use super::slug;

    #[test]
    fn gpu_names_become_file_names() {
        assert_eq!(slug(Some("NVIDIA H200, 570.86.15")), "nvidia-h200");
        assert_eq!(slug(Some("NVIDIA H100 80GB HBM3")), "nvidia-h100-80gb-hbm3");
        assert_eq!(slug(None), "unknown");
    }
}
