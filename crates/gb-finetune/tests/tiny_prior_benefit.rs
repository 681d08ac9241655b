//! The shipped tiny prior (`assets/tiny-prior`) measurably helps, on held-out procedural
//! pairs (seeds 101-102, never trained on):
//! - its 2D inpainting (the mean of a few samples, known region blended in, see
//!   `gb_finetune::train::validate`) beats the mean-colour and the nearest-pixel fills on
//!   masked PSNR;
//! - its RGB / normal LoRA lowers the masked angular error of normal-map inpainting
//!   against the base without it.
//!
//! The full figures (more samples) are in `assets/tiny-prior/training/summary.json` and
//! `cargo xtask finetune --synthetic --base tiny --validate-only` reproduces them.

use gb_core::BackendKind;
use gb_diffusion::pipeline::SdComponents;
use gb_finetune::captions::CaptionMode;
use gb_finetune::masks::MaskConfig;
use gb_finetune::synthetic::SyntheticPairs;
use gb_finetune::tiny_prior::{SyntheticData, TinyPriorRecipe};
use gb_finetune::train::vae_stage::reconstruction_psnr;
use gb_finetune::train::validate::{validate, ValidationReport, ValidationSettings};

fn settings() -> ValidationSettings {
    ValidationSettings {
        resolution: 64,
        samples: 6,
        ddim_steps: 20,
        mode: CaptionMode::Captions,
        normals: true,
        seed: 7,
        mask: MaskConfig {
            min_coverage: 0.05,
            max_coverage: 0.4,
            ..MaskConfig::default()
        },
        average: 4,
        blend_known: true,
    }
}

/// The recipe's held-out pairs.
fn held_out() -> SyntheticPairs {
    SyntheticData::builtin().held_out().expect("held-out pairs")
}

fn report(lora: bool) -> ValidationReport {
    // draws from Burn's process-global device RNG (crate::DEVICE_RNG)
    let _rng = crate::DEVICE_RNG.lock().unwrap_or_else(|e| e.into_inner());
    let dir = gb_core::tiny_prior_dir();
    let device = BackendKind::Flex.device();
    let val = held_out();
    let prior = SdComponents::load_inpainting(&dir, &device).expect("the shipped tiny prior loads");
    let prior = if lora {
        prior
            .with_lora(&dir.join("pytorch_lora_weights.safetensors"))
            .expect("its LoRA attaches")
            .0
    } else {
        prior
    };
    validate(&prior, &val, &settings()).expect("validation runs")
}

#[test]
fn the_shipped_prior_beats_the_fills_and_its_lora_lowers_the_normal_error() {
    let base = report(false);
    let with = report(true);
    eprintln!("base: {base:?}\nwith LoRA: {with:?}");
    let ours = with
        .prior_averaged
        .as_ref()
        .and_then(|s| s.rgb_masked_psnr)
        .expect("averaged RGB score");
    let mean = with.fill_mean.rgb_masked_psnr.expect("mean fill score");
    let nearest = with
        .fill_nearest
        .rgb_masked_psnr
        .expect("nearest fill score");
    assert!(
        ours > mean && ours > nearest,
        "prior {ours:.2} dB vs mean fill {mean:.2} dB, nearest fill {nearest:.2} dB"
    );
    let angle = |r: &ValidationReport| {
        r.prior_averaged
            .as_ref()
            .and_then(|s| s.normal_angular_error_deg)
            .expect("averaged normal score")
    };
    assert!(
        angle(&with) < angle(&base),
        "normal error with LoRA {:.1} deg vs base {:.1} deg",
        angle(&with),
        angle(&base)
    );
}

/// The recipe in `configs/tiny-prior` is the one the shipped prior came from: its data are
/// the built-in synthetic data, the held-out seeds are not trained on, and its networks have
/// the shipped prior's shapes.
#[test]
fn the_recipe_matches_the_shipped_prior() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/tiny-prior");
    let recipe = TinyPriorRecipe::load(&root.join("recipe.toml")).expect("recipe.toml reads");
    assert_eq!(recipe.data, SyntheticData::builtin());
    for s in &recipe.data.train_seeds {
        assert!(
            !recipe.data.val_seeds.contains(s),
            "seed {s} is trained and held out"
        );
    }
    let read = |p: std::path::PathBuf| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(&p).expect("config reads")).expect("JSON")
    };
    let shipped = gb_core::tiny_prior_dir();
    for (net, keys) in [
        ("vae", &["latent_channels", "block_out_channels"][..]),
        (
            "unet",
            &["in_channels", "out_channels", "block_out_channels"][..],
        ),
    ] {
        let (a, b) = (
            read(root.join(net).join("config.json")),
            read(shipped.join(net).join("config.json")),
        );
        for k in keys {
            assert_eq!(a[k], b[k], "{net}/config.json: {k}");
        }
    }
}

/// The autoencoder's held-out reconstruction PSNR must stay above this (dB). The shipped
/// one (4 latent channels, 300 steps) scores 26.9 dB on these crops: the ceiling of the
/// prior's fills. Trained for 2000 steps it reached 31.9 dB (8 channels: 31.7 dB), but the
/// base prior trained on that latent sampled worse
/// (`bench/results/tiny-prior-retrain-2026-12-02.json`).
const AUTOENCODER_PSNR_FLOOR: f64 = 26.0;

/// The shipped autoencoder's reconstruction of the held-out pairs, the ceiling of every
/// fill.
#[test]
fn the_shipped_autoencoder_reconstructs_the_held_out_pairs() {
    let device = BackendKind::Flex.device();
    let prior =
        SdComponents::load_inpainting(&gb_core::tiny_prior_dir(), &device).expect("prior loads");
    let psnr = reconstruction_psnr(&prior.vae, &held_out(), 64, &device).expect("runs");
    eprintln!("autoencoder PSNR {psnr:.2} dB");
    assert!(psnr > AUTOENCODER_PSNR_FLOOR, "{psnr:.2} dB");
}
