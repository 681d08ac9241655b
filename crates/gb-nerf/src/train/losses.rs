//! Reconstruction losses and the PSNR of a loss value.

use burn::tensor::Tensor;

/// Mean squared error over all elements.
pub fn mse(pred: Tensor<2>, target: Tensor<2>) -> Tensor<1> {
    (pred - target).square().mean()
}

/// The disparity loss: mean over rays with ground truth of
/// `(near / depth_pred - near / depth_gt)^2`, i.e. the squared error of disparity scaled by
/// the near bound so that it lies in `[0, 1]` in front of the far plane. `valid` is 1 where
/// ground truth exists, 0 elsewhere; `gt_disparity` is `near / depth_gt` (0 where invalid).
pub fn disparity_loss(
    pred_disparity: Tensor<1>,
    gt_disparity: Tensor<1>,
    valid: Tensor<1>,
    near: f32,
) -> Tensor<1> {
    let count = valid.clone().sum().clamp_min(1.0);
    ((pred_disparity.mul_scalar(near) - gt_disparity).square() * valid).sum() / count
}

/// The distortion loss of mip-NeRF 360 (Barron et al. 2022, eq. 15), mean over rays:
/// `sum_ij w_i w_j |s_i - s_j| + 1/3 sum_i w_i^2 width_i`, with the sample weights `w [R, S]`
/// and each sample's position `s [R, S]` and bin width `width [R, S]` in the ray's
/// normalised sampling coordinate (`[0, 1]` from near to far, uniform in the sampler's
/// spacing). The double sum is computed in `O(S)` from cumulative sums, using that `s`
/// increases along each ray: `2 sum_i w_i (s_i W_<i - (ws)_<i)`.
pub fn distortion_loss(weights: Tensor<2>, s: Tensor<2>, width: Tensor<2>) -> Tensor<1> {
    let ws = weights.clone() * s.clone();
    let w_before = weights.clone().cumsum(1) - weights.clone();
    let ws_before = ws.clone().cumsum(1) - ws;
    let inter = (weights.clone() * (s * w_before - ws_before)).mul_scalar(2.0);
    let intra = (weights.square() * width).div_scalar(3.0);
    (inter + intra).sum_dim(1).mean()
}

/// [`distortion_loss`] of rendered `rays`: each sample's position in the ray's normalised
/// sampling coordinate under `spacing`, and a bin width of `1 / samples`.
pub fn distortion_of(
    weights: Tensor<2>,
    rays: &crate::sampler::RayBatch,
    samples: &crate::sampler::SampleSet,
    spacing: crate::sampler::Spacing,
) -> Tensor<1> {
    let device = weights.device();
    let (r, s) = (samples.rays, samples.samples);
    let u = crate::sampler::normalized_positions(rays, samples, spacing);
    let u = Tensor::<2>::from_data(burn::tensor::TensorData::new(u, [r, s]), &device);
    let width = Tensor::<2>::full([r, s], 1.0 / s as f32, &device);
    distortion_loss(weights, u, width)
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::TensorData;

    #[test]
    fn disparity_loss_closed_form() {
        let device = gb_core::BackendKind::Flex.device();
        let pred = Tensor::<1>::from_floats([0.5f32, 0.25, 1.0], &device);
        let gt = Tensor::<1>::from_floats([0.5f32, 1.0, 0.0], &device);
        let valid = Tensor::<1>::from_floats([1.0f32, 1.0, 0.0], &device);
        // near 2: pred*near = [1.0, 0.5, 2.0]; errors (0.5)^2, (0.5)^2 over 2 rays
        let l: f32 = disparity_loss(pred, gt, valid, 2.0).into_scalar();
        assert!((l - 0.25).abs() < 1e-6, "{l}");
    }

    #[test]
    fn distortion_loss_matches_the_double_sum() {
        let device = gb_core::BackendKind::Flex.device();
        let (r, n) = (3usize, 5usize);
        let w: Vec<f32> = (0..r * n).map(|k| ((k * 7 % 11) as f32) / 40.0).collect();
        let width = 1.0 / n as f32;
        let s: Vec<f32> = (0..r * n)
            .map(|k| ((k % n) as f32 + 0.3 + 0.05 * (k / n) as f32) * width)
            .collect();
        let mut expected = 0.0f64;
        for ray in 0..r {
            for i in 0..n {
                let (wi, si) = (w[ray * n + i] as f64, s[ray * n + i] as f64);
                for j in 0..n {
                    expected += wi * w[ray * n + j] as f64 * (si - s[ray * n + j] as f64).abs();
                }
                expected += wi * wi * width as f64 / 3.0;
            }
        }
        expected /= r as f64;
        let t = |v: &[f32]| Tensor::<2>::from_data(TensorData::new(v.to_vec(), [r, n]), &device);
        let l: f32 = distortion_loss(t(&w), t(&s), t(&vec![width; r * n])).into_scalar();
        assert!((l as f64 - expected).abs() < 1e-6, "{l} vs {expected}");
        // one compact spike costs only its own width; two far-apart halves cost more
        let spike = [0.0f32, 0.0, 1.0, 0.0, 0.0];
        let split = [0.5f32, 0.0, 0.0, 0.0, 0.5];
        let pos: Vec<f32> = (0..n).map(|i| (i as f32 + 0.5) * width).collect();
        let one = |w: &[f32]| -> f32 {
            let t1 =
                |v: &[f32]| Tensor::<2>::from_data(TensorData::new(v.to_vec(), [1, n]), &device);
            distortion_loss(t1(w), t1(&pos), t1(&vec![width; n])).into_scalar()
        };
        assert!((one(&spike) - width / 3.0).abs() < 1e-7);
        assert!((one(&split) - (0.5 * 0.8 + 2.0 * 0.25 * width / 3.0)).abs() < 1e-6);
    }

    #[test]
    fn distortion_loss_gradient_matches_finite_differences() {
        let device = gb_core::BackendKind::Flex.autodiff_device();
        let (r, n) = (3usize, 5usize);
        let w0: Vec<f32> = (0..r * n)
            .map(|k| 0.02 + ((k * 5 % 7) as f32) * 0.03)
            .collect();
        let s: Vec<f32> = (0..r * n)
            .map(|k| ((k % n) as f32 + 0.5) / n as f32 + 0.01 * (k / n) as f32)
            .collect();
        let eval = |w: &[f32]| -> (f64, Vec<f32>) {
            let wt =
                Tensor::<2>::from_data(TensorData::new(w.to_vec(), [r, n]), &device).require_grad();
            let st = Tensor::<2>::from_data(TensorData::new(s.clone(), [r, n]), &device);
            let l = distortion_loss(wt.clone(), st, Tensor::full([r, n], 0.2, &device));
            let v: f32 = l.clone().into_scalar();
            let g = l.backward();
            let gw = wt
                .grad(&g)
                .unwrap()
                .into_data()
                .try_to_vec::<f32>()
                .unwrap();
            (v as f64, gw)
        };
        let (v, g) = eval(&w0);
        for i in 0..r * n {
            let mut w = w0.clone();
            w[i] += 1e-3;
            let numeric = (eval(&w).0 - v) / 1e-3;
            assert!(
                (g[i] as f64 - numeric).abs() < 1e-3,
                "{i}: {} vs {numeric}",
                g[i]
            );
        }
    }
}
