//! The gradient through a small nonlinear conv encoder (and the bilinear crop-resize) matches
//! central finite differences of the surrogate loss.

use burn::tensor::Tensor;
use gb_core::BackendKind;
use gb_diffusion::distill::gradient::surrogate_loss;
use gb_diffusion::distill::prior_input::crop_resize;
use gb_diffusion::distill::{LatentEncoder, MaskBox};

use crate::distill::support::{host, rand01, randn, tensor, ConvEncoder, LATENT_C};

#[test]
fn encoder_gradient_matches_finite_differences() {
    let device = BackendKind::Flex.device();
    let ad = device.clone().autodiff();
    let (w, h, res) = (12, 10, 8);
    let bbox = MaskBox {
        x0: 2,
        y0: 1,
        width: 7,
        height: 6,
    };
    let encoder = ConvEncoder::new(&device, 5);
    let g = randn(9, LATENT_C * (res / 2) * (res / 2));
    let image = rand01(8, 3 * w * h);

    // Analytic: backward of (encode(2 * crop_resize(x) - 1) * g).sum().
    let forward = |x: Tensor<4>| {
        let prior = crop_resize(x, &bbox, res, false)
            .mul_scalar(2.0)
            .sub_scalar(1.0);
        encoder.encode(prior).expect("encode")
    };
    let x = tensor(image.clone(), [1, 3, h, w], &ad).require_grad();
    let latents = forward(x.clone());
    let g_t = tensor(g.clone(), [1, LATENT_C, res / 2, res / 2], &device);
    let grads = surrogate_loss(&latents, &g_t).backward();
    let analytic = host(x.grad(&grads).expect("grad"));

    // Numeric, with the loss summed in f64 on the host.
    let loss = |values: Vec<f32>| -> f64 {
        let z = host(forward(tensor(values, [1, 3, h, w], &device)));
        z.iter().zip(&g).map(|(a, b)| *a as f64 * *b as f64).sum()
    };
    let eps = 1e-2f32;
    let mut checked = 0;
    let mut inside = 0;
    for idx in (0..image.len()).step_by(7) {
        let (mut plus, mut minus) = (image.clone(), image.clone());
        plus[idx] += eps;
        minus[idx] -= eps;
        let numeric = ((loss(plus) - loss(minus)) / (2.0 * eps as f64)) as f32;
        let a = analytic[idx];
        assert!(
            (a - numeric).abs() <= 2e-3 + 2e-2 * numeric.abs(),
            "pixel {idx}: autodiff {a} vs finite difference {numeric}"
        );
        checked += 1;
        if numeric.abs() > 1e-2 {
            inside += 1;
        }
    }
    assert!(
        checked > 40 && inside > 10,
        "checked {checked}, non-trivial {inside}"
    );
    // Pixels outside the box get exactly no gradient.
    assert_eq!(analytic[0], 0.0);
}
