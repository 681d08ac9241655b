//! The one interface every score-distillation guidance implements (threestudio style: one
//! small file per method, [`super::sds`], [`super::csd`], [`super::bsd`]); the one
//! [`super::GuidanceMethod`] that configs and the command line name builds them
//! ([`super::guidance_method`]).
//!
//! A guidance declares which text conditionings ("branches") its single batched U-Net call
//! evaluates, and combines the resulting noise predictions into the unweighted score
//! direction. The driver ([`super::step::ScoreDistiller`]) multiplies that direction by
//! `w(t)`, masks it, zeroes non-finite values, optionally clamps it and injects it.

use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};

/// The text conditioning of one row block of the batched U-Net call.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Branch {
    /// The (appearance or geometry) prompt `y`.
    Text,
    /// The empty prompt `null` (unconditional).
    Unconditional,
    /// The negative prompt `y_neg`.
    Negative,
}

/// A score-distillation guidance: which eps it needs and how it combines them.
pub trait Guidance: Send + Sync {
    /// Short lowercase name (`sds`, `csd`, `bsd`) for logs and reports.
    fn name(&self) -> &'static str;

    /// The conditionings evaluated by the one batched U-Net call, in batch order.
    /// The U-Net batch is `branches().len()` times the number of images.
    fn branches(&self) -> &'static [Branch];

    /// Combines the noise predictions (one tensor per branch, in [`Guidance::branches`]
    /// order, each `[B, C, h, w]`) and the injected noise into the unweighted direction.
    fn direction(&self, eps: &[Tensor<4>], noise: &Tensor<4>) -> Tensor<4>;
}
