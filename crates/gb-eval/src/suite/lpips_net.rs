//! Which LPIPS network the suite's `lpips` uses, loaded once per evaluation.

use std::path::Path;

use burn::tensor::Device;
use gb_core::RgbImage;

use crate::error::MetricError;
use crate::image_metrics::Region;
use crate::lpips::{Backbone, Lpips, PerceptualDistance};
use crate::stlpips::StLpips;

/// The LPIPS network.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum LpipsNet {
    /// Shift-tolerant LPIPS, AlexNet (weights `stlpips_alex_shift_tolerant.safetensors`).
    #[default]
    StAlex,
    /// Standard LPIPS, AlexNet (user weights `lpips_alex.safetensors`).
    Alex,
    /// Standard LPIPS, VGG16 (user weights `lpips_vgg.safetensors`).
    Vgg,
}

impl LpipsNet {
    /// The name written in the report's context.
    pub fn name(self) -> &'static str {
        match self {
            LpipsNet::StAlex => "st-lpips-alex",
            LpipsNet::Alex => "lpips-alex",
            LpipsNet::Vgg => "lpips-vgg",
        }
    }

    /// Its weights file in the weights folder.
    pub fn weights_file(self) -> &'static str {
        match self {
            LpipsNet::StAlex => StLpips::WEIGHTS_FILE,
            LpipsNet::Alex => "lpips_alex.safetensors",
            LpipsNet::Vgg => "lpips_vgg.safetensors",
        }
    }
}

/// A loaded LPIPS network of either kind. One instance lives for a whole evaluation, so the
/// size difference between the variants costs nothing worth a box.
#[allow(clippy::large_enum_variant)]
pub enum LpipsModel {
    /// Shift-tolerant.
    Shift(StLpips),
    /// Standard.
    Standard(Lpips),
}

impl LpipsModel {
    /// Loads `net` from `path`.
    pub fn load(net: LpipsNet, path: &Path, device: &Device) -> Result<Self, MetricError> {
        Ok(match net {
            LpipsNet::StAlex => LpipsModel::Shift(StLpips::load(path, device)?),
            LpipsNet::Alex => LpipsModel::Standard(Lpips::load(path, Backbone::Alex, device)?),
            LpipsNet::Vgg => LpipsModel::Standard(Lpips::load(path, Backbone::Vgg, device)?),
        })
    }

    /// The distance over the whole image or a box (a per-pixel mask does not apply to a
    /// network distance).
    pub fn distance(
        &self,
        p: &RgbImage,
        g: &RgbImage,
        region: &Region,
    ) -> Result<f64, MetricError> {
        let model: &dyn PerceptualDistance = match self {
            LpipsModel::Shift(m) => m,
            LpipsModel::Standard(m) => m,
        };
        match region {
            Region::Full => model.distance(p, g),
            Region::BBox { x0, y0, x1, y1 } => model.distance_bbox(p, g, (*x0, *y0, *x1, *y1)),
            Region::Mask(_) => Err(MetricError::InvalidInput {
                what: "LPIPS",
                reason: "has no per-pixel mask variant".into(),
            }),
        }
    }
}
