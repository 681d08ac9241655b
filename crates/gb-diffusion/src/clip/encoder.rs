//! Pre-norm transformer layers (`encoder.layers.N`).

use burn::module::Module;
use burn::nn::{LayerNorm, LayerNormConfig};
use burn::tensor::{Device, Tensor};

use super::attention::ClipAttention;
use super::mlp::ClipMlp;
use crate::config::ClipTextConfig;
use crate::precision::layer_norm_f32;

/// `encoder.layers.N`: `x + attn(ln1(x))`, then `x + mlp(ln2(x))`.
#[derive(Module, Debug)]
pub struct ClipEncoderLayer {
    /// Causal self-attention.
    pub self_attn: ClipAttention,
    /// Norm before attention.
    pub layer_norm1: LayerNorm,
    /// Feed-forward block.
    pub mlp: ClipMlp,
    /// Norm before the MLP.
    pub layer_norm2: LayerNorm,
}

impl ClipEncoderLayer {
    /// Randomly initialised layer.
    pub fn new(config: &ClipTextConfig, device: &Device) -> Self {
        let norm = || {
            LayerNormConfig::new(config.hidden_size)
                .with_epsilon(config.layer_norm_eps)
                .init(device)
        };
        Self {
            self_attn: ClipAttention::new(config, device),
            layer_norm1: norm(),
            mlp: ClipMlp::new(config, device),
            layer_norm2: norm(),
        }
    }

    /// One residual layer.
    pub fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        let x = x.clone() + self.self_attn.forward(layer_norm_f32(&self.layer_norm1, x));
        x.clone() + self.mlp.forward(layer_norm_f32(&self.layer_norm2, x))
    }
}

/// `encoder`: the stack of layers.
#[derive(Module, Debug)]
pub struct ClipEncoder {
    /// `layers.0 .. layers.{n-1}`.
    pub layers: Vec<ClipEncoderLayer>,
}

impl ClipEncoder {
    /// Randomly initialised stack of `num_hidden_layers` layers.
    pub fn new(config: &ClipTextConfig, device: &Device) -> Self {
        Self {
            layers: (0..config.num_hidden_layers)
                .map(|_| ClipEncoderLayer::new(config, device))
                .collect(),
        }
    }

    /// Runs every layer.
    pub fn forward(&self, mut x: Tensor<3>) -> Tensor<3> {
        for layer in &self.layers {
            x = layer.forward(x);
        }
        x
    }
}
