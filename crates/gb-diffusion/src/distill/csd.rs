//! Classifier Score Distillation (Yu et al. 2023), generalised with a free `w3`.

use burn::tensor::Tensor;

use super::guidance::{Branch, Guidance};

/// CSD: `w1*eps(y) + w3*eps(null) - w2*eps(y_neg)`.
///
/// The original CSD is `w3 = w2 - w1` (the direction then depends only on differences of
/// predictions); any other `w3` is allowed, and `w3 = 0` is exactly BSD. No noise term. One
/// batched U-Net call of batch 3 per image: `[text, unconditional, negative]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Csd {
    /// Weight of `eps(y)`.
    pub w1: f32,
    /// Weight of `eps(y_neg)` (subtracted).
    pub w2: f32,
    /// Weight of `eps(null)`.
    pub w3: f32,
}

impl Csd {
    /// CSD with `w3 = w3.unwrap_or(w2 - w1)`.
    pub fn new(w1: f32, w2: f32, w3: Option<f32>) -> Self {
        Self {
            w1,
            w2,
            w3: w3.unwrap_or(w2 - w1),
        }
    }
}

impl Guidance for Csd {
    fn name(&self) -> &'static str {
        "csd"
    }

    fn branches(&self) -> &'static [Branch] {
        &[Branch::Text, Branch::Unconditional, Branch::Negative]
    }

    fn direction(&self, eps: &[Tensor<4>], _noise: &Tensor<4>) -> Tensor<4> {
        // Evaluated as (w1*a + w3*b) - w2*c so that w3 = 0 reproduces BSD bit for bit.
        let (text, uncond, negative) = (eps[0].clone(), eps[1].clone(), eps[2].clone());
        (text.mul_scalar(self.w1) + uncond.mul_scalar(self.w3)) - negative.mul_scalar(self.w2)
    }
}
