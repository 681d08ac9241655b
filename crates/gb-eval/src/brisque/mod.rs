//! BRISQUE (Mittal et al.), a no-reference image quality score from 0 (best) to 100, computed
//! natively (no OpenCV) to match `cv2.quality.QualityBRISQUE` of opencv-contrib.
//!
//! The score is `clamp(svr(scale(features)), 0, 100)`: the 36 features of [`features`], each
//! scaled to [-1, 1] with the model's range file, then an RBF support-vector regressor.
//! Models load from OpenCV's YAML pair (`brisque_model_live.yml`, `brisque_range_live.yml`,
//! with their `%YAML:1.0` header and `!!opencv-matrix` tags) or from a libsvm text model with
//! an svm-scale range file.

pub mod error;
pub mod features;
pub mod libsvm;
pub mod opencv_yaml;
pub mod svr;

use std::path::Path;

pub use error::BrisqueError;
pub use features::{brisque_features, gray_from_gray8, gray_from_rgb8, GrayF32, FEATURE_COUNT};
pub use svr::{FeatureRange, KernelPrecision, RbfSvr};

use gb_core::RgbImage;

/// File name of OpenCV's LIVE-trained BRISQUE model in a weights folder.
pub const OPENCV_MODEL_FILE: &str = "brisque_model_live.yml";
/// File name of OpenCV's BRISQUE feature ranges in a weights folder.
pub const OPENCV_RANGE_FILE: &str = "brisque_range_live.yml";

/// A loaded BRISQUE model: feature ranges and the regressor.
#[derive(Debug, Clone)]
pub struct Brisque {
    /// Per-feature scaling to [-1, 1].
    pub range: FeatureRange,
    /// The regressor.
    pub svr: RbfSvr,
}

impl Brisque {
    /// Loads OpenCV's model and range YAML files.
    pub fn load_opencv(model: &Path, range: &Path) -> Result<Self, BrisqueError> {
        Self::new(
            FeatureRange::load_opencv_yaml(range)?,
            RbfSvr::load_opencv_yaml(model)?,
        )
    }

    /// Loads `brisque_model_live.yml` and `brisque_range_live.yml` from a weights folder.
    pub fn load_opencv_dir(dir: &Path) -> Result<Self, BrisqueError> {
        Self::load_opencv(&dir.join(OPENCV_MODEL_FILE), &dir.join(OPENCV_RANGE_FILE))
    }

    /// Loads a libsvm text model and an svm-scale range file (the original BRISQUE release).
    pub fn load_libsvm(model: &Path, range: &Path) -> Result<Self, BrisqueError> {
        Self::new(
            libsvm::load_svm_scale_range(range, FEATURE_COUNT)?,
            libsvm::load_libsvm_model(model, FEATURE_COUNT)?,
        )
    }

    /// Pairs a range with a regressor, checking that both have 36 features.
    pub fn new(range: FeatureRange, svr: RbfSvr) -> Result<Self, BrisqueError> {
        if svr.dim != FEATURE_COUNT {
            return Err(BrisqueError::FeatureCount {
                model: svr.dim,
                what: "BRISQUE",
                got: FEATURE_COUNT,
            });
        }
        if range.min.len() != svr.dim {
            return Err(BrisqueError::FeatureCount {
                model: svr.dim,
                what: "the range file",
                got: range.min.len(),
            });
        }
        Ok(Self { range, svr })
    }

    /// The score of a grey image in [0, 1], before and after OpenCV's clamp to [0, 100].
    pub fn score_gray_unclamped(&self, gray: &GrayF32) -> Result<f64, BrisqueError> {
        let feats = brisque_features(gray)?;
        Ok(self.svr.predict(&self.range.scale(&feats)))
    }

    /// The score of a grey image in [0, 1], clamped to [0, 100] as OpenCV does.
    pub fn score_gray(&self, gray: &GrayF32) -> Result<f64, BrisqueError> {
        Ok(self.score_gray_unclamped(gray)?.clamp(0.0, 100.0))
    }

    /// The score of an 8-bit RGB image (interleaved, row-major).
    pub fn score_rgb8(&self, rgb: &[u8], width: usize, height: usize) -> Result<f64, BrisqueError> {
        self.score_gray(&gray_from_rgb8(rgb, width, height)?)
    }

    /// The score of an [`RgbImage`] in [0, 1], quantised to 8 bits first.
    pub fn score(&self, img: &RgbImage) -> Result<f64, BrisqueError> {
        self.score_rgb8(&quantize_rgb(img), img.width, img.height)
    }
}

/// Rounds an [`RgbImage`] in [0, 1] to 8-bit values (clamped).
pub fn quantize_rgb(img: &RgbImage) -> Vec<u8> {
    img.data
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect()
}
