//! Extremes: t at the ends of the range, t = 0 and 1, large weights, empty and full masks,
//! constant images, NaN from the predictor, clamping and missing embeddings.

use gb_core::BackendKind;
use gb_diffusion::distill::{
    DistillError, DistillSettings, GuidanceMethod, LatentTarget, ScoreDistiller, TimestepConfig,
    ViewConditioning, Weighting,
};

use crate::distill::fixture::{half_mask, sd_alphas, Scene, LH, LW, TIMESTEP};
use crate::distill::support::{host, max_abs, tensor, LinearPoolEncoder, MockUnet, LATENT_C};

fn all_methods(w: f32) -> Vec<GuidanceMethod> {
    vec![
        GuidanceMethod::Sds { guidance_scale: w },
        GuidanceMethod::Csd {
            w1: w,
            w2: w - 1.0,
            w3: None,
        },
        GuidanceMethod::Csd {
            w1: w,
            w2: w,
            w3: Some(w),
        },
        GuidanceMethod::Bsd { w1: w, w2: w - 1.0 },
    ]
}

fn target<'a>(scene: &'a Scene, encoder: &LinearPoolEncoder) -> LatentTarget<'a> {
    use gb_diffusion::distill::LatentEncoder;
    LatentTarget {
        latents: encoder.encode(scene.image.clone()).expect("encode"),
        mask_latent: tensor(scene.mask.clone(), [1, 1, LH, LW], &scene.device),
        masked_image_latents: tensor(scene.masked.clone(), [1, LATENT_C, LH, LW], &scene.device),
        prompts: &scene.prompts,
    }
}

#[test]
fn t_at_the_ends_of_the_paper_range_is_finite() {
    let device = BackendKind::Flex.device();
    let scene = Scene::new(&device, half_mask(), None);
    let encoder = LinearPoolEncoder::new(&device);
    for method in all_methods(7.5) {
        let settings = DistillSettings {
            guidance: method.clone(),
            ..DistillSettings::paper_rgb()
        };
        let mut d = ScoreDistiller::new(&settings, sd_alphas(), 0).expect("distiller");
        for (t, index) in [(0.02, 20), (0.98, 980)] {
            let out = d
                .step_at(&MockUnet::default(), target(&scene, &encoder), t)
                .expect("step");
            assert_eq!(out.diagnostics.timestep, index);
            let g = host(out.gradient);
            assert!(
                g.iter().all(|v| v.is_finite()) && max_abs(&g) > 0.0,
                "{method:?} t={t}"
            );
        }
    }
}

#[test]
fn t_zero_and_one_are_rejected_clearly() {
    let device = BackendKind::Flex.device();
    let scene = Scene::new(&device, half_mask(), None);
    let encoder = LinearPoolEncoder::new(&device);
    let mut d =
        ScoreDistiller::new(&DistillSettings::paper_rgb(), sd_alphas(), 0).expect("distiller");
    for t in [0.0, 1.0, -0.5, f64::NAN] {
        let err = d
            .step_at(&MockUnet::default(), target(&scene, &encoder), t)
            .unwrap_err();
        assert!(
            matches!(err, DistillError::TimestepOutOfRange { field: "t", .. }),
            "{err}"
        );
        assert!(err.to_string().contains("outside (0, 1)"), "{err}");
    }
    for (t_min, t_max, field) in [(0.0, 0.98, "t_min"), (0.02, 1.0, "t_max")] {
        let settings = DistillSettings {
            timesteps: TimestepConfig {
                t_min,
                t_max,
                ..TimestepConfig::default()
            },
            ..DistillSettings::paper_rgb()
        };
        let err = ScoreDistiller::new(&settings, sd_alphas(), 0)
            .err()
            .expect("rejected");
        assert!(err.to_string().contains(field), "{err}");
    }
    let settings = DistillSettings {
        timesteps: TimestepConfig {
            t_min: 0.9,
            t_max: 0.1,
            ..TimestepConfig::default()
        },
        ..DistillSettings::paper_rgb()
    };
    assert!(matches!(
        ScoreDistiller::new(&settings, sd_alphas(), 0),
        Err(DistillError::TimestepRangeEmpty { .. })
    ));
    // The raw index API rejects index 0 and N.
    let d = Scene::distiller(GuidanceMethod::paper_rgb(), Weighting::OneMinusAlphaBar);
    for index in [0, 1000] {
        let noise = tensor(scene.noise.clone(), [1, LATENT_C, LH, LW], &device);
        let err = d
            .step_with(&MockUnet::default(), target(&scene, &encoder), index, noise)
            .unwrap_err();
        assert!(
            matches!(err, DistillError::TimestepOutOfRange { .. }),
            "{err}"
        );
    }
}

#[test]
fn weights_up_to_100_stay_finite_and_scale_linearly() {
    let device = BackendKind::Flex.device();
    let scene = Scene::new(&device, half_mask(), None);
    let encoder = LinearPoolEncoder::new(&device);
    for method in all_methods(100.0) {
        let d = Scene::distiller(method.clone(), Weighting::Constant);
        for timestep in [20, 980] {
            let (out, image_grad) = scene.run(&d, &MockUnet::default(), &encoder, timestep);
            let g = host(out.gradient);
            let expected = scene.expected(&method, timestep, Weighting::Constant);
            assert!(
                g.iter().chain(&image_grad).all(|v| v.is_finite()),
                "{method:?}"
            );
            let err = crate::distill::support::max_abs_diff(&g, &expected);
            assert!(
                err <= 1e-5 * max_abs(&expected).max(1.0),
                "{method:?} t={timestep}: {err}"
            );
        }
    }
    let bad = GuidanceMethod::Bsd {
        w1: f32::INFINITY,
        w2: 1.0,
    }
    .build()
    .err()
    .expect("rejected");
    assert!(bad.to_string().contains("w1"), "{bad}");
}

