//! Numerically stable volume rendering (emission-absorption quadrature of NeRF).
//!
//! For a ray with samples `i = 0..S` at distances `t_i`, densities `sigma_i` and interval
//! lengths `delta_i` (world units):
//! - `tau_i = clamp(sigma_i, 0, MAX_DENSITY) * clamp(delta_i, 0, MAX_DELTA)` (at most 1e20,
//!   finite in f32);
//! - transmittance `T_i = exp(-sum_{j<i} tau_j)`, the *exclusive* cumulative sum computed as
//!   the inclusive cumulative sum of the shifted sequence `[0, tau_0, .., tau_{S-2}]`
//!   (no cancellation), never as a product of `(1 - alpha)`;
//! - `alpha_i = 1 - exp(-tau_i)`, weights `w_i = T_i * alpha_i` (their sum telescopes to
//!   `1 - T_S <= 1`);
//! - opacity `A = clamp(sum_i w_i, 0, 1)`;
//! - colour `sum_i w_i c_i + (1 - A) * background`;
//! - depth `sum_i w_i t_i + (1 - A) * background_depth`: an empty ray has the documented
//!   background depth (the scene's far bound), never NaN;
//! - disparity `1 / max(depth, MIN_DEPTH)`.

use burn::tensor::{Tensor, TensorData};

/// Densities are clamped to this value before multiplying by the interval length.
pub const MAX_DENSITY: f32 = 1e10;
/// Interval lengths are clamped to this value.
pub const MAX_DELTA: f32 = 1e10;
/// Depths below this are clamped when taking the disparity.
pub const MIN_DEPTH: f32 = 1e-10;

/// What empty space looks like.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Background {
    /// Colour of rays that hit nothing.
    pub color: [f32; 3],
    /// Depth of rays that hit nothing (usually the far bound).
    pub depth: f32,
}

/// Per-ray outputs of [`composite`], all keeping the autodiff graph.
#[derive(Debug, Clone)]
pub struct VolumeOutput {
    /// `[R, 3]` colour.
    pub rgb: Tensor<2>,
    /// `[R]` expected depth (background depth for the missing opacity).
    pub depth: Tensor<1>,
    /// `[R]` `1 / depth`.
    pub disparity: Tensor<1>,
    /// `[R]` accumulated opacity in `[0, 1]`.
    pub opacity: Tensor<1>,
    /// `[R, S]` sample weights.
    pub weights: Tensor<2>,
}

/// Composites samples along rays: `sigma [R, S]`, `rgb [R, S, 3]`, `t [R, S]`,
/// `delta [R, S]`. See the module docs for the formulas.
pub fn composite(
    sigma: Tensor<2>,
    rgb: Tensor<3>,
    t: Tensor<2>,
    delta: Tensor<2>,
    background: Background,
) -> VolumeOutput {
    let [r, s] = sigma.dims();
    let device = sigma.device();
    let tau = sigma.clamp(0.0, MAX_DENSITY) * delta.clamp(0.0, MAX_DELTA);
    let shifted = if s > 1 {
        Tensor::cat(
            vec![
                Tensor::zeros([r, 1], &device),
                tau.clone().narrow(1, 0, s - 1),
            ],
            1,
        )
    } else {
        Tensor::zeros([r, 1], &device)
    };
    let transmittance = shifted.cumsum(1).neg().exp();
    let alpha = tau.neg().exp().neg().add_scalar(1.0);
    let weights = transmittance * alpha;
    let opacity = weights.clone().sum_dim(1).clamp(0.0, 1.0); // [R, 1]
    let missing = opacity.clone().neg().add_scalar(1.0);
    let bg = Tensor::<2>::from_data(TensorData::new(background.color.to_vec(), [1, 3]), &device);
    let color = (rgb * weights.clone().unsqueeze_dim::<3>(2))
        .sum_dim(1)
        .reshape([r, 3])
        + missing.clone() * bg;
    let depth = (weights.clone() * t).sum_dim(1) + missing.mul_scalar(background.depth);
    let depth = depth.reshape([r]);
    let disparity = depth.clone().clamp_min(MIN_DEPTH).recip();
    VolumeOutput {
        rgb: color,
        depth,
        disparity,
        opacity: opacity.reshape([r]),
        weights,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn single_opaque_slab_matches_closed_form() {
        let device = gb_core::BackendKind::Flex.device();
        // two samples: sigma 2 over delta 0.5 (tau 1), then sigma 1e6 over 0.1.
        let sigma = Tensor::<2>::from_floats([[2.0f32, 1e6]], &device);
        let rgb = Tensor::<3>::from_floats([[[1.0f32, 0.0, 0.0], [0.0, 1.0, 0.0]]], &device);
        let t = Tensor::<2>::from_floats([[1.0f32, 2.0]], &device);
        let delta = Tensor::<2>::from_floats([[0.5f32, 0.1]], &device);
        let out = composite(
            sigma,
            rgb,
            t,
            delta,
            Background {
                color: [0.0, 0.0, 1.0],
                depth: 10.0,
            },
        );
        let w0 = 1.0 - (-1.0f32).exp();
        let w1 = (-1.0f32).exp();
        let c: Vec<f32> = out.rgb.into_data().try_to_vec::<f32>().unwrap();
        assert!((c[0] - w0).abs() < 1e-6 && (c[1] - w1).abs() < 1e-6 && c[2].abs() < 1e-6);
        let d: f32 = out.depth.into_scalar();
        assert!((d - (w0 * 1.0 + w1 * 2.0)).abs() < 1e-5);
        let a: f32 = out.opacity.into_scalar();
        assert!((a - 1.0).abs() < 1e-6);
    }
}
