//! `cargo xtask inpaint-image`: 2D inpainting with a Stable Diffusion inpainting prior
//! (DDIM, classifier-free guidance). It shows that a prior folder loads and works.

use std::path::PathBuf;

use anyhow::{bail, Context};
use gb_core::{read_gray, read_rgb, write_rgb_png, BackendKind, RgbImage};
use gb_diffusion::inpaint::{inpaint, InpaintRequest};
use gb_diffusion::pipeline::SdComponents;
use indicatif::ProgressStyle;

/// Arguments of `cargo xtask inpaint-image`.
#[derive(clap::Args)]
pub struct Args {
    /// `tiny` (the built-in prior), a diffusers-layout inpainting folder (tokenizer,
    /// text_encoder, unet with 9 input channels, vae, scheduler) or a cached hub id.
    #[arg(long)]
    prior: String,
    /// LoRA files (.safetensors) merged into the U-Net and text encoder, in order (repeat the
    /// flag: a prior's geometric LoRA, then a run's per-scene `personalize/lora.safetensors`).
    #[arg(long)]
    lora: Vec<PathBuf>,
    /// Input image (PNG/JPEG); its size must be a multiple of the VAE factor (8 for SD).
    #[arg(long)]
    image: PathBuf,
    /// Mask (white = repaint), same size as the image.
    #[arg(long)]
    mask: PathBuf,
    /// Prompt.
    #[arg(long)]
    prompt: String,
    /// Negative prompt (the unconditional input of the guidance).
    #[arg(long, default_value = "")]
    negative_prompt: String,
    /// DDIM steps.
    #[arg(long, default_value_t = 50)]
    steps: usize,
    /// Guidance scale (diffusers convention; no guidance when <= 1).
    #[arg(long, default_value_t = 7.5)]
    guidance: f64,
    /// Seed of the initial noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output PNG.
    #[arg(long)]
    out: PathBuf,
    /// Keep the known region on the image's noised latent after each step (RePaint-style
    /// blending; off: diffusers' 9-channel pipeline exactly).
    #[arg(long)]
    blend_known: bool,
    /// Backend: ndarray, flex (default) or wgpu.
    #[arg(long, value_enum)]
    device: Option<BackendKind>,
}

/// Loads the prior, inpaints the image and writes the PNG.
pub fn run(args: Args) -> anyhow::Result<()> {
    if args.steps == 0 {
        bail!("--steps must be at least 1");
    }
    if !args.guidance.is_finite() {
        bail!("--guidance must be a finite number");
    }
    let img = read_rgb(&args.image, Some([1.0, 1.0, 1.0]))
        .with_context(|| format!("reading --image {}", args.image.display()))?;
    let (mw, mh, mask) =
        read_gray(&args.mask).with_context(|| format!("reading --mask {}", args.mask.display()))?;
    if (mw, mh) != (img.width, img.height) {
        bail!(
            "mask {} is {mw}x{mh} but image {} is {}x{}",
            args.mask.display(),
            args.image.display(),
            img.width,
            img.height
        );
    }
    let kind = args.device.unwrap_or_default();
    let device = kind.device();
    let prior_dir = gb_diffusion::checkpoint::resolve_prior(&args.prior)?;
    let mut prior = SdComponents::load_inpainting(&prior_dir, &device)
        .with_context(|| format!("loading prior {}", prior_dir.display()))?;
    for lora in &args.lora {
        prior = prior
            .with_lora(lora)
            .with_context(|| format!("--lora {}", lora.display()))?
            .0;
    }
    tracing::info!(device = %kind, steps = args.steps, "prior loaded from {}", prior_dir.display());

    let req = InpaintRequest {
        width: img.width,
        height: img.height,
        rgb: img.data,
        mask,
        prompt: args.prompt,
        negative_prompt: args.negative_prompt,
        steps: args.steps,
        guidance: args.guidance,
        seed: args.seed,
        init_latents: None,
        blend_known: args.blend_known,
    };
    let bar = gb_core::progress::bar(args.steps as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{bar:40} {pos}/{len} t={msg} [{elapsed_precise}<{eta_precise}]",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let image = inpaint(&prior, &req, |_, t| {
        bar.set_message(t.to_string());
        bar.inc(1);
    })?;
    bar.finish();

    let [_, _, h, w] = image.dims();
    let chw: Vec<f32> = image
        .into_data()
        .convert::<f32>()
        .try_to_vec()
        .map_err(|e| anyhow::anyhow!("reading the result back: {e:?}"))?;
    let mut data = vec![0f32; h * w * 3];
    for c in 0..3 {
        for i in 0..h * w {
            data[i * 3 + c] = chw[c * h * w + i];
        }
    }
    if let Some(parent) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("creating {}", parent.display()))?;
    }
    write_rgb_png(
        &args.out,
        &RgbImage {
            width: w,
            height: h,
            data,
        },
    )
    .with_context(|| format!("writing {}", args.out.display()))?;
    println!("wrote {}", args.out.display());
    Ok(())
}
