//! Score Distillation Sampling (DreamFusion).

use burn::tensor::Tensor;

use super::guidance::{Branch, Guidance};

/// SDS: `eps_cfg - eps`, with diffusers' classifier-free guidance convention
/// `eps_cfg = eps_uncond + s * (eps_text - eps_uncond)`.
///
/// threestudio writes `eps_text + s * (eps_text - eps_uncond)`, i.e. its scale is ours minus
/// one: threestudio's `s = 100` is `guidance_scale = 101` here. One batched U-Net call of
/// batch 2 per image: `[text, unconditional]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sds {
    /// Classifier-free guidance scale `s` (diffusers' convention).
    pub guidance_scale: f32,
}

impl Guidance for Sds {
    fn name(&self) -> &'static str {
        "sds"
    }

    fn branches(&self) -> &'static [Branch] {
        &[Branch::Text, Branch::Unconditional]
    }

    fn direction(&self, eps: &[Tensor<4>], noise: &Tensor<4>) -> Tensor<4> {
        let (text, uncond) = (eps[0].clone(), eps[1].clone());
        let cfg = uncond.clone() + (text - uncond).mul_scalar(self.guidance_scale);
        cfg - noise.clone()
    }
}
