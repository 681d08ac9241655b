//! `cargo xtask bench gpu [--smoke] [--out FILE]`: every GPU figure of the project in one
//! file, in one command sized for a short lease of a fresh GPU machine.
//!
//! A GPU machine that reaches no package registry and has no Rust toolchain (the lent
//! machines) gets a bundle made here: `bench gpu --prepare DIR` writes the running binary
//! (stripped, xz), the Vulkan loader's `.deb`, the pinned diffusers wheels and a `run.sh`
//! into DIR ([`bundle`]); there `bash DIR/run.sh` unpacks them and runs `bench gpu
//! --no-setup`. On a machine that does reach a registry, `bench gpu` without `--no-setup`
//! first makes what it needs itself ([`setup`]): the Vulkan loader through apt, a venv with
//! the pinned torch and diffusers (`tools/bench/gpu_setup.sh`), and a release build with
//! Burn's `vulkan` feature (SPIR-V; the default WGSL build when that fails to build or to
//! run a first kernel), re-running itself with `cargo run --release`.
//!
//! Then it measures, on `--device` (wgpu by default), one stage after another ([`stages`]:
//! a stage that fails is recorded with its error and the rest still run; stages after
//! `--budget-s` are skipped; the report is rewritten after each):
//! - the U-Net forward at SD-1.5-inpainting shapes (batch 2, 64x64 latent, random weights),
//!   in f16 and f32, against diffusers fp16 and fp32 on the same GPU in the same run
//!   (`tools/bench/unet_bench.py --device cuda --fp16`), with the ratios;
//! - the VAE encoder forward and backward at 512 px, against diffusers;
//! - NeRF `fast` and `balanced` steps/s on the device against flex on this machine's cores;
//! - one full gb-nerf step at the `paper` preset with an SD-1.5-sized prior, split into NeRF,
//!   U-Net and VAE (`bench pipeline`), and the projected 10k-step time;
//! - the peak GPU memory (`nvidia-smi`) over the whole run.
//!
//! Every timing keeps the first call (kernel compilation and autotuning: the cold start)
//! apart from the steady state (the fastest of the repeats after it).
//!
//! Without `--smoke` it measures a GPU card or nothing: an adapter that is no card (a CPU
//! backend, or Mesa's lavapipe, a CPU behind Vulkan) is refused with its name before anything
//! runs. The report records the adapter (name, type, kernel target, backend, driver, shader
//! compiler) and takes its file name from the adapter's name.
//!
//! `--smoke` runs the same code at tiny sizes (the built-in tiny prior's U-Net and VAE, its
//! prior in the pipeline step, a few NeRF steps, no Python reference, no setup), on any
//! device, lavapipe included, so that GPU time is never spent finding a bug.
//!
//! The U-Net and the VAE encoder are timed in f32 and, where the device has f16 tensors, in
//! f16 (`--precision f16`: f16 weights and activations, norms and softmax in f32). The
//! pipeline step runs in the device's default precision: f16 on a GPU card.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::bail;
use gb_core::{BackendKind, Precision};
use serde_json::{json, Value};

use super::pipeline::GpuMemoryPoll;
use super::{machine_description, today};

pub mod adapter;
pub mod bundle;
mod measure;
mod setup;
mod stages;

pub use adapter::Adapter;
use measure::{
    diffusers_reference, nerf_speed, pipeline_step, unet_forward, vae_encoder_fwd_bwd, Sizes,
};
use stages::StagedReport;

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
    /// Seconds for all the stages together: a stage that would start later is skipped and
    /// recorded as such (the lent GPU machines allow one command of 10 minutes).
    #[arg(long, default_value_t = 420.0, value_name = "SECONDS")]
    pub budget_s: f64,
    /// Writes the offline bundle for a GPU machine into DIR instead of measuring: this
    /// binary (stripped, xz), the Vulkan loader's .deb, the diffusers wheels and run.sh.
    #[arg(long, value_name = "DIR")]
    pub prepare: Option<PathBuf>,
    /// With --prepare: the loader's .deb files from DIR instead of `apt-get download`.
    #[arg(long, value_name = "DIR", requires = "prepare")]
    pub debs: Option<PathBuf>,
    /// With --prepare: the wheels from DIR instead of `pip download`.
    #[arg(long, value_name = "DIR", requires = "prepare")]
    pub wheels: Option<PathBuf>,
    /// With --prepare: xz's preset for the binary (9 is -9e).
    #[arg(long, default_value_t = 9, value_parser = clap::value_parser!(u32).range(0..=9), requires = "prepare")]
    pub xz_level: u32,
    /// With --prepare: the MiB that the tracked tree and the bundle may hold together (the
    /// device tool carries 64).
    #[arg(long, default_value_t = 64, value_name = "MIB", requires = "prepare")]
    pub carry_limit_mib: u64,
    /// With --prepare: copies the built-in assets into the bundle, so that a binary built
    /// without them (`--no-default-features`) runs from the bundle alone.
    #[arg(long, requires = "prepare")]
    pub with_assets: bool,
}

