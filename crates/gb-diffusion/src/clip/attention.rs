//! Multi-head causal self-attention (`self_attn`).

use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::activation::softmax;
use burn::tensor::{Bool, DType, Device, Int, Tensor};

use crate::config::ClipTextConfig;

/// `self_attn`: `q_proj`, `k_proj`, `v_proj`, `out_proj` with a causal mask.
#[derive(Module, Debug)]
pub struct ClipAttention {
    /// Query projection.
    pub q_proj: Linear,
    /// Key projection.
    pub k_proj: Linear,
    /// Value projection.
    pub v_proj: Linear,
    /// Output projection.
    pub out_proj: Linear,
    /// Number of heads.
    #[module(skip)]
    pub num_heads: usize,
}

impl ClipAttention {
    /// Randomly initialised attention of the configured width.
    pub fn new(config: &ClipTextConfig, device: &Device) -> Self {
        let d = config.hidden_size;
        let linear = || LinearConfig::new(d, d).init(device);
        Self {
            q_proj: linear(),
            k_proj: linear(),
            v_proj: linear(),
            out_proj: linear(),
            num_heads: config.num_attention_heads,
        }
    }

    /// `[batch, seq, hidden]` to `[batch, seq, hidden]`; token `i` attends to `0..=i`.
    /// Scores and softmax are computed in f32.
    pub fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        let [batch, seq, hidden] = x.dims();
        let heads = self.num_heads;
        let head_dim = hidden / heads;
        let split = |t: Tensor<3>| {
            t.reshape([batch, seq, heads, head_dim])
                .swap_dims(1, 2)
                .cast(DType::F32)
        };
        let in_dtype = x.dtype();
        let q = split(self.q_proj.forward(x.clone()));
        let k = split(self.k_proj.forward(x.clone()));
        let v = split(self.v_proj.forward(x));
        let scale = (head_dim as f64).powf(-0.5);
        let scores = q.matmul(k.swap_dims(2, 3)).mul_scalar(scale);
        let mask = causal_mask(seq, &scores.device()).reshape([1, 1, seq, seq]);
        let scores = scores.mask_fill(mask.expand([batch, heads, seq, seq]), -1.0e30);
        let probs = softmax(scores, 3);
        let out = probs
            .matmul(v)
            .swap_dims(1, 2)
            .reshape([batch, seq, hidden])
            .cast(in_dtype);
        self.out_proj.forward(out)
    }
}

/// `[seq, seq]` mask that is true where key position > query position.
pub fn causal_mask(seq: usize, device: &Device) -> Tensor<2, Bool> {
    let idx = Tensor::<1, Int>::arange(0..seq as i64, device);
    let rows = idx.clone().reshape([seq, 1]).expand([seq, seq]);
    let cols = idx.reshape([1, seq]).expand([seq, seq]);
    cols.greater(rows)
}
