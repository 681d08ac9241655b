//! The same seed gives the same gradient on every backend (ndarray, flex, wgpu).

use gb_core::{test_backends, BackendKind};
use gb_diffusion::distill::{
    distill_view, DistillSettings, GuidanceMethod, PriorInputMode, PromptEmbeddings,
    ScoreDistiller, TimestepConfig, ViewConditioning, ViewStepModels, Weighting,
};

use crate::distill::fixture::sd_alphas;
use crate::distill::support::{
    host, max_abs, max_abs_diff, rand01, randn, tensor, wgpu_env, ConvEncoder, MockUnet,
};

/// Two seeded steps of `method` on `kind`; returns (timesteps, render gradient).
fn run(kind: BackendKind, method: GuidanceMethod, seed: u64) -> (Vec<usize>, Vec<f32>) {
    let (w, h) = (12, 12);
    let device = kind.device();
    let ad = kind.autodiff_device();
    let mask: Vec<f32> = (0..w * h)
        .map(|i| {
            if (3..9).contains(&(i % w)) && (2..10).contains(&(i / w)) {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    let encoder = ConvEncoder::new(&device, 31);
    let gt = tensor(rand01(32, 3 * w * h), [1, 3, h, w], &device);
    let view = ViewConditioning::new(0, &encoder, gt, tensor(mask, [1, 1, h, w], &device), 8)
        .expect("view");
    let prompts = PromptEmbeddings {
        text: tensor(randn(4, 8), [1, 2, 4], &device),
        unconditional: Some(tensor(randn(5, 8), [1, 2, 4], &device)),
        negative: Some(tensor(randn(6, 8), [1, 2, 4], &device)),
    };
    let unet = MockUnet::default();
    let models = ViewStepModels {
        unet: &unet,
        encoder: &encoder,
    };
    let settings = DistillSettings {
        guidance: method,
        timesteps: TimestepConfig::default(),
        weighting: Weighting::OneMinusAlphaBar,
        grad_clamp: None,
    };
    let mut distiller = ScoreDistiller::new(&settings, sd_alphas(), seed).expect("distiller");
    let render = tensor(rand01(33, 3 * w * h), [1, 3, h, w], &ad).require_grad();
    let mut total = vec![0.0f32; 3 * w * h];
    let mut timesteps = Vec::new();
    for _ in 0..2 {
        let out = distill_view(
            &mut distiller,
            &models,
            render.clone(),
            &view,
            0,
            PriorInputMode::RenderOnly,
            &prompts,
        )
        .expect("step");
        timesteps.push(out.diagnostics.timestep);
        let grad = host(render.grad(&out.loss.backward()).expect("grad"));
        total.iter_mut().zip(grad).for_each(|(t, g)| *t += g);
    }
    (timesteps, total)
}

#[test]
fn same_seed_same_gradient_on_every_backend() {
    wgpu_env();
    for method in [
        GuidanceMethod::Sds {
            guidance_scale: 7.5,
        },
        GuidanceMethod::Csd {
            w1: 7.5,
            w2: 6.5,
            w3: None,
        },
        GuidanceMethod::Bsd { w1: 7.5, w2: 6.5 },
    ] {
        let (ref_t, ref_g) = run(BackendKind::Ndarray, method.clone(), 42);
        assert!(max_abs(&ref_g) > 1e-3, "{method:?}: gradient vanished");
        let (again_t, again_g) = run(BackendKind::Ndarray, method.clone(), 42);
        assert_eq!(
            (&ref_t, &ref_g),
            (&again_t, &again_g),
            "{method:?}: not reproducible"
        );
        let (other_t, other_g) = run(BackendKind::Ndarray, method.clone(), 43);
        assert!(
            other_t != ref_t || max_abs_diff(&other_g, &ref_g) > 1e-4,
            "seed ignored"
        );
        for kind in test_backends() {
            let (t, g) = run(kind, method.clone(), 42);
            assert_eq!(t, ref_t, "{kind} {method:?}: timesteps");
            let err = max_abs_diff(&g, &ref_g);
            assert!(
                err <= 1e-4 * max_abs(&ref_g).max(1.0),
                "{kind} {method:?}: gradient differs by {err}"
            );
        }
    }
}
