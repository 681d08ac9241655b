//! Post-processing of the guidance gradient and its injection into the autodiff graph.

use burn::tensor::Tensor;

/// Multiplies `g` (`[B, C, h, w]`) by the latent-resolution mask (`[B, 1, h, w]`), zeroes
/// every non-finite value (NaN and ±inf, threestudio's `nan_to_num` made stricter) and, if
/// `clamp` is set, clamps to `[-clamp, clamp]`.
pub fn postprocess(g: Tensor<4>, mask_latent: &Tensor<4>, clamp: Option<f32>) -> Tensor<4> {
    let channels = g.dims()[1];
    let masked = g * mask_latent.clone().repeat_dim(1, channels);
    let non_finite = masked.clone().is_finite().bool_not();
    let cleaned = masked.mask_fill(non_finite, 0.0);
    match clamp {
        Some(c) => cleaned.clamp(-c, c),
        None => cleaned,
    }
}

/// The surrogate loss `(latents * g.detach()).sum()`: its gradient with respect to `latents`
/// is exactly `g`, so `backward()` carries `g` through the encoder to the image.
pub fn surrogate_loss(latents: &Tensor<4>, g: &Tensor<4>) -> Tensor<1> {
    let mut constant = g.clone();
    if latents.is_autodiff() {
        constant = constant.autodiff();
    }
    (latents.clone() * constant.detach()).sum()
}
