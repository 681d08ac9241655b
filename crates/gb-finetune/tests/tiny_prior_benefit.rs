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
use gb_diffusion::inpaint::InpaintPrior;
use gb_finetune::captions::CaptionMode;
use gb_finetune::masks::MaskConfig;
use gb_finetune::synthetic::SyntheticPairs;
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

fn report(lora: bool) -> ValidationReport {
    let dir = gb_core::tiny_prior_dir();
    let device = BackendKind::Flex.device();
    let val = SyntheticPairs::generate(&["stairs", "fence"], &[101, 102], 96, 72)
        .expect("held-out pairs");
    let prior = InpaintPrior::load(&dir, &device).expect("the shipped tiny prior loads");
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
