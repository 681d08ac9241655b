//! The noise schedule score distillation reads: `alpha_bar(t)` for every training timestep,
//! taken from a slice the scheduler provides ([`crate::scheduler::DdimScheduler`]'s
//! `alphas_cumprod`).

use super::error::DistillError;
use crate::config::SchedulerConfig;
use crate::scheduler::DdimScheduler;

/// `alphas_cumprod` of a diffusion model's training schedule, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct AlphasCumprod {
    values: Vec<f64>,
}

impl AlphasCumprod {
    /// Wraps a scheduler's `alphas_cumprod` (one value per training timestep, each in
    /// (0, 1]). Rejects fewer than two values or values outside that interval.
    pub fn new(values: &[f64]) -> Result<Self, DistillError> {
        if values.len() < 2 {
            return Err(DistillError::BadNoiseSchedule(format!(
                "needs at least 2 timesteps, got {}",
                values.len()
            )));
        }
        if let Some((i, v)) = values
            .iter()
            .enumerate()
            .find(|(_, v)| !(v.is_finite() && **v > 0.0 && **v <= 1.0))
        {
            return Err(DistillError::BadNoiseSchedule(format!(
                "value {v} at timestep {i} is not in (0, 1]"
            )));
        }
        Ok(Self {
            values: values.to_vec(),
        })
    }

    /// The schedule of a scheduler config (through [`DdimScheduler`]).
    pub fn from_config(config: &SchedulerConfig) -> Result<Self, DistillError> {
        Self::new(&DdimScheduler::new(config.clone()).alphas_cumprod)
    }

    /// Stable Diffusion 1.x's schedule (`scaled_linear`, 1000 steps, 0.00085 .. 0.012).
    pub fn stable_diffusion() -> Self {
        Self::from_config(&SchedulerConfig::default()).expect("the SD 1.x schedule is valid")
    }

    /// Number of training timesteps `N`.
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// Always false: the schedule has at least two timesteps.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// `alpha_bar` at timestep index `t` (clamped to the last index).
    pub fn at(&self, t: usize) -> f64 {
        self.values[t.min(self.values.len() - 1)]
    }
}
