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

pub use error::MetricError;
pub use image_metrics::{psnr, ssim, Region};
