//! The distillation section of a method config: prompts, the RGB and normal-map guidances,
//! the prior input and its resolution.

use serde::{Deserialize, Serialize};

use super::error::DistillError;
use super::prior_input::PriorInputMode;
use super::step::DistillSettings;

/// The prompts of the object-removal task.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Prompts {
    /// Appearance prompt for RGB renders.
    pub appearance: String,
    /// Negative prompt (both guidances).
    #[serde(default)]
    pub negative: String,
    /// Geometry prompt for normal maps.
    pub geometry: String,
}

/// Score-distillation configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DistillConfig {
    /// Prompts.
    pub prompts: Prompts,
    /// Guidance on RGB renders; paper: BSD (7.5, 6.5).
    #[serde(default = "DistillSettings::paper_rgb")]
    pub rgb: DistillSettings,
    /// Guidance on normal maps; paper: BSD (1.5, 0.5).
    #[serde(default = "DistillSettings::paper_normals")]
    pub normals: DistillSettings,
    /// Render alone, or render pasted onto the ground truth (the reference).
    #[serde(default)]
    pub prior_input: PriorInputMode,
    /// The prior's square input resolution (512 for SD 1.5).
    #[serde(default = "default_resolution")]
    pub resolution: usize,
}

fn default_resolution() -> usize {
    512
}

impl DistillConfig {
    /// The paper's settings with the given prompts.
    pub fn paper(prompts: Prompts) -> Self {
        Self {
            prompts,
            rgb: DistillSettings::paper_rgb(),
            normals: DistillSettings::paper_normals(),
            prior_input: PriorInputMode::default(),
            resolution: default_resolution(),
        }
    }

    /// Checks every field that can be checked without a model.
    pub fn validate(&self) -> Result<(), DistillError> {
        for settings in [&self.rgb, &self.normals] {
            settings.timesteps.validate()?;
            settings.guidance.build()?;
        }
        if self.resolution == 0 {
            return Err(DistillError::Config {
                field: "resolution",
                message: "must be > 0".into(),
            });
        }
        if self.prompts.appearance.trim().is_empty() {
            return Err(DistillError::Config {
                field: "prompts.appearance",
                message: "must not be empty".into(),
            });
        }
        Ok(())
    }
}
