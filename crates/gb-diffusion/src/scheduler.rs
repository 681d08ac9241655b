//! diffusers' DDPM/DDIM noise schedule and the deterministic DDIM sampler step (`eta = 0`).

use burn::tensor::{Tensor, TensorData};

use crate::config::{BetaSchedule, PredictionType, SchedulerConfig, TimestepSpacing};

/// Error of the scheduler API on out-of-range requests.
#[derive(Debug, thiserror::Error)]
pub enum SchedulerError {
    /// `num_inference_steps` is 0 or larger than the training timesteps.
    #[error("num_inference_steps = {steps} must be in 1..={train}")]
    Steps {
        /// The requested count.
        steps: usize,
        /// `num_train_timesteps`.
        train: usize,
    },
    /// The number of timesteps is neither 1 nor the batch size.
    #[error("{given} timesteps for a batch of {batch} (give 1 or {batch})")]
    Batch {
        /// Timesteps given.
        given: usize,
        /// Batch size.
        batch: usize,
    },
    /// A timestep outside `0..num_train_timesteps`.
    #[error("timestep {t} is outside 0..{train}")]
    Timestep {
        /// The timestep.
        t: usize,
        /// `num_train_timesteps`.
        train: usize,
    },
}

/// The noise schedule (`alphas_cumprod`) and DDIM's inference timesteps.
#[derive(Debug, Clone)]
pub struct DdimScheduler {
    /// The configuration it was built from.
    pub config: SchedulerConfig,
    /// `prod_{s <= t} (1 - beta_s)` for every training timestep.
    pub alphas_cumprod: Vec<f64>,
    /// `alpha_bar` used past the last step (1, or `alphas_cumprod[0]`).
    pub final_alpha_cumprod: f64,
    /// Inference timesteps in sampling order (descending); empty until
    /// [`DdimScheduler::set_timesteps`].
    pub timesteps: Vec<usize>,
    /// The step count of [`DdimScheduler::set_timesteps`].
    pub num_inference_steps: usize,
}

/// `alphas_cumprod` of a scheduler config: the running product of `1 - beta` over
/// [`betas`] (diffusers' `alphas_cumprod`).
pub fn alphas_cumprod(cfg: &SchedulerConfig) -> Vec<f64> {
    let mut acc = 1.0;
    betas(cfg)
        .into_iter()
        .map(|b| {
            acc *= 1.0 - b;
            acc
        })
        .collect()
}

/// `N` betas of the configured schedule, as diffusers computes them.
pub fn betas(cfg: &SchedulerConfig) -> Vec<f64> {
    let n = cfg.num_train_timesteps;
    let lin = |a: f64, b: f64| -> Vec<f64> {
        if n == 1 {
            return vec![a];
        }
        (0..n)
            .map(|i| a + (b - a) * i as f64 / (n - 1) as f64)
            .collect()
    };
    match cfg.beta_schedule {
        BetaSchedule::Linear => lin(cfg.beta_start, cfg.beta_end),
        BetaSchedule::ScaledLinear => lin(cfg.beta_start.sqrt(), cfg.beta_end.sqrt())
            .into_iter()
            .map(|b| b * b)
            .collect(),
    }
}

impl DdimScheduler {
    /// The schedule of `config` (no inference timesteps yet).
    pub fn new(config: SchedulerConfig) -> Self {
        let alphas_cumprod = alphas_cumprod(&config);
        let final_alpha_cumprod = if config.set_alpha_to_one {
            1.0
        } else {
            alphas_cumprod[0]
        };
        Self {
            config,
            alphas_cumprod,
            final_alpha_cumprod,
            timesteps: Vec::new(),
            num_inference_steps: 0,
        }
    }

