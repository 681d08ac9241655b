//! Multi-head causal self-attention (`self_attn`).

use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::module::attention;
use burn::tensor::ops::AttentionModuleOptions;
use burn::tensor::{DType, Device, Tensor};

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
    /// Computed in f32 by Burn's fused attention op in its causal mode.
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
        // Burn's fused attention with its causal mode (scale 1 / sqrt(head_dim)).
        let causal = AttentionModuleOptions {
            is_causal: true,
            ..Default::default()
        };
        let out = attention(q, k, v, None, None, causal)
            .swap_dims(1, 2)
            .reshape([batch, seq, hidden])
            .cast(in_dtype);
        self.out_proj.forward(out)
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::activation::softmax;
    use burn::tensor::{Distribution, Int};

    use super::*;

    /// The causal scores materialised and masked, as before the fused op.
    fn materialised_causal(q: Tensor<4>, k: Tensor<4>, v: Tensor<4>) -> Tensor<4> {
        let [b, h, seq, d] = q.dims();
        let device = q.device();
        let scores = q
            .matmul(k.swap_dims(2, 3))
            .mul_scalar((d as f64).powf(-0.5));
        let idx = Tensor::<1, Int>::arange(0..seq as i64, &device);
        let rows = idx.clone().reshape([seq, 1]).expand([seq, seq]);
        let cols = idx.reshape([1, seq]).expand([seq, seq]);
        let future = cols
            .greater(rows)
            .reshape([1, 1, seq, seq])
            .expand([b, h, seq, seq]);
        softmax(scores.mask_fill(future, -1.0e30), 3).matmul(v)
    }

    /// CLIP's 77-token causal attention through the fused op: within 1e-4 of the masked,
    /// materialised scores on every backend, and the first token sees only itself.
    /// Slow on purpose (about 30-40 s): on wgpu, lavapipe JIT-compiles the causal kernel, and
    /// this is its only check on wgpu; ndarray and flex take under 0.02 s.
    #[test]
    fn fused_causal_attention_matches_the_masked_scores() {
        for kind in gb_core::test_backends() {
            let device = kind.device();
            let rnd =
                || Tensor::<4>::random([2, 3, 77, 16], Distribution::Normal(0.0, 2.0), &device);
            let (q, k, v) = (rnd(), rnd(), rnd());
            let causal = AttentionModuleOptions {
                is_causal: true,
                ..Default::default()
            };
            let fused = attention(q.clone(), k.clone(), v.clone(), None, None, causal);
            let reference = materialised_causal(q, k, v.clone());
            let worst = (fused.clone() - reference).abs().max().into_scalar::<f32>();
            assert!(worst <= 1e-4, "{kind}: max difference {worst}");
            let first = (fused.narrow(2, 0, 1) - v.narrow(2, 0, 1)).abs().max();
            assert!(first.into_scalar::<f32>() <= 1e-5, "{kind}");
        }
    }
}
