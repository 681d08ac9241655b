//! LoRA on convolution kernels (and any weight laid out `[out, in, ...]`): a
//! reparameterisation of our own, since burn's `LoraAdapter` covers `[in, out]` linear
//! weights only.

use burn::module::{Module, Param, Reparameterization};
use burn::tensor::Tensor;

/// Effective weight `base + scale * reshape(up @ down, base.shape)`, with `up: [out, r]`
/// and `down: [r, in * kh * kw]` — PEFT's conv LoRA (`lora_A`: conv `in -> r` with the
/// layer's kernel, `lora_B`: 1x1 conv `r -> out`) flattened.
#[derive(Module, Debug)]
pub struct ConvLoraAdapter {
    /// Down factor `[r, in * kh * kw]`.
    pub down: Param<Tensor<2>>,
    /// Up factor `[out, r]`.
    pub up: Param<Tensor<2>>,
    /// Multiplier of the low-rank product (`alpha / r`).
    #[module(skip)]
    pub scale: f64,
}

impl ConvLoraAdapter {
    /// The low-rank update `scale * up @ down`, `[out, in * kh * kw]`.
    pub fn delta(&self) -> Tensor<2> {
        self.up.val().matmul(self.down.val()).mul_scalar(self.scale)
    }
}

impl Reparameterization for ConvLoraAdapter {
    const NAME: &'static str = "conv_lora";

    fn apply<const D: usize>(&self, base: Tensor<D>) -> Tensor<D> {
        let delta: Tensor<D> = self.delta().reshape(base.shape());
        base + delta
    }
}
