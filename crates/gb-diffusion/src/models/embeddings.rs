//! Timestep embeddings: diffusers' `Timesteps` (sinusoidal) and `TimestepEmbedding` (MLP).

use burn::module::Module;
use burn::nn::Linear;
use burn::tensor::activation::silu;
use burn::tensor::{Device, Tensor, TensorData};

use super::layers::linear;

/// diffusers' `get_timestep_embedding` with `max_period = 10000` and `scale = 1`:
/// `[n, dim]` rows `[sin(t f), cos(t f)]` (or `[cos, sin]` when `flip_sin_to_cos`), with
/// `f_i = exp(-ln(10000) i / (dim / 2 - freq_shift))`. Computed on the host in f32 in the
/// same operation order as diffusers.
pub fn timestep_embedding(
    timesteps: &[f32],
    dim: usize,
    flip_sin_to_cos: bool,
    freq_shift: f64,
    device: &Device,
) -> Tensor<2> {
    let half = dim / 2;
    let log_period = -(10000f64.ln()) as f32;
    let denom = (half as f64 - freq_shift) as f32;
    let freqs: Vec<f32> = (0..half)
        .map(|i| ((log_period * i as f32) / denom).exp())
        .collect();
    let mut data = Vec::with_capacity(timesteps.len() * dim);
    for &t in timesteps {
        let args: Vec<f32> = freqs.iter().map(|&f| t * f).collect();
        let sin = args.iter().map(|a| a.sin());
        let cos = args.iter().map(|a| a.cos());
        if flip_sin_to_cos {
            data.extend(cos.chain(sin));
        } else {
            data.extend(sin.chain(cos));
        }
        if dim % 2 == 1 {
            data.push(0.0);
        }
    }
    Tensor::from_data(TensorData::new(data, [timesteps.len(), dim]), device)
}

/// `time_embedding`: `linear_1`, SiLU, `linear_2`.
#[derive(Module, Debug)]
pub struct TimestepEmbedding {
    /// First projection (`in -> time_embed_dim`).
    pub linear_1: Linear,
    /// Second projection (`time_embed_dim -> time_embed_dim`).
    pub linear_2: Linear,
}

impl TimestepEmbedding {
    /// Randomly initialised embedding MLP.
    pub fn new(d_in: usize, d_out: usize, device: &Device) -> Self {
        Self {
            linear_1: linear(d_in, d_out, true, device),
            linear_2: linear(d_out, d_out, true, device),
        }
    }

    /// `[n, d_in]` to `[n, d_out]`.
    pub fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        self.linear_2.forward(silu(self.linear_1.forward(x)))
    }
}
