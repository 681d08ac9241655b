//! `scheduler/scheduler_config.json`: diffusers' DDPM/DDIM scheduler configuration.

use serde::{Deserialize, Serialize};

use super::ConfigError;

/// What the U-Net predicts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum PredictionType {
    /// The added noise (SD 1.x, SD 2 base and inpainting).
    #[default]
    Epsilon,
    /// `v = sqrt(a) * eps - sqrt(1 - a) * x0` (SD 2.x 768-v).
    VPrediction,
}

/// Shape of the beta schedule.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum BetaSchedule {
    /// `linspace(sqrt(beta_start), sqrt(beta_end), N)^2` (Stable Diffusion).
    #[default]
    ScaledLinear,
    /// `linspace(beta_start, beta_end, N)`.
    Linear,
}

/// How inference timesteps are spread over the training timesteps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum TimestepSpacing {
    /// `arange(n) * (N / n)`, reversed, plus `steps_offset` (diffusers' DDIM default).
    #[default]
    Leading,
    /// `round(arange(N, 0, -N / n)) - 1`.
    Trailing,
    /// `round(linspace(0, N - 1, n))`, reversed.
    Linspace,
}

/// The fields of a DDPM/DDIM `scheduler_config.json` that SD pipelines use.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SchedulerConfig {
    /// Training timesteps (1000).
    #[serde(default = "d_1000")]
    pub num_train_timesteps: usize,
    /// First beta (0.00085 for SD).
    #[serde(default = "d_beta_start")]
    pub beta_start: f64,
    /// Last beta (0.012 for SD).
    #[serde(default = "d_beta_end")]
    pub beta_end: f64,
    /// Beta schedule.
    #[serde(default)]
    pub beta_schedule: BetaSchedule,
    /// What the model predicts.
    #[serde(default)]
    pub prediction_type: PredictionType,
    /// Offset added to the inference timesteps (1 for SD).
    #[serde(default)]
    pub steps_offset: usize,
    /// DDIM: whether the step past the end uses `alpha_bar = 1` (else `alphas_cumprod[0]`).
    #[serde(default = "d_true")]
    pub set_alpha_to_one: bool,
    /// Whether the predicted x0 is clipped (false for SD latents; unsupported when true).
    #[serde(default)]
    pub clip_sample: bool,
    /// Timestep spacing.
    #[serde(default)]
    pub timestep_spacing: TimestepSpacing,
}

fn d_1000() -> usize {
    1000
}
fn d_beta_start() -> f64 {
    0.00085
}
fn d_beta_end() -> f64 {
    0.012
}
fn d_true() -> bool {
    true
}

impl Default for SchedulerConfig {
    /// Stable Diffusion 1.x's DDIM configuration.
    fn default() -> Self {
        Self {
            num_train_timesteps: 1000,
            beta_start: 0.00085,
            beta_end: 0.012,
            beta_schedule: BetaSchedule::ScaledLinear,
            prediction_type: PredictionType::Epsilon,
            steps_offset: 1,
            set_alpha_to_one: false,
            clip_sample: false,
            timestep_spacing: TimestepSpacing::Leading,
        }
    }
}

impl SchedulerConfig {
    /// Reads `scheduler_config.json` and checks that it is supported.
    pub fn from_file(path: &std::path::Path) -> Result<Self, ConfigError> {
        let cfg: Self = super::read_json_config(path)?;
        if cfg.clip_sample {
            return Err(ConfigError::Unsupported {
                path: path.to_path_buf(),
                field: "clip_sample".into(),
                value: "true".into(),
            });
        }
        if cfg.num_train_timesteps == 0 {
            return Err(ConfigError::Unsupported {
                path: path.to_path_buf(),
                field: "num_train_timesteps".into(),
                value: "0".into(),
            });
        }
        Ok(cfg)
    }
}
