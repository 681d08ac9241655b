//! `cargo xtask distill-image`: the 2D score-distillation playground. Optimises the pixels
//! inside a mask directly with SDS, CSD or BSD through a Stable Diffusion prior, writing a
//! PNG every N steps, a grid at the end and a JSON-lines log (loss, gradient norm, t).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use gb_core::{read_rgb, write_rgb_png, BackendKind, RgbImage};
use gb_diffusion::distill::image::{ImageDistillConfig, ImageDistillation};
use gb_diffusion::distill::{
    DistillSettings, GuidanceMethod, PriorOptions, SdPrior, TimestepConfig, Weighting,
};
use indicatif::ProgressStyle;

/// Arguments of `distill-image`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The prior: `tiny` (the built-in prior), a diffusers-layout folder (unet/, vae/,
    /// text_encoder/, tokenizer/, scheduler/) or a cached hub id.
    #[arg(long)]
    pub prior: String,
    /// The image (PNG/JPEG).
    #[arg(long)]
    pub image: PathBuf,
    /// The mask (white or 1 = pixels to optimise), same size as the image.
    #[arg(long)]
    pub mask: PathBuf,
    /// The prompt.
    #[arg(long)]
    pub prompt: String,
    /// The negative prompt (CSD, BSD).
    #[arg(long, default_value = "")]
    pub negative_prompt: String,
    /// Guidance method: sds (guidance scale = --w1), csd (w1, w2, w3; w3 defaults to
    /// w2 - w1) or bsd (w1, w2).
    #[arg(long, default_value = "bsd", value_parser = ["sds", "csd", "bsd"])]
    pub method: String,
    /// w1 (SDS: the guidance scale, diffusers' convention).
    #[arg(long, default_value_t = 7.5)]
    pub w1: f32,
    /// w2.
    #[arg(long, default_value_t = 6.5)]
    pub w2: f32,
    /// w3 (CSD only; default w2 - w1).
    #[arg(long)]
    pub w3: Option<f32>,
    /// Optimisation steps.
    #[arg(long, default_value_t = 200)]
    pub steps: usize,
    /// Adam learning rate on the pixels (values in [0, 1]).
    #[arg(long, default_value_t = 0.01)]
    pub lr: f32,
    /// Seed of the timesteps and noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Write a PNG every this many steps.
    #[arg(long, default_value_t = 50)]
    pub save_every: usize,
    /// Prior input resolution (default: the prior's native one).
    #[arg(long)]
    pub resolution: Option<usize>,
    /// Use w(t) = 1 instead of 1 - alpha_bar.
    #[arg(long)]
    pub constant_weight: bool,
    /// Clamp the latent gradient to [-c, c].
    #[arg(long)]
    pub grad_clamp: Option<f32>,
    /// Compute backend.
    #[arg(long, value_enum)]
    pub device: Option<BackendKind>,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs the playground.
pub fn run(args: Args) -> anyhow::Result<()> {
    if args.steps == 0 || args.save_every == 0 {
        bail!("--steps and --save-every must be > 0");
    }
    if !(args.lr.is_finite() && args.lr > 0.0) {
        bail!("--lr must be a positive number, got {}", args.lr);
    }
    let image = read_rgb(&args.image, None).with_context(|| "reading --image".to_string())?;
    let mask = read_mask(&args.mask, image.width, image.height)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;

    let device = args.device.unwrap_or_default().device();
    let prior_dir = gb_diffusion::checkpoint::resolve_prior(&args.prior)?;
    let prior = SdPrior::load(&prior_dir, &PriorOptions::default(), &device)
        .with_context(|| format!("loading the prior from {}", prior_dir.display()))?;
    let guidance = GuidanceMethod::from_weights(&args.method, args.w1, args.w2, args.w3)
        .with_context(|| format!("--method {}: expected sds, csd or bsd", args.method))?;
    let cfg = ImageDistillConfig {
        settings: DistillSettings {
            guidance,
            timesteps: TimestepConfig::default(),
            weighting: if args.constant_weight {
                Weighting::Constant
            } else {
                Weighting::OneMinusAlphaBar
            },
            grad_clamp: args.grad_clamp,
        },
        lr: f64::from(args.lr),
        seed: args.seed,
        resolution: args.resolution,
    };
    let mut distillation = ImageDistillation::new(
        &prior,
        &image,
        &mask,
        &args.prompt,
        &args.negative_prompt,
        &cfg,
    )?;
    tracing::info!(
        method = distillation.guidance_name(),
        resolution = distillation.resolution(),
        bbox = ?distillation.mask_box(),
        "distilling {} ({}x{}) for {} steps",
        args.image.display(),
        image.width,
        image.height,
        args.steps
    );

    let mut snapshots = vec![image.clone()];
    let mut log = String::new();
    let bar = gb_core::progress::bar(args.steps as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    for step in 1..=args.steps {
        let d = distillation.step()?;
        bar.set_message(format!(
            "t={} loss={:.3e} |g|={:.3e}",
            d.timestep, d.loss, d.grad_norm
        ));
        bar.inc(1);
        tracing::debug!(
            step,
            t = d.timestep,
            loss = d.loss,
            grad_norm = d.grad_norm,
            "step"
        );
        log.push_str(&serde_json::to_string(&serde_json::json!({
            "step": step, "t": d.timestep, "weight": d.weight, "loss": d.loss,
            "grad_norm": d.grad_norm, "unet_calls": d.unet_calls, "unet_batch": d.unet_batch,
        }))?);
        log.push('\n');
        if step % args.save_every == 0 || step == args.steps {
            let snap = distillation.image()?;
            write_rgb_png(&args.out.join(format!("step_{step:05}.png")), &snap)?;
            snapshots.push(snap);
        }
    }
    bar.finish();
    gb_core::write_atomic(&args.out.join("log.jsonl"), log.as_bytes())?;
    write_rgb_png(&args.out.join("grid.png"), &grid(&snapshots))?;
    tracing::info!(
        "wrote {} snapshots and grid.png to {}",
        snapshots.len() - 1,
        args.out.display()
    );
    Ok(())
}

/// Reads `--mask` as 0/1 values with the scenes' reader ([`gb_nerf::scene::masks::read_mask`]:
/// 0/1 or 0/255, binary), refusing a size other than the image's and an empty mask.
fn read_mask(path: &Path, width: usize, height: usize) -> anyhow::Result<Vec<f32>> {
    let mut fitted = Vec::new();
    let mask = gb_nerf::scene::masks::read_mask(path, width, height, &mut fitted)
        .with_context(|| "reading --mask".to_string())?;
    if !fitted.is_empty() {
        bail!(
            "{}: the mask is not the image's size {width}x{height} (--mask must match --image)",
            path.display()
        );
    }
    if !mask.data.iter().any(|&b| b) {
        bail!("{}: the mask is empty (no white pixel)", path.display());
    }
    Ok(mask
        .data
        .iter()
        .map(|&b| if b { 1.0 } else { 0.0 })
        .collect())
}

/// The snapshots side by side (input first).
fn grid(images: &[RgbImage]) -> RgbImage {
    let (w, h) = (images[0].width, images[0].height);
    let mut out = RgbImage::filled(w * images.len(), h, [1.0, 1.0, 1.0]);
    for (i, img) in images.iter().enumerate() {
        for y in 0..h {
            for x in 0..w {
                out.set(i * w + x, y, img.get(x, y));
            }
        }
    }
    out
}
