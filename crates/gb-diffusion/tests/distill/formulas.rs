//! The gradient reaching the image equals each method's formula (closed-form mock).

use gb_core::BackendKind;
use gb_diffusion::distill::{GuidanceMethod, Weighting};

use crate::distill::fixture::{half_mask, Scene, H, TIMESTEP, W};
use crate::distill::support::{host, max_abs, max_abs_diff, LinearPoolEncoder, MockUnet};

fn methods() -> Vec<GuidanceMethod> {
    vec![
        GuidanceMethod::Sds {
            guidance_scale: 7.5,
        },
        GuidanceMethod::Sds {
            guidance_scale: 1.0,
        },
        GuidanceMethod::Csd {
            w1: 7.5,
            w2: 6.5,
            w3: None,
        },
        GuidanceMethod::Csd {
            w1: 7.5,
            w2: 6.5,
            w3: Some(2.5),
        },
        GuidanceMethod::Bsd { w1: 7.5, w2: 6.5 },
        GuidanceMethod::Bsd { w1: 1.5, w2: 0.5 },
    ]
}

#[test]
fn gradient_reaching_the_image_equals_each_formula() {
    let device = BackendKind::Flex.device();
    let scene = Scene::new(&device, half_mask(), None);
    let encoder = LinearPoolEncoder::new(&device);
    for weighting in [Weighting::OneMinusAlphaBar, Weighting::Constant] {
        for method in methods() {
            let unet = MockUnet::default();
            let distiller = Scene::distiller(method.clone(), weighting);
            let (out, image_grad) = scene.run(&distiller, &unet, &encoder, TIMESTEP);
            let expected = scene.expected(&method, TIMESTEP, weighting);
            let g = host(out.gradient.clone());
            let scale = max_abs(&expected);
            assert!(scale > 0.1, "{method:?}: degenerate expectation");
            let err = max_abs_diff(&g, &expected);
            assert!(
                err <= 1e-5 * scale.max(1.0),
                "{method:?} {weighting:?}: latent grad err {err}"
            );
            let expected_image = LinearPoolEncoder::transpose_host(&expected, H, W);
            let err = max_abs_diff(&image_grad, &expected_image);
            assert!(
                err <= 1e-5 * max_abs(&expected_image).max(1.0),
                "{method:?} {weighting:?}: image grad err {err}"
            );
            let ab = crate::distill::fixture::sd_alphas().at(TIMESTEP);
            let w = if weighting == Weighting::Constant {
                1.0
            } else {
                1.0 - ab
            };
            assert!((out.diagnostics.weight - w).abs() < 1e-12);
            let norm = expected
                .iter()
                .map(|v| (*v as f64).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!((out.diagnostics.grad_norm - norm).abs() <= 1e-4 * norm);
        }
    }
}

#[test]
fn csd_with_w3_zero_is_exactly_bsd() {
    let device = BackendKind::Flex.device();
    let scene = Scene::new(&device, half_mask(), None);
    let encoder = LinearPoolEncoder::new(&device);
    let unet = MockUnet::default();
    let run = |m| {
        let d = Scene::distiller(m, Weighting::OneMinusAlphaBar);
        let (out, image_grad) = scene.run(&d, &unet, &encoder, TIMESTEP);
        (host(out.gradient), image_grad)
    };
    let (csd_g, csd_img) = run(GuidanceMethod::Csd {
        w1: 7.5,
        w2: 6.5,
        w3: Some(0.0),
    });
    let (bsd_g, bsd_img) = run(GuidanceMethod::Bsd { w1: 7.5, w2: 6.5 });
    assert!(max_abs(&bsd_g) > 0.1);
    assert_eq!(csd_g, bsd_g, "latent gradients differ");
    assert_eq!(csd_img, bsd_img, "image gradients differ");
    // The default w3 = w2 - w1 = -1 is not BSD.
    let (csd_default, _) = run(GuidanceMethod::Csd {
        w1: 7.5,
        w2: 6.5,
        w3: None,
    });
    assert!(max_abs_diff(&csd_default, &bsd_g) > 1e-3);
}

#[test]
fn one_batched_unet_call_per_step() {
    let device = BackendKind::Flex.device();
    let scene = Scene::new(&device, half_mask(), None);
    let encoder = LinearPoolEncoder::new(&device);
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
        let unet = MockUnet::default();
        let distiller = Scene::distiller(method.clone(), Weighting::OneMinusAlphaBar);
        let (out, _) = scene.run(&distiller, &unet, &encoder, TIMESTEP);
        assert_eq!(*unet.calls.borrow(), vec![(batch, TIMESTEP)], "{method:?}");
        assert_eq!(out.diagnostics.unet_calls, 1);
        assert_eq!(out.diagnostics.unet_batch, batch);
        assert_eq!(distiller.guidance().branches().len(), batch);
    }
}
