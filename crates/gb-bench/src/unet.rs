//! `cargo xtask bench unet`: U-Net forward time and peak memory at the real
//! SD-1.5-inpainting size (random weights), and VAE encoder forward+backward, against
//! diffusers doing the same on the same machine in the same run
//! (`tools/bench/unet_bench.py`). Writes `bench/results/unet-<device>.json`.
//!
//! Peak memory is the process's peak resident set (`VmHWM`), weights included; on wgpu it
//! does not see GPU memory.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::bail;
use burn::module::Module;
use burn::tensor::{Distribution, Tensor};
use gb_core::BackendKind;
use gb_diffusion::config::{AutoencoderKLConfig, UNet2DConditionConfig};
use gb_diffusion::models::{AutoencoderKL, UNet2DConditionModel};
use serde_json::{json, Value};

/// Arguments of `cargo xtask bench unet`.
#[derive(clap::Args)]
pub struct Args {
    /// Latent side (32 on the CPU, 64 = 512x512 images on a GPU).
    #[arg(long, default_value_t = 32)]
    latent: usize,
    /// Batch (2 = classifier-free guidance).
    #[arg(long, default_value_t = 2)]
    batch: usize,
    /// Image sides for the VAE encoder forward+backward.
    #[arg(long, value_delimiter = ',', default_values_t = vec![256usize])]
    vae_sizes: Vec<usize>,
    /// Timed repetitions after one warm-up (the fastest is kept).
    #[arg(long, default_value_t = 1)]
    repeats: usize,
    /// Backend: ndarray, flex (default) or wgpu.
    #[arg(long, value_enum)]
    device: Option<BackendKind>,
    /// Python with torch and diffusers (default: $GB_PYTHON, else python3 on PATH;
    /// `bash tools/bench/make_venv.sh` makes the pinned one); `none` skips the reference.
    #[arg(long)]
    python: Option<PathBuf>,
    /// Threads for torch (default: all logical cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Device of the diffusers reference: `cpu`, or `cuda` on a GPU machine.
    #[arg(long, default_value = "cpu")]
    python_device: String,
    /// Output folder.
    #[arg(long, default_value = "bench/results")]
    out: PathBuf,
}

/// SD-1.5-inpainting's `unet/config.json` (stable-diffusion-v1-5/stable-diffusion-inpainting).
pub fn sd15_inpainting_unet() -> anyhow::Result<UNet2DConditionConfig> {
    serde_json::from_value(json!({
        "in_channels": 9, "out_channels": 4, "sample_size": 64, "layers_per_block": 2,
        "block_out_channels": [320, 640, 1280, 1280], "cross_attention_dim": 768,
        "attention_head_dim": 8, "norm_num_groups": 32,
        "down_block_types": ["CrossAttnDownBlock2D", "CrossAttnDownBlock2D", "CrossAttnDownBlock2D", "DownBlock2D"],
        "up_block_types": ["UpBlock2D", "CrossAttnUpBlock2D", "CrossAttnUpBlock2D", "CrossAttnUpBlock2D"]
    }))
    .map_err(|e| anyhow::anyhow!("built-in SD-1.5 config: {e}"))
}

/// SD-1.5's `vae/config.json`.
pub fn sd15_vae() -> anyhow::Result<AutoencoderKLConfig> {
    serde_json::from_value(json!({
        "block_out_channels": [128, 256, 512, 512], "layers_per_block": 2, "latent_channels": 4,
        "norm_num_groups": 32,
        "down_block_types": ["DownEncoderBlock2D", "DownEncoderBlock2D", "DownEncoderBlock2D", "DownEncoderBlock2D"],
        "up_block_types": ["UpDecoderBlock2D", "UpDecoderBlock2D", "UpDecoderBlock2D", "UpDecoderBlock2D"]
    }))
    .map_err(|e| anyhow::anyhow!("built-in SD-1.5 config: {e}"))
}

