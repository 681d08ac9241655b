//! The adapters on the tiny random-weight diffusers fixtures of sd-image: finite
//! differences through the real VAE encoder, and full steps on the tiny inpainting prior.

use std::path::PathBuf;

use burn::module::Module;
use gb_core::{read_gray, read_rgb, BackendKind};
use gb_diffusion::distill::gradient::surrogate_loss;
use gb_diffusion::distill::sd_adapter::{SdPrior, SdVaeEncoder};
use gb_diffusion::distill::{
    distill_view, DistillSettings, GuidanceMethod, LatentEncoder, PriorInputMode, PriorModels,
    PromptCache, ScoreDistiller, ViewConditioning,
};
use gb_diffusion::models::load_vae;

use crate::support::{host, rand01, randn, tensor};

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
    let prior = SdPrior::load(&fixture("pipeline"), &device).expect("tiny prior");
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
    let models = PriorModels {
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
