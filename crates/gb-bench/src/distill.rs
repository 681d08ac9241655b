//! `cargo xtask distill-bench`: times one guidance step (VAE encoder forward and backward +
//! the one batched U-Net call) for SDS, CSD and BSD on a prior, and BSD's saving over CSD
//! as a ratio from the same run; writes `bench/results/distill-<device>.json`.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use burn::tensor::{Tensor, TensorData};
use gb_core::BackendKind;
use gb_diffusion::distill::sd_adapter::SdPrior;
use gb_diffusion::distill::{
    distill_view, DistillSettings, GuidanceMethod, PriorInputMode, PromptCache, ScoreDistiller,
    ViewConditioning, ViewStepModels,
};

/// Arguments of `distill-bench`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Diffusers-layout prior folder.
    #[arg(long)]
    pub prior: PathBuf,
    /// Timed steps per method (after one warm-up step).
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
    /// Prior input resolution (default: the prior's native one).
    #[arg(long)]
    pub resolution: Option<usize>,
    /// Compute backend.
    #[arg(long, value_enum)]
    pub device: Option<BackendKind>,
    /// Output JSON (default `bench/results/distill-<device>.json`).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Runs the benchmark.
pub fn run(args: Args) -> anyhow::Result<()> {
    let kind = args.device.unwrap_or_default();
    let device = kind.device();
    let prior = SdPrior::load(
        &args.prior,
        &gb_diffusion::distill::PriorOptions::default(),
        &device,
    )
    .with_context(|| format!("loading the prior from {}", args.prior.display()))?;
    let res = args.resolution.unwrap_or(prior.resolution);
    let repeats = args.repeats.max(1);
    let pixels: Vec<f32> = (0..3 * res * res)
        .map(|i| ((i * 7919) % 997) as f32 / 997.0)
        .collect();
    let mask: Vec<f32> = (0..res * res)
        .map(|i| {
            if (i % res) >= res / 4 && (i % res) < 3 * res / 4 {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    let image = Tensor::<4>::from_data(TensorData::new(pixels, [1, 3, res, res]), &device);
    let mask = Tensor::<4>::from_data(TensorData::new(mask, [1, 1, res, res]), &device);
    let view = ViewConditioning::new(0, &prior.encoder, image.clone(), mask, res)?;
    let models = ViewStepModels {
        unet: &prior.unet,
        encoder: &prior.encoder,
    };
    let mut cache = PromptCache::new();
    // The methods take turns step by step, so that other load on a shared CPU falls on all
    // three alike and the ratio stays fair.
    let mut runs = Vec::new();
    for method in [
        GuidanceMethod::Sds {
            guidance_scale: 7.5,
        },
        GuidanceMethod::Csd {
            w1: 7.5,
            w2: 6.5,
            w3: None,
        },
        GuidanceMethod::Bsd { w1: 7.5, w2: 6.5 },
    ] {
        let settings = DistillSettings {
            guidance: method,
            ..DistillSettings::paper_rgb()
        };
        let distiller = ScoreDistiller::new(&settings, prior.alphas.clone(), 0)?;
        let prompts = cache.for_guidance(&prior.text, distiller.guidance(), "a photo", "blurry")?;
        runs.push((distiller, prompts, Vec::new(), 0usize));
    }
    for i in 0..=repeats {
        for (distiller, prompts, times, batch) in &mut runs {
            let start = Instant::now();
            let render = image.clone().autodiff().require_grad();
            let out = distill_view(
                distiller,
                &models,
                render.clone(),
                &view,
                0,
                PriorInputMode::RenderOnly,
                prompts,
            )?;
            let grads = out.loss.backward();
            let g = render.grad(&grads).context("no gradient")?;
            let _sync: f32 = g.sum().into_scalar::<f32>();
            *batch = out.diagnostics.unet_batch;
            if i > 0 {
                times.push(start.elapsed().as_secs_f64() * 1e3);
            }
        }
    }
    let mut rows = Vec::new();
    for (distiller, _, mut times, batch) in runs {
        times.sort_by(f64::total_cmp);
        let median = times[times.len() / 2];
        tracing::info!(
            method = distiller.guidance().name(),
            batch,
            median_ms = median,
            "step time"
        );
        rows.push((distiller.guidance().name(), batch, median, times));
    }
    let ms = |name: &str| {
        rows.iter()
            .find(|r| r.0 == name)
            .map(|r| r.2)
            .unwrap_or(f64::NAN)
    };
    let min_ms = |name: &str| {
        rows.iter()
            .find(|r| r.0 == name)
            .and_then(|r| r.3.first().copied())
            .unwrap_or(f64::NAN)
    };
    let machine = super::machine_description();
    let json = serde_json::json!({
        "benchmark": "distill step (VAE encoder fwd+bwd + one batched U-Net call)",
        "prior": args.prior.display().to_string(),
        "resolution": res,
        "device": kind.name(),
        "machine": machine,
        "profile": if cfg!(debug_assertions) { "debug" } else { "release" },
        "repeats": repeats,
        "methods": rows.iter().map(|(name, batch, median, times)| serde_json::json!({
            "method": name, "unet_batch": batch, "median_ms": median, "min_ms": times[0], "times_ms": times,
        })).collect::<Vec<_>>(),
        "bsd_over_csd_time_ratio": ms("bsd") / ms("csd"),
        "bsd_saving_over_csd": 1.0 - ms("bsd") / ms("csd"),
        // The fastest step is the least disturbed by other load on a shared CPU.
        "bsd_over_csd_min_time_ratio": min_ms("bsd") / min_ms("csd"),
    });
    let out = args
        .out
        .unwrap_or_else(|| PathBuf::from(format!("bench/results/distill-{}.json", kind.name())));
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    gb_core::write_atomic(&out, serde_json::to_string_pretty(&json)?.as_bytes())?;
    println!("{}", serde_json::to_string_pretty(&json)?);
    Ok(())
}
