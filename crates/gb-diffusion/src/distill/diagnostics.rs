//! What one distillation step reports for logs, tests and benchmarks.

use serde::Serialize;

/// Diagnostics of one guidance step.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepDiagnostics {
    /// Guidance method name (`sds`, `csd`, `bsd`).
    pub method: &'static str,
    /// The distiller's step counter when this step ran (drives the annealed schedule).
    pub iteration: usize,
    /// Timestep index given to the U-Net.
    pub timestep: usize,
    /// The same timestep as a fraction of the training schedule.
    pub t: f64,
    /// `alpha_bar(t)`.
    pub alpha_bar: f64,
    /// `w(t)`.
    pub weight: f64,
    /// Number of U-Net calls made by this step (always 1: one batched call).
    pub unet_calls: usize,
    /// Batch size of that call (branches x images: SDS and BSD 2, CSD 3 per image).
    pub unet_batch: usize,
    /// L2 norm of the final latent gradient.
    pub grad_norm: f64,
    /// threestudio's logged loss `0.5 * mean(g^2)` (the value of
    /// `0.5 * mse(latents, latents - g)`), for logging only.
    pub loss: f64,
    /// Number of non-finite gradient values that were zeroed.
    pub non_finite_zeroed: usize,
}
