//! gb-eval: Evaluation metrics (PSNR, SSIM, LPIPS, FID, BRISQUE, NIMA, D-PSNR, D-FID) and reports.

pub mod brisque;
pub mod d_fid;
pub mod disparity;
pub mod error;
pub mod eval_inputs;
pub mod fid;
pub mod image_metrics;
pub mod lpips;
pub mod nima;
pub mod report;
pub mod stlpips;
pub mod suite;

pub use error::MetricError;
pub use image_metrics::{psnr, ssim, Region};
pub use lpips::PerceptualDistance;

/// The metric weights folder used when none is given: `$GB_TEST_DATA/weights` when it
/// exists. A relative `GB_TEST_DATA` is taken against the current folder.
pub fn default_weights_dir() -> Option<std::path::PathBuf> {
    let dir = std::path::PathBuf::from(std::env::var_os("GB_TEST_DATA")?).join("weights");
    dir.is_dir().then_some(dir)
}