fn time_best(repeats: usize, mut f: impl FnMut()) -> f64 {
    f();
    (0..repeats.max(1))
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Runs the benchmark and writes its JSON.
pub fn run(args: Args) -> anyhow::Result<()> {
    if args.latent == 0 || !args.latent.is_multiple_of(8) || args.batch == 0 {
        bail!("--latent must be a positive multiple of 8 and --batch at least 1");
    }
    if args.vae_sizes.iter().any(|&s| s == 0 || s % 8 != 0) {
        bail!("--vae-sizes must be positive multiples of 8");
    }
    // The diffusers reference runs after the Rust timing: check its packages first.
    let reference = match args.python.as_deref() {
        Some(p) if p.as_os_str() == "none" => None,
        explicit => Some(super::python::reference_python(
            explicit,
            &["torch", "diffusers"],
        )?),
    };
    let kind = args.device.unwrap_or_default();
    let device = kind.device();
    let cfg = sd15_inpainting_unet()?;

    tracing::info!(device = %kind, "building the SD-1.5-inpainting U-Net (random weights)");
    let unet = UNet2DConditionModel::new(&cfg, &device);
    let x = Tensor::<4>::random(
        [args.batch, 9, args.latent, args.latent],
        Distribution::Normal(0.0, 1.0),
        &device,
    );
    let ehs = Tensor::<3>::random(
        [args.batch, 77, 768],
        Distribution::Normal(0.0, 1.0),
        &device,
    );
    let t = vec![500.0f32; args.batch];
    let unet_s = time_best(args.repeats, || {
        let out = unet.forward(x.clone(), &t, ehs.clone());
        let _ = out.into_data();
    });
    let unet_rss = super::peak_rss_mb();
    drop(unet);

    let ad = device.clone().autodiff();
    // Frozen weights, gradient to the image only, as the guidance step and the reference do.
    let vae = AutoencoderKL::new(&sd15_vae()?, &ad).no_grad();
    let mut vae_times = serde_json::Map::new();
    for &size in &args.vae_sizes {
        tracing::info!(size, "VAE encoder forward+backward");
        let s = time_best(args.repeats, || {
            let img =
                Tensor::<4>::random([1, 3, size, size], Distribution::Uniform(-1.0, 1.0), &ad)
                    .require_grad();
            let grads = vae.encode_mean(img.clone()).sum().backward();
            let _ = img.grad(&grads).map(|g| g.into_data());
        });
        vae_times.insert(size.to_string(), json!(s));
    }
    let rust = json!({
        "device": kind.to_string(),
        "profile": if cfg!(debug_assertions) { "debug" } else { "release" },
        "unet_forward_s": unet_s,
        "unet_peak_rss_mb": unet_rss,
        "vae_encoder_fwd_bwd_s": vae_times,
        "peak_rss_mb": super::peak_rss_mb(),
    });
    let python = run_python(&args, reference.as_deref());
    let ratio = |k: &str| -> Value {
        match (rust[k].as_f64(), python.get(k).and_then(Value::as_f64)) {
            (Some(r), Some(p)) if p > 0.0 => json!(r / p),
            _ => Value::Null,
        }
    };
    let mut vae_ratio = serde_json::Map::new();
    for (size, r) in rust["vae_encoder_fwd_bwd_s"]
        .as_object()
        .into_iter()
        .flatten()
    {
        let p = python
            .get("vae_encoder_fwd_bwd_s")
            .and_then(|v| v.get(size))
            .and_then(Value::as_f64);
        if let (Some(r), Some(p)) = (r.as_f64(), p) {
            vae_ratio.insert(size.clone(), json!(r / p));
        }
    }
    let doc = json!({
        "benchmark": "unet",
        "machine": super::machine_description(),
        "unet": "SD-1.5-inpainting shape (859.5M parameters, random weights)",
        "latent": args.latent,
        "batch": args.batch,
        "rust": rust,
        "python": python,
        "ratio_rust_over_python": { "unet_forward": ratio("unet_forward_s"), "vae_encoder_fwd_bwd": vae_ratio },
    });
    super::write_report(&args.out, &format!("unet-{kind}.json"), &doc)?;
    Ok(())
}

/// Runs tools/bench/unet_bench.py; on failure the JSON records why.
fn run_python(args: &Args, python: Option<&Path>) -> Value {
    let Some(python) = python else {
        return json!({ "skipped": "--python none" });
    };
    let threads = args.threads.unwrap_or_else(|| {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    });
    let mut cmd = Command::new(python);
    cmd.arg("tools/bench/unet_bench.py")
        .args([
            "--latent",
            &args.latent.to_string(),
            "--batch",
            &args.batch.to_string(),
        ])
        .args([
            "--threads",
            &threads.to_string(),
            "--repeats",
            &args.repeats.to_string(),
        ])
        .args(["--device", &args.python_device])
        .arg("--vae-sizes")
        .args(args.vae_sizes.iter().map(|s| s.to_string()));
    match cmd.output() {
        Ok(out) if out.status.success() => {
            let text = String::from_utf8_lossy(&out.stdout);
            serde_json::from_str(text.lines().last().unwrap_or(""))
                .unwrap_or_else(|e| json!({ "error": format!("unparsable output: {e}") }))
        }
        Ok(out) => {
            json!({ "error": String::from_utf8_lossy(&out.stderr).lines().last().unwrap_or("failed").to_string() })
        }
        Err(e) => json!({ "error": format!("{}: {e}", python.display()) }),
    }
}