    /// Chooses `steps` inference timesteps with the configured spacing (diffusers'
    /// `set_timesteps`).
    pub fn set_timesteps(&mut self, steps: usize) -> Result<(), SchedulerError> {
        let n = self.config.num_train_timesteps;
        if steps == 0 || steps > n {
            return Err(SchedulerError::Steps { steps, train: n });
        }
        self.timesteps = match self.config.timestep_spacing {
            TimestepSpacing::Leading => {
                let ratio = n / steps;
                (0..steps)
                    .rev()
                    .map(|i| (i * ratio + self.config.steps_offset).min(n - 1))
                    .collect()
            }
            TimestepSpacing::Trailing => {
                let ratio = n as f64 / steps as f64;
                (0..steps)
                    .map(|i| ((n as f64 - i as f64 * ratio).round() as usize).saturating_sub(1))
                    .collect()
            }
            TimestepSpacing::Linspace => (0..steps)
                .rev()
                .map(|i| {
                    let x = if steps == 1 {
                        0.0
                    } else {
                        (n - 1) as f64 * i as f64 / (steps - 1) as f64
                    };
                    x.round_ties_even() as usize
                })
                .collect(),
        };
        self.num_inference_steps = steps;
        Ok(())
    }

    /// `alpha_bar(t)`.
    pub fn alpha_bar(&self, t: usize) -> Result<f64, SchedulerError> {
        self.alphas_cumprod
            .get(t)
            .copied()
            .ok_or(SchedulerError::Timestep {
                t,
                train: self.config.num_train_timesteps,
            })
    }

    /// Forward diffusion `sqrt(a_t) x0 + sqrt(1 - a_t) noise`, one timestep per batch item.
    pub fn add_noise(
        &self,
        x0: Tensor<4>,
        noise: Tensor<4>,
        timesteps: &[usize],
    ) -> Result<Tensor<4>, SchedulerError> {
        let b = x0.dims()[0];
        if timesteps.len() != 1 && timesteps.len() != b {
            return Err(SchedulerError::Batch {
                given: timesteps.len(),
                batch: b,
            });
        }
        let device = x0.device();
        let mut sa = Vec::with_capacity(b);
        let mut sb = Vec::with_capacity(b);
        for i in 0..b {
            let t = timesteps[if timesteps.len() == 1 { 0 } else { i }];
            let a = self.alpha_bar(t)?;
            sa.push(a.sqrt() as f32);
            sb.push((1.0 - a).sqrt() as f32);
        }
        let col = |v: Vec<f32>| Tensor::<4>::from_data(TensorData::new(v, [b, 1, 1, 1]), &device);
        Ok(x0 * col(sa) + noise * col(sb))
    }

    /// One deterministic DDIM step (`eta = 0`, no clipping) from timestep `t` to
    /// `t - N / num_inference_steps`; returns the previous sample.
    pub fn step(
        &self,
        model_output: Tensor<4>,
        t: usize,
        sample: Tensor<4>,
    ) -> Result<Tensor<4>, SchedulerError> {
        let n = self.config.num_train_timesteps;
        let stride = n / self.num_inference_steps.max(1);
        let a_t = self.alpha_bar(t)?;
        let a_prev = if t >= stride {
            self.alpha_bar(t - stride)?
        } else {
            self.final_alpha_cumprod
        };
        let b_t = 1.0 - a_t;
        let (x0, eps) = match self.config.prediction_type {
            PredictionType::Epsilon => (
                (sample.clone() - model_output.clone().mul_scalar(b_t.sqrt()))
                    .div_scalar(a_t.sqrt()),
                model_output,
            ),
            PredictionType::VPrediction => (
                sample.clone().mul_scalar(a_t.sqrt()) - model_output.clone().mul_scalar(b_t.sqrt()),
                model_output.mul_scalar(a_t.sqrt()) + sample.mul_scalar(b_t.sqrt()),
            ),
        };
        Ok(x0.mul_scalar(a_prev.sqrt()) + eps.mul_scalar((1.0 - a_prev).sqrt()))
    }
}
