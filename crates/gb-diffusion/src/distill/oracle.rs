//! The score of a prior that knows the answer: an oracle noise predictor for experiments.
//!
//! For a data distribution that is a single point `z0` (the latents of the true image), the
//! exact noise prediction at `x_t = sqrt(a) z0' + sqrt(1 - a) eps` is
//! `eps*(x_t) = (x_t - sqrt(a) z0) / sqrt(1 - a)`: the best denoiser there is. With it,
//! SDS's direction `eps* - eps` is exactly `sqrt(a) / sqrt(1 - a) * (z - z0)`, a pull of the
//! latents straight to the truth, and any failure of the distillation to move a render
//! toward the truth lies in the pipeline (crop, encoder, weights, timesteps), not the prior.
//!
//! [`OracleEps`] answers the rows of chosen branches (the prompt `y`, by default) with
//! `eps*` and leaves the others to the real predictor, so that BSD's negative branch can
//! stay the prior's own. It never stands for a method: no capture has `z0`.

use burn::tensor::Tensor;

use super::alphas::AlphasCumprod;
use super::eps::{EpsBatch, InpaintEpsPredictor};
use super::error::DistillError;
use super::guidance::Branch;

/// An eps-predictor whose rows of [`OracleEps::oracle_branches`] are the exact score of the
/// point distribution at `clean` (module docs) and whose other rows are `inner`'s.
pub struct OracleEps<'a> {
    /// The real predictor, for the other branches.
    pub inner: &'a dyn InpaintEpsPredictor,
    /// The true latents `z0`, `[B, C, h, w]` (no graph).
    pub clean: Tensor<4>,
    /// The noise schedule.
    pub alphas: &'a AlphasCumprod,
    /// The branches of the batched call, in its order (the guidance's `branches()`).
    pub branches: &'a [Branch],
    /// The branches the oracle answers.
    pub oracle_branches: &'a [Branch],
}

impl OracleEps<'_> {
    /// `eps*(x_t)` for `x_t` with `B` rows (module docs).
    pub fn exact_eps(&self, noisy: Tensor<4>, timestep: usize) -> Tensor<4> {
        let a = self.alphas.at(timestep);
        (noisy - self.clean.clone().mul_scalar(a.sqrt())).div_scalar((1.0 - a).sqrt())
    }
}

impl InpaintEpsPredictor for OracleEps<'_> {
    fn predict_eps(&self, batch: EpsBatch) -> Result<Tensor<4>, DistillError> {
        let n = batch.batch_size();
        let b = self.clean.dims()[0];
        if b == 0 || n != b * self.branches.len() {
            return Err(DistillError::Shape {
                tensor: "oracle batch",
                actual: batch.noisy_latents.dims().to_vec(),
                expected: format!(
                    "{} branch(es) of the {b} row(s) of the clean latents",
                    self.branches.len()
                ),
            });
        }
        let all = self
            .branches
            .iter()
            .all(|br| self.oracle_branches.contains(br));
        let (noisy, timestep) = (batch.noisy_latents.clone(), batch.timestep);
        let real = if all {
            None
        } else {
            Some(self.inner.predict_eps(batch)?)
        };
        let rows: Vec<Tensor<4>> = self
            .branches
            .iter()
            .enumerate()
            .map(|(i, br)| match &real {
                Some(real) if !self.oracle_branches.contains(br) => {
                    real.clone().narrow(0, i * b, b)
                }
                _ => self.exact_eps(noisy.clone().narrow(0, i * b, b), timestep),
            })
            .collect();
        Ok(Tensor::cat(rows, 0))
    }
}
