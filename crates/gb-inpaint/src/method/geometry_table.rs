//! `[geometry]` of a method: the hidden region's depth held to the unguided field's
//! ([`crate::geometry`] applies it).

use serde::{Deserialize, Serialize};

/// `[geometry]` of a method (module docs). Off when a method file leaves it out; the built-in
/// `none` and the default method `gb-nerf-unseen` set `depth_weight = 1`, `region = "crop"`,
/// and a run applies it only when it has a term inside the mask
/// ([`crate::MethodConfig::holds_geometry`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeometryConfig {
    /// Weight of the disparity loss of the hidden rays toward the unguided field's depth
    /// (0: off; the reconstruction's own depth loss has 0.1 in every preset).
    #[serde(default)]
    pub depth_weight: f64,
    /// Weight of the distortion loss on the same rays (0: off).
    #[serde(default)]
    pub distortion_weight: f64,
    /// Rays per step through the masked pixels.
    #[serde(default = "default_rays")]
    pub rays: usize,
    /// At most this many masked pixels of each training view are kept (a stride grid).
    #[serde(default = "default_max_pixels")]
    pub max_pixels_per_view: usize,
    /// Which pixels of each training view the term holds. Left out of the written config
    /// while it is the mask, so that the runs made before it existed resume.
    #[serde(default, skip_serializing_if = "GeometryRegion::is_mask")]
    pub region: GeometryRegion,
}

/// The pixels of a training view whose depth the geometry term holds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GeometryRegion {
    /// The masked pixels (the hidden region).
    #[default]
    Mask,
    /// Every pixel of the guided crop: the mask's bounding box grown by the method's
    /// `crop_margin` (the hidden region and the observed surroundings the guidance renders).
    Crop,
}

impl GeometryRegion {
    /// True for [`GeometryRegion::Mask`].
    pub fn is_mask(&self) -> bool {
        *self == Self::Mask
    }
}

fn default_rays() -> usize {
    256
}
fn default_max_pixels() -> usize {
    4096
}

impl Default for GeometryConfig {
    fn default() -> Self {
        Self {
            depth_weight: 0.0,
            distortion_weight: 0.0,
            rays: default_rays(),
            max_pixels_per_view: default_max_pixels(),
            region: GeometryRegion::Mask,
        }
    }
}

impl GeometryConfig {
    /// True for the default table (off).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// True when either loss has a weight.
    pub fn enabled(&self) -> bool {
        self.depth_weight > 0.0 || self.distortion_weight > 0.0
    }

    /// A message naming the first invalid field, if any.
    pub fn check(&self) -> Option<String> {
        let weights = [
            ("depth_weight", self.depth_weight),
            ("distortion_weight", self.distortion_weight),
        ];
        if let Some(msg) = super::first_negative_weight("geometry", &weights) {
            return Some(msg);
        }
        if self.rays == 0 {
            return Some("geometry.rays must be >= 1".into());
        }
        if self.max_pixels_per_view == 0 {
            return Some("geometry.max_pixels_per_view must be >= 1".into());
        }
        None
    }
}
