//! Timestep sampling and the weight `w(t)`.
//!
//! Timesteps are fractions `t` of the training schedule (`num_train_timesteps`, 1000 for SD);
//! the U-Net receives the integer index `round(t * N)`. The paper samples `t` uniformly in
//! `[0.02, 0.98]` (threestudio's `randint(int(N*t_min), int(N*t_max) + 1)`); the reference
//! code's deterministic schedule is `t = N*t_max - N*(t_max - t_min) * sqrt(i / total)`,
//! which with the defaults is `980 - 960 * sqrt(i / 20000)`.

use rand::Rng;
use serde::{Deserialize, Serialize};

use super::error::DistillError;

/// How the timestep of each step is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum TimestepSchedule {
    /// Uniform integer timestep in `[floor(N*t_min), floor(N*t_max)]` (the paper).
    Uniform,
    /// The reference code's annealed schedule `N*t_max - N*(t_max-t_min)*sqrt(i/total_steps)`,
    /// rounded; `i` is clamped to `total_steps`.
    Annealed {
        /// Number of steps over which `t` decreases from `t_max` to `t_min` (20000).
        total_steps: usize,
    },
}

/// The weight `w(t)` multiplying every guidance direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Weighting {
    /// `w(t) = 1 - alpha_bar(t)` (the reference code).
    #[default]
    OneMinusAlphaBar,
    /// `w(t) = 1`.
    Constant,
}

/// Timestep settings: range and schedule.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TimestepConfig {
    /// Lower end of `t`, in (0, 1); 0.02 in the paper.
    pub t_min: f64,
    /// Upper end of `t`, in (0, 1); 0.98 in the paper.
    pub t_max: f64,
    /// Uniform sampling or the reference's annealed schedule.
    pub schedule: TimestepSchedule,
}

impl Default for TimestepConfig {
    fn default() -> Self {
        Self {
            t_min: 0.02,
            t_max: 0.98,
            schedule: TimestepSchedule::Uniform,
        }
    }
}

impl TimestepConfig {
    /// The reference code's deterministic schedule `980 - 960*sqrt(i/20000)`.
    pub fn reference_annealed() -> Self {
        Self {
            schedule: TimestepSchedule::Annealed { total_steps: 20000 },
            ..Self::default()
        }
    }

    /// Rejects `t_min`/`t_max` outside (0, 1), an empty range, or `total_steps = 0`.
    pub fn validate(&self) -> Result<(), DistillError> {
        check_fraction("t_min", self.t_min)?;
        check_fraction("t_max", self.t_max)?;
        if self.t_min > self.t_max {
            return Err(DistillError::TimestepRangeEmpty {
                t_min: self.t_min,
                t_max: self.t_max,
            });
        }
        if let TimestepSchedule::Annealed { total_steps: 0 } = self.schedule {
            return Err(DistillError::Config {
                field: "timestep.schedule.total_steps",
                message: "must be > 0".into(),
            });
        }
        Ok(())
    }

    /// The timestep index of step `iteration` (uses `rng` for the uniform schedule) for a
    /// schedule of `num_train_timesteps`. Call [`TimestepConfig::validate`] first.
    pub fn sample(
        &self,
        iteration: usize,
        num_train_timesteps: usize,
        rng: &mut impl Rng,
    ) -> usize {
        let n = num_train_timesteps as f64;
        let (lo, hi) = index_range(self.t_min, self.t_max, num_train_timesteps);
        match self.schedule {
            TimestepSchedule::Uniform => rng.random_range(lo..=hi),
            TimestepSchedule::Annealed { total_steps } => {
                let progress = (iteration.min(total_steps) as f64 / total_steps as f64).sqrt();
                let t = n * self.t_max - n * (self.t_max - self.t_min) * progress;
                (t.round() as usize).clamp(lo, hi)
            }
        }
    }
}

/// The inclusive timestep-index range `[floor(N*t_min), floor(N*t_max)]`, kept within
/// `[1, N-1]`.
pub fn index_range(t_min: f64, t_max: f64, num_train_timesteps: usize) -> (usize, usize) {
    let n = num_train_timesteps as f64;
    let top = num_train_timesteps.saturating_sub(1).max(1);
    let lo = ((n * t_min).floor() as usize).clamp(1, top);
    let hi = ((n * t_max).floor() as usize).clamp(lo, top);
    (lo, hi)
}

/// Rejects a timestep fraction outside the open interval (0, 1) with a clear error.
pub fn check_fraction(field: &'static str, value: f64) -> Result<(), DistillError> {
    if value.is_finite() && value > 0.0 && value < 1.0 {
        Ok(())
    } else {
        Err(DistillError::TimestepOutOfRange { field, value })
    }
}

/// Converts a fraction `t` in (0, 1) into a timestep index `round(t * N)` within `[1, N-1]`.
pub fn fraction_to_index(t: f64, num_train_timesteps: usize) -> Result<usize, DistillError> {
    check_fraction("t", t)?;
    let top = num_train_timesteps.saturating_sub(1).max(1);
    Ok(((t * num_train_timesteps as f64).round() as usize).clamp(1, top))
}

/// `w(t)` for a timestep index, given `alpha_bar(t)`.
pub fn weight(weighting: Weighting, alpha_bar: f64) -> f64 {
    match weighting {
        Weighting::OneMinusAlphaBar => 1.0 - alpha_bar,
        Weighting::Constant => 1.0,
    }
}
