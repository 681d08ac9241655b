//! The adapters on the tiny random-weight diffusers fixtures of sd-image: finite
//! differences through the real VAE encoder, and full steps on the tiny inpainting prior.

use std::path::PathBuf;

use burn::module::Module;
use gb_core::{read_gray, read_rgb, BackendKind, Precision};
use gb_diffusion::distill::gradient::surrogate_loss;
use gb_diffusion::distill::sd_adapter::{SdPrior, SdVaeEncoder};
use gb_diffusion::distill::{
    distill_view, DistillSettings, GuidanceMethod, LatentEncoder, LatentTarget, PriorInputMode,
    PromptCache, ScoreDistiller, ViewConditioning, ViewStepModels,
};
use gb_diffusion::models::load_vae;

use crate::distill::support::{host, rand01, randn, tensor};

fn fixture(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/sd_image")
        .join(path)
}

#[test]
fn vae_encoder_gradient_matches_finite_differences() {
    let device = BackendKind::Flex.device();
    let ad = device.clone().autodiff();
    let (vae, cfg) = load_vae(&fixture("vae"), &ad).expect("tiny vae");
    let encoder = SdVaeEncoder::new(vae.no_grad(), cfg.scale_factor());
    assert_eq!(encoder.downsample_factor(), 4);
    let (size, lat) = (16, 4);
    let image = rand01(51, 3 * size * size)
        .into_iter()
        .map(|v| 2.0 * v - 1.0)
        .collect::<Vec<_>>();
    let g = randn(52, 4 * lat * lat);
    let x = tensor(image.clone(), [1, 3, size, size], &ad).require_grad();
    let latents = encoder.encode(x.clone()).expect("encode");
    assert_eq!(latents.dims(), [1, 4, lat, lat]);
    let g_t = tensor(g.clone(), [1, 4, lat, lat], &device);
    let analytic = host(
        x.grad(&surrogate_loss(&latents, &g_t).backward())
            .expect("grad"),
    );
    let loss = |values: Vec<f32>| -> f64 {
        let z = host(
            encoder
                .encode(tensor(values, [1, 3, size, size], &ad))
                .expect("encode")
                .inner(),
        );
        z.iter().zip(&g).map(|(a, b)| *a as f64 * *b as f64).sum()
    };
    let eps = 1e-2f32;
    let scale = analytic.iter().map(|v| v.abs()).fold(0.0f32, f32::max);
    assert!(scale > 1e-3, "no gradient through the VAE encoder");
    for idx in (0..image.len()).step_by(37) {
        let (mut plus, mut minus) = (image.clone(), image.clone());
        plus[idx] += eps;
        minus[idx] -= eps;
        let numeric = ((loss(plus) - loss(minus)) / (2.0 * eps as f64)) as f32;
        assert!(
            (analytic[idx] - numeric).abs() <= 2e-2 * scale + 2e-2 * numeric.abs(),
            "pixel {idx}: autodiff {} vs finite difference {numeric} (scale {scale})",
            analytic[idx]
        );
    }
}

#[test]
fn one_step_of_each_method_on_the_tiny_inpainting_prior() {
    let device = BackendKind::Flex.device();
    let prior = SdPrior::load(
        &fixture("pipeline"),
        &gb_diffusion::distill::PriorOptions::default(),
        &device,
    )
    .expect("tiny prior");
    assert_eq!(prior.resolution, 32);
    assert_eq!(prior.alphas.len(), 1000);
    let img = read_rgb(&fixture("pipeline_image.png"), None).expect("image");
    let (mw, mh, mask) = read_gray(&fixture("pipeline_mask.png")).expect("mask");
    assert_eq!((mw, mh), (img.width, img.height));
    let (w, h) = (img.width, img.height);
    let chw: Vec<f32> = (0..3)
        .flat_map(|c| (0..h * w).map(move |i| (c, i)))
        .map(|(c, i)| img.data[i * 3 + c])
        .collect();
    let gt = tensor(chw.clone(), [1, 3, h, w], &device);
    let binary: Vec<f32> = mask
        .iter()
        .map(|v| if *v >= 0.5 { 1.0 } else { 0.0 })
        .collect();
    let view = ViewConditioning::new(
        0,
        &prior.encoder,
        gt,
        tensor(binary.clone(), [1, 1, h, w], &device),
        32,
    )
    .expect("view");
    assert_eq!(view.masked_image_latents.dims(), [1, 4, 8, 8]);
    let models = ViewStepModels {
        unet: &prior.unet,
        encoder: &prior.encoder,
    };
    let mut cache = PromptCache::new();
    for (method, batch) in [
        (
            GuidanceMethod::Sds {
                guidance_scale: 7.5,
            },
            2,
        ),
        (
            GuidanceMethod::Csd {
                w1: 7.5,
                w2: 6.5,
                w3: None,
            },
            3,
        ),
        (GuidanceMethod::Bsd { w1: 7.5, w2: 6.5 }, 2),
    ] {
        let settings = DistillSettings {
            guidance: method.clone(),
            ..DistillSettings::paper_rgb()
        };
        let mut d = ScoreDistiller::new(&settings, prior.alphas.clone(), 1).expect("distiller");
        let prompts = cache
            .for_guidance(&prior.text, d.guidance(), "a wooden bench", "blurry")
            .expect("prompts");
        assert_eq!(prompts.text.dims(), [1, 77, 16]);
        let render = tensor(
            rand01(61, 3 * h * w),
            [1, 3, h, w],
            &device.clone().autodiff(),
        )
        .require_grad();
        let out = distill_view(
            &mut d,
            &models,
            render.clone(),
            &view,
            0,
            PriorInputMode::PasteOnGroundTruth,
            &prompts,
        )
        .expect("step");
        assert_eq!(
            (out.diagnostics.unet_calls, out.diagnostics.unet_batch),
            (1, batch)
        );
        assert!(
            out.diagnostics.grad_norm.is_finite() && out.diagnostics.grad_norm > 0.0,
            "{method:?}"
        );
        let grad = host(render.grad(&out.loss.backward()).expect("grad"));
        let mut inside = 0.0f32;
        for (i, v) in grad.iter().enumerate() {
            assert!(v.is_finite());
            if binary[i % (h * w)] == 0.0 {
                assert_eq!(*v, 0.0, "{method:?}: pixel {i} outside the mask");
            } else {
                inside = inside.max(v.abs());
            }
        }
        assert!(inside > 0.0, "{method:?}: no gradient inside the mask");
    }
    // Three distinct prompts: "a wooden bench", "" and "blurry".
    assert_eq!(cache.len(), 3);
}

