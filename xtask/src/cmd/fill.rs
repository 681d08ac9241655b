//! `cargo xtask fill`: a reference view filled in 2D (`gb_inpaint::fill`), for
//! `inpaint --reference VIEW=IMAGE`.
//!
//! ```text
//! cargo xtask fill --scene DIR --view VIEW --out IMAGE [--with fsr|smooth|prior]  (default fsr)
//!     [--prior tiny|DIR|HUB_ID]
//!     [--lora FILE ...] [--prompt P] [--negative-prompt N] [--steps 50] [--guidance 7.5]
//!     [--seed 0] [--device D]
//! ```

use std::path::PathBuf;

use anyhow::Context;
use gb_core::BackendKind;
use gb_inpaint::fill::{fill, FillOptions, FillWith};
use gb_inpaint::PromptOverrides;

/// Arguments of `cargo xtask fill`.
#[derive(clap::Args)]
pub struct Args {
    /// The scene folder.
    #[arg(long)]
    scene: PathBuf,
    /// A training view's file name (or stem) with a mask.
    #[arg(long)]
    view: String,
    /// Output PNG: the view at its full size, the masked pixels filled.
    #[arg(long)]
    out: PathBuf,
    /// The fill: `fsr` (frequency-selective reconstruction, no weights; the default),
    /// `smooth` (the membrane fill, no weights) or `prior` (the diffusion prior; the flags
    /// below).
    #[arg(long, value_enum, default_value_t = With::Fsr)]
    with: With,
    /// `tiny` (the built-in prior), a diffusers inpainting folder or a hub id.
    #[arg(long, default_value = "tiny")]
    prior: String,
    /// LoRA files merged in order (default: the prior's own geometric LoRA, the one the
    /// guided methods use, when it has one).
    #[arg(long)]
    lora: Vec<PathBuf>,
    /// Prompt (default: "RGB image, " and the scene's caption).
    #[arg(long)]
    prompt: Option<String>,
    /// Negative prompt (default: "RGB image, " and the removed object's caption).
    #[arg(long)]
    negative_prompt: Option<String>,
    /// DDIM steps.
    #[arg(long, default_value_t = 50)]
    steps: usize,
    /// Classifier-free guidance scale.
    #[arg(long, default_value_t = 7.5)]
    guidance: f64,
    /// Seed of the initial noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Backend: flex (default), ndarray or wgpu.
    #[arg(long, value_enum)]
    device: Option<BackendKind>,
}

/// `--with`.
#[derive(Clone, Copy, clap::ValueEnum)]
enum With {
    Fsr,
    Smooth,
    Prior,
}

/// Fills the view and writes the PNG.
pub fn run(args: Args) -> anyhow::Result<()> {
    let opts = FillOptions {
        with: match args.with {
            With::Fsr => FillWith::Fsr,
            With::Smooth => FillWith::Smooth,
            With::Prior => FillWith::Prior,
        },
        prior: args.prior,
        lora: (!args.lora.is_empty()).then_some(args.lora),
        prompts: PromptOverrides {
            appearance: args.prompt,
            negative: args.negative_prompt,
            geometry: None,
        },
        steps: args.steps,
        guidance: args.guidance,
        seed: args.seed,
        device: args.device.unwrap_or_default(),
        ..FillOptions::default()
    };
    let filled = fill(&args.scene, &args.view, &opts)?;
    gb_core::write_rgb_png(&args.out, &filled.image)
        .with_context(|| format!("--out {}", args.out.display()))?;
    println!(
        "wrote {} ({} masked pixels of {} filled by {}); use it with: inpaint --scene {} --reference {}.png={}",
        args.out.display(),
        filled.filled_pixels,
        filled.view,
        filled.with.name(),
        args.scene.display(),
        filled.view,
        args.out.display()
    );
    Ok(())
}
