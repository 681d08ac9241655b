//! The oracle eps-predictor: the exact score of the true latents makes SDS a pure pull to
//! them, independent of the noise, and answers only the branches it is given.

use gb_core::BackendKind;
use gb_diffusion::distill::{Branch, GuidanceMethod, LatentTarget, OracleEps, Weighting};

use crate::distill::fixture::{half_mask, sd_alphas, Scene, LH, LW, TIMESTEP};
use crate::distill::support::LATENT_C;
use crate::distill::support::{
    host, max_abs, max_abs_diff, randn, tensor, LinearPoolEncoder, MockUnet,
};
use gb_diffusion::distill::LatentEncoder;

/// One step of `method` on the scene's image with `unet`, at [`TIMESTEP`] and `noise`;
/// returns the latent gradient and the latents.
fn step(
    scene: &Scene,
    method: GuidanceMethod,
    unet: &dyn gb_diffusion::distill::InpaintEpsPredictor,
    noise: Vec<f32>,
) -> Vec<f32> {
    let distiller = Scene::distiller(method, Weighting::OneMinusAlphaBar);
    let latents = LinearPoolEncoder::new(&scene.device)
        .encode(scene.image.clone())
        .expect("encode");
    let target = LatentTarget {
        latents,
        mask_latent: tensor(scene.mask.clone(), [1, 1, LH, LW], &scene.device),
        masked_image_latents: tensor(scene.masked.clone(), [1, LATENT_C, LH, LW], &scene.device),
        prompts: &scene.prompts,
    };
    let noise = tensor(noise, [1, LATENT_C, LH, LW], &scene.device);
    let out = distiller
        .step_with(unet, target, TIMESTEP, noise)
        .expect("step");
    host(out.gradient)
}

fn latents(scene: &Scene) -> Vec<f32> {
    host(
        LinearPoolEncoder::new(&scene.device)
            .encode(scene.image.clone().inner())
            .expect("encode"),
    )
}

#[test]
fn sds_with_the_oracle_pulls_the_latents_to_the_truth_whatever_the_noise() {
    let device = BackendKind::Flex.device();
    let scene = Scene::new(&device, half_mask(), None);
    let z = latents(&scene);
    let n = LATENT_C * LH * LW;
    let clean_values: Vec<f32> = randn(11, n);
    let clean = tensor(clean_values.clone(), [1, LATENT_C, LH, LW], &device);
    let alphas = sd_alphas();
    let unet = MockUnet::default();
    let oracle = OracleEps {
        inner: &unet,
        clean,
        alphas: &alphas,
        branches: &[Branch::Text, Branch::Unconditional],
        oracle_branches: &[Branch::Text, Branch::Unconditional],
    };
    let sds = GuidanceMethod::Sds {
        guidance_scale: 1.0,
    };
    let a = alphas.at(TIMESTEP);
    // w(t) = 1 - a times sqrt(a) / sqrt(1 - a) (z - z0), inside the mask
    let expected: Vec<f32> = (0..n)
        .map(|i| {
            ((1.0 - a) * a.sqrt() / (1.0 - a).sqrt()) as f32
                * (z[i] - clean_values[i])
                * scene.mask[i % (LH * LW)]
        })
        .collect();
    for seed in [7, 8] {
        let g = step(&scene, sds.clone(), &oracle, randn(seed, n));
        let err = max_abs_diff(&g, &expected);
        assert!(
            err <= 1e-5 * max_abs(&expected).max(1.0) && max_abs(&expected) > 0.1,
            "noise seed {seed}: err {err}"
        );
    }
    assert!(
        unet.calls.borrow().is_empty(),
        "the oracle answered every row"
    );
}

#[test]
fn bsd_with_an_oracle_prompt_keeps_the_priors_negative() {
    let device = BackendKind::Flex.device();
    let scene = Scene::new(&device, half_mask(), None);
    let n = LATENT_C * LH * LW;
    let clean_values: Vec<f32> = randn(12, n);
    let alphas = sd_alphas();
    let unet = MockUnet::default();
    let oracle = OracleEps {
        inner: &unet,
        clean: tensor(clean_values.clone(), [1, LATENT_C, LH, LW], &device),
        alphas: &alphas,
        branches: &[Branch::Text, Branch::Negative],
        oracle_branches: &[Branch::Text],
    };
    let (w1, w2) = (7.5f32, 6.5f32);
    let g = step(
        &scene,
        GuidanceMethod::Bsd { w1, w2 },
        &oracle,
        scene.noise.clone(),
    );
    assert_eq!(unet.calls.borrow().as_slice(), &[(2, TIMESTEP)]);
    // the closed form: w1 * eps*(x_t) - w2 * mock(x_t; negative), times w(t) and the mask
    let z = latents(&scene);
    let a = alphas.at(TIMESTEP);
    let x_t: Vec<f32> = z
        .iter()
        .zip(&scene.noise)
        .map(|(z, e)| (a.sqrt() as f32) * z + ((1.0 - a).sqrt() as f32) * e)
        .collect();
    let neg = crate::distill::support::mock_eps_host(
        &x_t,
        scene.means[2],
        &scene.mask,
        &scene.masked,
        LH * LW,
    );
    let expected: Vec<f32> = (0..n)
        .map(|i| {
            let exact = (x_t[i] - (a.sqrt() as f32) * clean_values[i]) / ((1.0 - a).sqrt() as f32);
            (1.0 - a) as f32 * (w1 * exact - w2 * neg[i]) * scene.mask[i % (LH * LW)]
        })
        .collect();
    let err = max_abs_diff(&g, &expected);
    assert!(
        err <= 1e-5 * max_abs(&expected).max(1.0),
        "err {err} of {}",
        max_abs(&expected)
    );
}
