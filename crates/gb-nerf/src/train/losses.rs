//! Reconstruction losses and the PSNR of a loss value.

use burn::tensor::Tensor;

/// Mean squared error over all elements.
pub fn mse(pred: Tensor<2>, target: Tensor<2>) -> Tensor<1> {
    (pred - target).square().mean()
}

/// PSNR in dB of a mean squared error of [0, 1] values.
pub fn psnr_from_mse(mse: f64) -> f64 {
    -10.0 * mse.max(1e-20).log10()
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn psnr_and_disparity_loss_closed_forms() {
        assert!((psnr_from_mse(0.01) - 20.0).abs() < 1e-9);
        let device = gb_core::BackendKind::Flex.device();
        let pred = Tensor::<1>::from_floats([0.5f32, 0.25, 1.0], &device);
        let gt = Tensor::<1>::from_floats([0.5f32, 1.0, 0.0], &device);
        let valid = Tensor::<1>::from_floats([1.0f32, 1.0, 0.0], &device);
        // near 2: pred*near = [1.0, 0.5, 2.0]; errors (0.5)^2, (0.5)^2 over 2 rays
        let l: f32 = disparity_loss(pred, gt, valid, 2.0).into_scalar();
        assert!((l - 0.25).abs() < 1e-6, "{l}");
    }
}
