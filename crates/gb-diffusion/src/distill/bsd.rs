//! Balanced Score Distillation (GB-NeRF).

use burn::tensor::Tensor;

use super::guidance::{Branch, Guidance};

/// BSD: `w1*eps(y) - w2*eps(y_neg)`: no noise term and no unconditional term. One batched
/// U-Net call of batch 2 per image: `[text, negative]`, one evaluation fewer than CSD.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bsd {
    /// Weight of `eps(y)`.
    pub w1: f32,
    /// Weight of `eps(y_neg)` (subtracted).
    pub w2: f32,
}

impl Guidance for Bsd {
    fn name(&self) -> &'static str {
        "bsd"
    }

    fn branches(&self) -> &'static [Branch] {
        &[Branch::Text, Branch::Negative]
    }

    fn direction(&self, eps: &[Tensor<4>], _noise: &Tensor<4>) -> Tensor<4> {
        let (text, negative) = (eps[0].clone(), eps[1].clone());
        text.mul_scalar(self.w1) - negative.mul_scalar(self.w2)
    }
}
