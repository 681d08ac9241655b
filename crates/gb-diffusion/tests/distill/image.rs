//! Score distillation into an image's pixels (`distill-image`'s library half) on the tiny
//! inpainting prior: Burn's Adam moves exactly the masked pixels, by its first step's size.

use std::path::PathBuf;

use gb_core::{read_gray, read_rgb, BackendKind, RgbImage};
use gb_diffusion::distill::image::{ImageDistillConfig, ImageDistillation};
use gb_diffusion::distill::{DistillError, DistillSettings, SdPrior};

fn fixture(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/sd_image")
        .join(path)
}

/// The tiny inpainting prior (resolution 32) and its fixture image.
fn tiny_prior_and_image() -> (SdPrior, RgbImage) {
    let prior = SdPrior::load(
        &fixture("pipeline"),
        &gb_diffusion::distill::PriorOptions::default(),
        &BackendKind::Flex.device(),
    )
    .expect("tiny prior");
    let image = read_rgb(&fixture("pipeline_image.png"), None).expect("image");
    (prior, image)
}

/// BSD at the paper's weights, with Adam at `lr`.
fn config(lr: f64, seed: u64) -> ImageDistillConfig {
    ImageDistillConfig {
        settings: DistillSettings::paper_rgb(),
        lr,
        seed,
        resolution: None,
    }
}

#[test]
fn adam_moves_only_the_masked_pixels_by_its_learning_rate_on_the_first_step() {
    let (prior, image) = tiny_prior_and_image();
    let (_, _, grey) = read_gray(&fixture("pipeline_mask.png")).expect("mask");
    let mask: Vec<f32> = grey.iter().map(|v| f32::from(*v >= 0.5)).collect();
    let inside = mask.iter().filter(|m| **m > 0.0).count();
    assert!(inside > 0 && inside < mask.len());
    let lr = 0.01;
    let cfg = config(lr, 3);
    let mut d = ImageDistillation::new(&prior, &image, &mask, "a photo", "blurry", &cfg)
        .expect("distillation");
    assert_eq!(d.resolution(), 32);
    assert_eq!(d.guidance_name(), "bsd");
    let diag = d.step().expect("step");
    assert!(diag.loss.is_finite() && diag.grad_norm > 0.0, "{diag:?}");
    let after = d.image().expect("image");
    assert_eq!((after.width, after.height), (image.width, image.height));
    let (mut at_lr, mut moved_max) = (0usize, 0.0f32);
    for (p, m) in mask.iter().enumerate() {
        for c in 0..3 {
            let (a, b) = (image.data[p * 3 + c], after.data[p * 3 + c]);
            if *m == 0.0 {
                assert_eq!(a, b, "pixel {p} channel {c} outside the mask moved");
                continue;
            }
            let step = (b - a).abs();
            moved_max = moved_max.max(step);
            // Adam's first step is lr * g / (|g| + eps): lr, unless clamped to [0, 1]
            let clamped = b == 0.0 || b == 1.0;
            if (step - lr as f32).abs() < 1e-4 || clamped {
                at_lr += 1;
            }
        }
    }
    assert!(
        moved_max <= lr as f32 + 1e-5,
        "a step larger than lr: {moved_max}"
    );
    assert!(
        at_lr * 10 >= inside * 3 * 9,
        "{at_lr} of {} masked values moved by lr",
        inside * 3
    );
    // a second step continues Adam's state: the image keeps changing
    d.step().expect("second step");
    assert_ne!(d.image().expect("image").data, after.data);
}

#[test]
fn a_mask_of_another_size_and_a_zero_learning_rate_are_refused() {
    let (prior, image) = tiny_prior_and_image();
    let mut cfg = config(0.01, 0);
    let short = vec![1.0; image.width * image.height - 1];
    let err = ImageDistillation::new(&prior, &image, &short, "a", "", &cfg).err();
    assert!(
        matches!(err, Some(DistillError::Shape { tensor: "mask", .. })),
        "{err:?}"
    );
    cfg.lr = 0.0;
    let full = vec![1.0; image.width * image.height];
    let err = ImageDistillation::new(&prior, &image, &full, "a", "", &cfg).err();
    assert!(
        matches!(err, Some(DistillError::Config { field: "lr", .. })),
        "{err:?}"
    );
}
