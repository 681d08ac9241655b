//! Feed-forward block (`mlp.fc1` -> activation -> `mlp.fc2`).

use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::activation::{gelu, sigmoid};
use burn::tensor::{Device, Tensor};

use crate::config::{ClipActivation, ClipTextConfig};

/// `mlp`: two linear layers around `quick_gelu` or `gelu`.
#[derive(Module, Debug)]
pub struct ClipMlp {
    /// `hidden -> intermediate`.
    pub fc1: Linear,
    /// `intermediate -> hidden`.
    pub fc2: Linear,
    /// The activation between them.
    #[module(skip)]
    pub activation: ClipActivation,
}

impl ClipMlp {
    /// Randomly initialised MLP of the configured sizes.
    pub fn new(config: &ClipTextConfig, device: &Device) -> Self {
        Self {
            fc1: LinearConfig::new(config.hidden_size, config.intermediate_size).init(device),
            fc2: LinearConfig::new(config.intermediate_size, config.hidden_size).init(device),
            activation: config.hidden_act,
        }
    }

    /// `[batch, seq, hidden]` to the same shape.
    pub fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        let h = self.fc1.forward(x);
        let h = match self.activation {
            ClipActivation::QuickGelu => h.clone() * sigmoid(h.mul_scalar(1.702)),
            ClipActivation::Gelu => gelu(h),
        };
        self.fc2.forward(h)
    }
}
