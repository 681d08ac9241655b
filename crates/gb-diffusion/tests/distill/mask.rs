//! The gradient is exactly zero outside the mask.

use gb_core::BackendKind;
use gb_diffusion::distill::{
    distill_view, DistillSettings, GuidanceMethod, PriorInputMode, PromptEmbeddings,
    ScoreDistiller, TimestepConfig, ViewConditioning, ViewStepModels, Weighting,
};

use crate::distill::fixture::{half_mask, sd_alphas, Scene, LH, LW, TIMESTEP};
use crate::distill::support::{
    host, max_abs, rand01, randn, tensor, ConvEncoder, LinearPoolEncoder, MockUnet,
};

#[test]
fn latent_gradient_is_zero_outside_the_latent_mask() {
    let device = BackendKind::Flex.device();
    let scene = Scene::new(&device, half_mask(), None);
    let encoder = LinearPoolEncoder::new(&device);
    for method in [
        GuidanceMethod::Sds {
            guidance_scale: 100.0,
        },
        GuidanceMethod::Csd {
            w1: 7.5,
            w2: 6.5,
            w3: None,
        },
        GuidanceMethod::Bsd { w1: 7.5, w2: 6.5 },
    ] {
        let d = Scene::distiller(method, Weighting::OneMinusAlphaBar);
        let (out, image_grad) = scene.run(&d, &MockUnet::default(), &encoder, TIMESTEP);
        let g = host(out.gradient);
        let hw = LH * LW;
        for (i, v) in g.iter().enumerate() {
            if scene.mask[i % hw] == 0.0 {
                assert_eq!(*v, 0.0, "latent {i}");
            }
        }
        assert!(max_abs(&g) > 0.1);
        // The linear 2x2 encoder maps latent column j to image columns 2j, 2j+1.
        for (i, v) in image_grad.iter().enumerate() {
            if (i % 8) / 2 >= LW / 2 {
                assert_eq!(*v, 0.0, "pixel {i}");
            }
        }
    }
}

/// A 16x12 view with a 6x5 mask; the render's gradient is zero outside the pixel mask when
/// the render is pasted onto the ground truth, whatever the encoder's receptive field.
#[test]
fn render_gradient_is_zero_outside_the_pixel_mask_when_pasted() {
    let (w, h) = (16, 12);
    let device = BackendKind::Flex.device();
    let ad = device.clone().autodiff();
    let mut mask = vec![0.0f32; w * h];
    for y in 3..8 {
        for x in 5..11 {
            mask[y * w + x] = 1.0;
        }
    }
    let encoder = ConvEncoder::new(&device, 11);
    let gt = tensor(rand01(21, 3 * w * h), [1, 3, h, w], &device);
    let view = ViewConditioning::new(
        0,
        &encoder,
        gt,
        tensor(mask.clone(), [1, 1, h, w], &device),
        8,
    )
    .expect("view");
    assert_eq!(
        (
            view.bbox.x0,
            view.bbox.y0,
            view.bbox.width,
            view.bbox.height
        ),
        (5, 3, 6, 5)
    );
    let prompts = PromptEmbeddings {
        text: tensor(randn(4, 12), [1, 3, 4], &device),
        unconditional: Some(tensor(randn(5, 12), [1, 3, 4], &device)),
        negative: Some(tensor(randn(6, 12), [1, 3, 4], &device)),
    };
    let unet = MockUnet::default();
    let models = ViewStepModels {
        unet: &unet,
        encoder: &encoder,
    };
    let settings = DistillSettings {
        guidance: GuidanceMethod::Bsd { w1: 7.5, w2: 6.5 },
        timesteps: TimestepConfig::default(),
        weighting: Weighting::OneMinusAlphaBar,
        grad_clamp: None,
    };
    let mut distiller = ScoreDistiller::new(&settings, sd_alphas(), 3).expect("distiller");
    let render = tensor(rand01(22, 3 * w * h), [1, 3, h, w], &ad).require_grad();
    let out = distill_view(
        &mut distiller,
        &models,
        render.clone(),
        &view,
        0,
        PriorInputMode::PasteOnGroundTruth,
        &prompts,
    )
    .expect("step");
    let grad = host(render.grad(&out.loss.backward()).expect("render grad"));
    let mut inside = 0.0f32;
    for (i, v) in grad.iter().enumerate() {
        let m = mask[i % (w * h)];
        assert!(v.is_finite());
        if m == 0.0 {
            assert_eq!(*v, 0.0, "pixel {i} outside the mask");
        } else {
            inside = inside.max(v.abs());
        }
    }
    assert!(inside > 0.0, "no gradient inside the mask");
}
