//! The one [`GuidanceMethod`] that configs (through [`super::settings_table`]) and the command
//! line name, and that builds its [`Guidance`].

use super::bsd::Bsd;
use super::csd::Csd;
use super::error::DistillError;
use super::guidance::Guidance;
use super::sds::Sds;

/// A guidance method and its weights (a config names it as `method = "bsd"` with its weights
/// in the same table, see [`super::settings_table`]).
#[derive(Debug, Clone, PartialEq)]
pub enum GuidanceMethod {
    /// Score Distillation Sampling with classifier-free guidance scale `guidance_scale`
    /// (diffusers' convention, see [`Sds`]).
    Sds {
        /// Classifier-free guidance scale `s`.
        guidance_scale: f32,
    },
    /// Classifier Score Distillation; `w3 = None` means the original CSD, `w3 = w2 - w1`.
    Csd {
        /// Weight of `eps(y)`.
        w1: f32,
        /// Weight of `eps(y_neg)` (subtracted).
        w2: f32,
        /// Weight of `eps(null)`; `None` for the default `w2 - w1`.
        w3: Option<f32>,
    },
    /// Balanced Score Distillation: `w1*eps(y) - w2*eps(y_neg)`.
    Bsd {
        /// Weight of `eps(y)`.
        w1: f32,
        /// Weight of `eps(y_neg)` (subtracted).
        w2: f32,
    },
}

impl GuidanceMethod {
    /// The paper's BSD weights for RGB renders, `(w1, w2) = (7.5, 6.5)`.
    pub fn paper_rgb() -> Self {
        GuidanceMethod::Bsd { w1: 7.5, w2: 6.5 }
    }

    /// The paper's BSD weights for normal maps, `(w1, w2) = (1.5, 0.5)`.
    pub fn paper_normals() -> Self {
        GuidanceMethod::Bsd { w1: 1.5, w2: 0.5 }
    }

    /// Its name in configs and logs: `sds`, `csd` or `bsd`.
    pub fn name(&self) -> &'static str {
        match self {
            GuidanceMethod::Sds { .. } => "sds",
            GuidanceMethod::Csd { .. } => "csd",
            GuidanceMethod::Bsd { .. } => "bsd",
        }
    }

    /// The method `name` (`sds`, `csd` or `bsd`) from the three weights of a command line:
    /// SDS takes `w1` as its guidance scale, CSD all three (`w3 = None`: `w2 - w1`), BSD `w1`
    /// and `w2`. `None` for another name.
    pub fn from_weights(name: &str, w1: f32, w2: f32, w3: Option<f32>) -> Option<Self> {
        Some(match name {
            "sds" => GuidanceMethod::Sds { guidance_scale: w1 },
            "csd" => GuidanceMethod::Csd { w1, w2, w3 },
            "bsd" => GuidanceMethod::Bsd { w1, w2 },
            _ => return None,
        })
    }

    /// Checks the weights and builds the guidance.
    pub fn build(&self) -> Result<Box<dyn Guidance>, DistillError> {
        let finite = |name: &'static str, value: f32| {
            if value.is_finite() {
                Ok(())
            } else {
                Err(DistillError::NonFiniteWeight { name, value })
            }
        };
        Ok(match *self {
            GuidanceMethod::Sds { guidance_scale } => {
                finite("guidance_scale", guidance_scale)?;
                Box::new(Sds { guidance_scale })
            }
            GuidanceMethod::Csd { w1, w2, w3 } => {
                finite("w1", w1)?;
                finite("w2", w2)?;
                if let Some(w3) = w3 {
                    finite("w3", w3)?;
                }
                Box::new(Csd::new(w1, w2, w3))
            }
            GuidanceMethod::Bsd { w1, w2 } => {
                finite("w1", w1)?;
                finite("w2", w2)?;
                Box::new(Bsd { w1, w2 })
            }
        })
    }
}