/// Runs the benchmark, or with `--prepare` writes the bundle (see the module docs).
pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(dir) = &args.prepare {
        let options = bundle::Options {
            dir: dir.clone(),
            binary: std::env::current_exe()?,
            debs: args.debs.clone(),
            wheels: args.wheels.clone(),
            xz_level: args.xz_level,
            limit_bytes: args.carry_limit_mib << 20,
            with_assets: args.with_assets,
        };
        let manifest = bundle::prepare(&options)?;
        println!("{}", bundle::device_instructions(dir, &manifest));
        return Ok(());
    }
    // a CPU backend is refused at once; a wgpu adapter is checked by the process that
    // measures (after the setup, which may install the Vulkan loader), so that this one holds
    // no GPU context while the release run measures the card's memory
    let cpu_backend = args.device != BackendKind::Wgpu;
    if !args.smoke && !args.no_setup && !cpu_backend {
        return setup::setup_then_rerun(&args);
    }
    if !args.budget_s.is_finite() || args.budget_s < 0.0 {
        bail!(
            "--budget-s {}: expected a number of seconds, 0 or more",
            args.budget_s
        );
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
    let kind = args.device;
    let head = json!({
        "benchmark": "gpu",
        "smoke": args.smoke,
        "date": today(),
        "machine": machine_description(),
        "gpu": super::pipeline::gpu_name(),
        "adapter": adapter.to_json(),
        "device": kind.name(),
        "wgpu_compiler": WGPU_COMPILER,
        "profile": if cfg!(debug_assertions) { "dev (deps at opt-level 3)" } else { "release" },
        "unet_shape": if args.smoke { "the tiny prior's U-Net" } else { "SD-1.5-inpainting (859.5M parameters, random weights)" },
        "unet_batch": 2,
        "unet_latent": sizes.latent,
        "vae_side": sizes.vae_side,
    });
    let mut report = StagedReport::new(
        report_path(&args, &adapter),
        head,
        Duration::from_secs_f64(args.budget_s),
    );

    let f16 = kind.device().supports_dtype(burn::tensor::DType::F16);
    let unet_f16 = if f16 {
        report.stage("unet_forward_f16", || {
            unet_forward(&sizes, kind, Precision::F16).map(measure::Timing::to_json)
        })
    } else {
        report.set("unet_f16", json!("the device has no f16 tensors"));
        None
    };
    let unet_f32 = report.stage("unet_forward_f32", || {
        unet_forward(&sizes, kind, Precision::F32).map(measure::Timing::to_json)
    });
    let python = match (&args.python, args.smoke) {
        (_, true) => {
            report.set("diffusers_reference", json!("skipped: --smoke"));
            None
        }
        (Some(p), _) if p.as_os_str() == "none" => {
            report.set("diffusers_reference", json!("skipped: --python none"));
            None
        }
        (explicit, false) => report.stage("diffusers", || {
            let py = super::python::reference_python(
                explicit
                    .as_deref()
                    .or(Some(Path::new(setup::VENV_PYTHON)).filter(|p| p.exists())),
                &["torch", "diffusers"],
            )?;
            diffusers_reference(&py, &sizes)
        }),
    };
    let vae_f32 = report.stage("vae_encoder_fwd_bwd_f32", || {
        vae_encoder_fwd_bwd(&sizes, kind, Precision::F32).map(measure::Timing::to_json)
    });
    if f16 {
        report.stage("vae_encoder_fwd_bwd_f16", || {
            vae_encoder_fwd_bwd(&sizes, kind, Precision::F16).map(measure::Timing::to_json)
        });
    }
    report.stage("nerf", || nerf_speed(&sizes, kind));
    let pipeline = report.stage("pipeline_step", || pipeline_step(&sizes, kind));

    let steady = |v: &Option<Value>| v.as_ref().and_then(|v| v["steady_s"].as_f64());
    let reference = |key: &str| -> Option<f64> {
        let v = python.as_ref()?.get(key)?;
        v.as_f64()
            .or_else(|| v.get(sizes.vae_side.to_string())?.as_f64())
    };
    let ratio = |ours: Option<f64>, theirs: Option<f64>| match (ours, theirs) {
        (Some(a), Some(b)) if b > 0.0 => json!(a / b),
        _ => Value::Null,
    };
    let step_s = pipeline.as_ref().and_then(|p| p["step_s_median"].as_f64());
    report.set(
        "ratios",
        json!({
            "unet_f16_over_diffusers_fp16": ratio(steady(&unet_f16), reference("unet_forward_fp16_s")),
            "unet_f32_over_diffusers_fp32": ratio(steady(&unet_f32), reference("unet_forward_s")),
            "vae_f32_over_diffusers": ratio(steady(&vae_f32), reference("vae_encoder_fwd_bwd_s")),
        }),
    );
    report.set(
        "projected_10k_steps_h",
        json!(step_s.map(|s| s * 10_000.0 / 3600.0)),
    );
    let (gpu_start, gpu_peak) = gpu.as_ref().map(|g| g.read()).unwrap_or((None, 0));
    report.set(
        "gpu_memory_mib",
        json!(gpu
            .as_ref()
            .map(|_| json!({ "at_start": gpu_start, "peak": gpu_peak }))),
    );
    report.set("peak_rss_mb", json!(super::peak_rss_mb()));
    report.finish()?;
    Ok(())
}

/// `--out`, else `bench/results/gpu-<adapter>-<date>.json` (`gpu-smoke-<device>-...` with
/// `--smoke`).
fn report_path(args: &Args, adapter: &Adapter) -> PathBuf {
    if let Some(out) = &args.out {
        return out.clone();
    }
    let name = if args.smoke {
        format!(
            "gpu-smoke-{}-{}-{}.json",
            args.device.name(),
            slug(Some(&adapter.name)),
            today()
        )
    } else {
        format!("gpu-{}-{}.json", slug(Some(&adapter.name)), today())
    };
    PathBuf::from("bench/results").join(name)
}

/// The shader compiler `--device wgpu` uses on a Vulkan adapter in this build.
pub const WGPU_COMPILER: &str = if cfg!(feature = "vulkan") {
    "spir-v (the `vulkan` feature: cooperative-matrix matmul and implicit-GEMM convolutions for f16)"
} else {
    "wgsl (the default build; `--features vulkan` selects SPIR-V)"
};

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