/// The render's gradient from one step of `method` at `t` on the tiny inpainting prior in
/// `precision` (flex), with its latent gradient norm.
fn render_gradient(precision: Precision, method: &GuidanceMethod, t: f64) -> (Vec<f32>, f64) {
    let device = BackendKind::Flex.device();
    let prior = SdPrior::load(
        &fixture("pipeline"),
        &gb_diffusion::distill::PriorOptions {
            precision: Some(precision),
            ..Default::default()
        },
        &device,
    )
    .unwrap();
    let (h, w) = (32, 32);
    let ad = device.clone().autodiff();
    let gt = tensor(rand01(7, 3 * h * w), [1, 3, h, w], &device);
    let mask: Vec<f32> = (0..h * w)
        .map(|i| if i % w >= w / 2 { 1.0 } else { 0.0 })
        .collect();
    let view = ViewConditioning::new(
        0,
        &prior.encoder,
        gt,
        tensor(mask, [1, 1, h, w], &device),
        32,
    )
    .unwrap();
    let settings = DistillSettings {
        guidance: method.clone(),
        ..DistillSettings::paper_rgb()
    };
    let mut d = ScoreDistiller::new(&settings, prior.alphas.clone(), 3).unwrap();
    let prompts = PromptCache::new()
        .for_guidance(&prior.text, d.guidance(), "a wooden bench", "blurry")
        .unwrap();
    let render = tensor(rand01(61, 3 * h * w), [1, 3, h, w], &ad).require_grad();
    let target = LatentTarget {
        latents: prior
            .encoder
            .encode(render.clone().mul_scalar(2.0).sub_scalar(1.0))
            .unwrap(),
        mask_latent: view.mask_latent.clone(),
        masked_image_latents: view.masked_image_latents.clone(),
        prompts: &prompts,
    };
    let out = d.step_at(&prior.unet, target, t).unwrap();
    let norm = out.diagnostics.grad_norm;
    (host(render.grad(&out.loss.backward()).expect("grad")), norm)
}

/// f16 at the extremes of the guidance: t = 0.02 and 0.98 with weights of 100. The image
/// gradient stays finite, and points the way the f32 one does (cosine above 0.95; the step's
/// gradient norm within 5%).
#[test]
fn f16_guidance_at_t_and_weight_extremes_stays_finite_and_follows_f32() {
    for method in [
        GuidanceMethod::Bsd {
            w1: 100.0,
            w2: 99.0,
        },
        GuidanceMethod::Sds {
            guidance_scale: 100.0,
        },
    ] {
        for t in [0.02, 0.98] {
            let (g16, n16) = render_gradient(Precision::F16, &method, t);
            let (g32, n32) = render_gradient(Precision::F32, &method, t);
            assert!(
                g16.iter().all(|v| v.is_finite()),
                "{method:?} t={t}: non-finite"
            );
            let dot: f64 = g16
                .iter()
                .zip(&g32)
                .map(|(a, b)| (*a as f64) * (*b as f64))
                .sum();
            let norm = |g: &[f32]| g.iter().map(|v| (*v as f64).powi(2)).sum::<f64>().sqrt();
            let cosine = dot / (norm(&g16) * norm(&g32));
            let norm_err = ((n16 - n32) / n32).abs();
            println!(
                "{method:?} t={t}: cosine {cosine:.5}, latent-gradient norm {n16:.4e} vs {n32:.4e}"
            );
            assert!(norm(&g32) > 0.0, "{method:?} t={t}: no f32 gradient");
            assert!(cosine > 0.95, "{method:?} t={t}: cosine {cosine}");
            assert!(norm_err < 0.05, "{method:?} t={t}: norm {n16} vs {n32}");
        }
    }
}
