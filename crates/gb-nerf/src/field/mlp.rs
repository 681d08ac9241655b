//! A plain ReLU multilayer perceptron with an optional input skip connection.

use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};

/// `Linear -> ReLU -> ... -> Linear` (no activation after the last layer). When `skip` is
/// set, the network input is concatenated to the hidden state before layer `skip`.
#[derive(Module, Debug)]
pub struct Mlp {
    /// The layers, in order.
    pub layers: Vec<Linear>,
    /// Index of the layer whose input is `[hidden, network input]`, if any.
    #[module(skip)]
    pub skip: Option<usize>,
}

impl Mlp {
    /// `input -> hidden x (depth - 1) -> output`; `depth` counts linear layers (>= 1).
    pub fn new(
        input: usize,
        hidden: usize,
        output: usize,
        depth: usize,
        skip: Option<usize>,
        device: &Device,
    ) -> Self {
        let depth = depth.max(1);
        let skip = skip.filter(|&s| s > 0 && s < depth);
        let mut layers = Vec::with_capacity(depth);
        for i in 0..depth {
            let mut d_in = if i == 0 { input } else { hidden };
            if Some(i) == skip {
                d_in += input;
            }
            let d_out = if i + 1 == depth { output } else { hidden };
            layers.push(LinearConfig::new(d_in, d_out).init(device));
        }
        Self { layers, skip }
    }

    /// Applies the network to `[N, input]`.
    pub fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        let mut h = x.clone();
        let last = self.layers.len() - 1;
        for (i, layer) in self.layers.iter().enumerate() {
            if Some(i) == self.skip {
                h = Tensor::cat(vec![h, x.clone()], 1);
            }
            h = layer.forward(h);
            if i != last {
                h = relu(h);
            }
        }
        h
    }
}