#[test]
fn all_zero_and_full_masks() {
    let device = BackendKind::Flex.device();
    let encoder = LinearPoolEncoder::new(&device);
    for method in all_methods(7.5) {
        let zero = Scene::new(&device, vec![0.0; LH * LW], None);
        let d = Scene::distiller(method.clone(), Weighting::OneMinusAlphaBar);
        let (out, image_grad) = zero.run(&d, &MockUnet::default(), &encoder, TIMESTEP);
        assert!(host(out.gradient)
            .iter()
            .chain(&image_grad)
            .all(|v| *v == 0.0));
        assert_eq!(out.diagnostics.grad_norm, 0.0);

        let full = Scene::new(&device, vec![1.0; LH * LW], None);
        let (out, image_grad) = full.run(&d, &MockUnet::default(), &encoder, TIMESTEP);
        let g = host(out.gradient);
        assert!(g.iter().all(|v| v.is_finite() && *v != 0.0), "{method:?}");
        assert!(image_grad.iter().all(|v| v.is_finite()));
    }
    // An empty image mask has no bounding box: a clear error naming the view.
    let err = match ViewConditioning::new(
        7,
        &encoder,
        tensor(vec![0.5; 3 * 64], [1, 3, 8, 8], &device),
        tensor(vec![0.0; 64], [1, 1, 8, 8], &device),
        8,
    ) {
        Err(e) => e,
        Ok(_) => panic!("empty mask accepted"),
    };
    assert!(matches!(err, DistillError::EmptyMask(_)), "{err}");
    assert!(err.to_string().contains("view 7"), "{err}");
    // A full image mask is a bounding box of the whole image.
    let view = ViewConditioning::new(
        1,
        &encoder,
        tensor(vec![0.5; 3 * 64], [1, 3, 8, 8], &device),
        tensor(vec![1.0; 64], [1, 1, 8, 8], &device),
        8,
    )
    .expect("full mask");
    assert_eq!((view.bbox.width, view.bbox.height), (8, 8));
    assert!(host(view.masked_image_latents).iter().all(|v| *v == 0.0));
}

#[test]
fn constant_image_gives_finite_gradients() {
    let device = BackendKind::Flex.device();
    let encoder = LinearPoolEncoder::new(&device);
    for value in [0.0, 0.5, 1.0] {
        let scene = Scene::new(&device, half_mask(), Some(vec![value; 3 * 64]));
        for method in all_methods(7.5) {
            let d = Scene::distiller(method.clone(), Weighting::OneMinusAlphaBar);
            let (out, image_grad) = scene.run(&d, &MockUnet::default(), &encoder, TIMESTEP);
            let expected = scene.expected(&method, TIMESTEP, Weighting::OneMinusAlphaBar);
            let g = host(out.gradient);
            assert!(image_grad.iter().all(|v| v.is_finite()));
            assert!(
                crate::distill::support::max_abs_diff(&g, &expected)
                    <= 1e-5 * max_abs(&expected).max(1.0)
            );
        }
    }
}

#[test]
fn nan_is_zeroed_and_clamp_bounds_the_gradient() {
    let device = BackendKind::Flex.device();
    let scene = Scene::new(&device, vec![1.0; LH * LW], None);
    let encoder = LinearPoolEncoder::new(&device);
    let unet = MockUnet {
        nan_above: Some(0.5),
        ..MockUnet::default()
    };
    let d = Scene::distiller(GuidanceMethod::paper_rgb(), Weighting::OneMinusAlphaBar);
    let (out, image_grad) = scene.run(&d, &unet, &encoder, TIMESTEP);
    let g = host(out.gradient);
    let zeros = g.iter().filter(|v| **v == 0.0).count();
    assert!(out.diagnostics.non_finite_zeroed > 0);
    assert!(zeros >= out.diagnostics.non_finite_zeroed);
    assert!(g.iter().chain(&image_grad).all(|v| v.is_finite()));

    let settings = DistillSettings {
        guidance: GuidanceMethod::Sds {
            guidance_scale: 100.0,
        },
        grad_clamp: Some(0.05),
        ..DistillSettings::paper_rgb()
    };
    let d = ScoreDistiller::new(&settings, sd_alphas(), 0).expect("distiller");
    let (out, _) = scene.run(&d, &MockUnet::default(), &encoder, TIMESTEP);
    let g = host(out.gradient);
    assert!(max_abs(&g) <= 0.05 && max_abs(&g) > 0.049);
    for bad in [0.0, -1.0] {
        let settings = DistillSettings {
            grad_clamp: Some(bad),
            ..DistillSettings::paper_rgb()
        };
        assert!(matches!(
            ScoreDistiller::new(&settings, sd_alphas(), 0),
            Err(DistillError::BadClamp(_))
        ));
    }
}

#[test]
fn a_missing_embedding_is_a_clear_error() {
    let device = BackendKind::Flex.device();
    let mut scene = Scene::new(&device, half_mask(), None);
    scene.prompts.negative = None;
    let encoder = LinearPoolEncoder::new(&device);
    let d = Scene::distiller(GuidanceMethod::paper_rgb(), Weighting::OneMinusAlphaBar);
    let noise = tensor(scene.noise.clone(), [1, LATENT_C, LH, LW], &device);
    let err = d
        .step_with(
            &MockUnet::default(),
            target(&scene, &encoder),
            TIMESTEP,
            noise,
        )
        .unwrap_err();
    assert!(
        err.to_string().contains("bsd") && err.to_string().contains("Negative"),
        "{err}"
    );
}
