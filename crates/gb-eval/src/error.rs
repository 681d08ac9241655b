//! The error type shared by the image metrics (PSNR, SSIM, LPIPS, D-PSNR).

use std::path::PathBuf;

/// A metric could not be computed on the given inputs.
#[derive(Debug, thiserror::Error)]
pub enum MetricError {
    /// The two images do not have the same size.
    #[error("image sizes differ: prediction is {pred_w}x{pred_h}, ground truth is {gt_w}x{gt_h}")]
    SizeMismatch {
        /// Prediction width.
        pred_w: usize,
        /// Prediction height.
        pred_h: usize,
        /// Ground-truth width.
        gt_w: usize,
        /// Ground-truth height.
        gt_h: usize,
    },
    /// An image's buffer does not hold `width * height * channels` values.
    #[error("{which} image buffer holds {got} values, expected {expected} ({width}x{height}x{channels})")]
    BadBuffer {
        /// Which image ("prediction", "ground truth", "disparity", ...).
        which: &'static str,
        /// Values found.
        got: usize,
        /// Values expected.
        expected: usize,
        /// Width.
        width: usize,
        /// Height.
        height: usize,
        /// Channels.
        channels: usize,
    },
    /// A mask does not have one entry per pixel.
    #[error("mask has {got} entries but the image has {expected} pixels ({width}x{height})")]
    MaskSize {
        /// Entries in the mask.
        got: usize,
        /// Pixels in the image.
        expected: usize,
        /// Image width.
        width: usize,
        /// Image height.
        height: usize,
    },
    /// A mask selects no pixel, so a masked mean is undefined.
    #[error("the mask selects no pixel: a masked metric is undefined")]
    EmptyMask,
    /// A bounding box is empty or reaches outside the image.
    #[error(
        "bounding box x {x0}..{x1}, y {y0}..{y1} is empty or outside the {width}x{height} image"
    )]
    BadBBox {
        /// Left column (inclusive).
        x0: usize,
        /// Top row (inclusive).
        y0: usize,
        /// Right column (exclusive).
        x1: usize,
        /// Bottom row (exclusive).
        y1: usize,
        /// Image width.
        width: usize,
        /// Image height.
        height: usize,
    },
    /// The image (or its crop) is smaller than the metric's window.
    #[error("{metric} needs at least {min}x{min} pixels, got {width}x{height}")]
    TooSmall {
        /// The metric.
        metric: &'static str,
        /// The smallest side accepted.
        min: usize,
        /// Width given.
        width: usize,
        /// Height given.
        height: usize,
    },
    /// A weights file could not be read or does not hold the expected tensors.
    #[error("{path}: cannot load {what} weights: {reason}")]
    Weights {
        /// The weights file.
        path: PathBuf,
        /// The network ("ST-LPIPS AlexNet", ...).
        what: &'static str,
        /// What went wrong.
        reason: String,
    },
    /// A value that must be finite and positive (e.g. a disparity maximum) is not.
    #[error("{what}: {reason}")]
    InvalidInput {
        /// The input concerned.
        what: &'static str,
        /// What is wrong with it.
        reason: String,
    },
}
