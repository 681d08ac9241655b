//! The one PSNR formula: of a mean squared error of values in `[0, 1]`. The metrics
//! (gb-eval) and the training logs (gb-nerf, gb-inpaint) both use it.

/// PSNR in dB of a mean squared error of values in `[0, 1]`: `10 log10(1 / mse)`, infinite
/// for a zero error (a training log clamps the error first, so that its line stays a number).
pub fn psnr_from_mse(mse: f64) -> f64 {
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (1.0 / mse).log10()
    }
}

/// The smallest error a training log's PSNR is computed from (200 dB at most).
pub const LOG_MIN_MSE: f64 = 1e-20;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn psnr_is_ten_log_of_the_inverse_error() {
        assert!((psnr_from_mse(0.01) - 20.0).abs() < 1e-9);
        assert!((psnr_from_mse(1.0)).abs() < 1e-12);
        assert_eq!(psnr_from_mse(0.0), f64::INFINITY);
        assert!((psnr_from_mse(LOG_MIN_MSE) - 200.0).abs() < 1e-9);
    }
}
