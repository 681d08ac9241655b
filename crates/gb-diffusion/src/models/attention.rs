//! diffusers' `Attention` (self- and cross-attention with `to_q`, `to_k`, `to_v`,
//! `to_out.0`) and the scaled dot-product it uses: Burn's fused attention, in f32.

use burn::module::Module;
use burn::nn::Linear;
use burn::tensor::module::attention;
use burn::tensor::ops::AttentionModuleOptions;
use burn::tensor::{DType, Device, Tensor};

use super::layers::linear;

/// Multi-head scaled dot-product attention: `q` `[b, n, heads * d]`, `k`/`v` `[b, m, heads * d]`
/// to `[b, n, heads * d]`, through Burn's fused attention op
/// ([`burn::tensor::module::attention`]): a flash kernel chosen by autotune on the cubecl
/// devices, a tiled online-softmax kernel on flex for long sequences, the materialised
/// scores elsewhere and under autodiff. Computed in f32; the scale is `1 / sqrt(d)`.
pub fn scaled_dot_product(q: Tensor<3>, k: Tensor<3>, v: Tensor<3>, heads: usize) -> Tensor<3> {
    let [b, n, inner] = q.dims();
    let m = k.dims()[1];
    let d = inner / heads;
    let dtype = q.dtype();
    let split = |t: Tensor<3>, len: usize| {
        t.reshape([b, len, heads, d])
            .swap_dims(1, 2)
            .cast(DType::F32)
    };
    let out = attention(
        split(q, n),
        split(k, m),
        split(v, m),
        None,
        None,
        AttentionModuleOptions::default(),
    );
    out.swap_dims(1, 2).reshape([b, n, inner]).cast(dtype)
}

/// `attn1` / `attn2` of a transformer block: projections without bias, `to_out.0` with bias.
#[derive(Module, Debug)]
pub struct Attention {
    /// Query projection.
    pub to_q: Linear,
    /// Key projection (from the context width).
    pub to_k: Linear,
    /// Value projection (from the context width).
    pub to_v: Linear,
    /// `to_out.0`: output projection (`to_out.1` is dropout and has no weights).
    pub to_out: Vec<Linear>,
    /// Number of heads.
    #[module(skip)]
    pub heads: usize,
}

impl Attention {
    /// Randomly initialised attention; `context_dim` is `None` for self-attention.
    pub fn new(
        query_dim: usize,
        context_dim: Option<usize>,
        heads: usize,
        head_dim: usize,
        device: &Device,
    ) -> Self {
        let inner = heads * head_dim;
        let ctx = context_dim.unwrap_or(query_dim);
        Self {
            to_q: linear(query_dim, inner, false, device),
            to_k: linear(ctx, inner, false, device),
            to_v: linear(ctx, inner, false, device),
            to_out: vec![linear(inner, query_dim, true, device)],
            heads,
        }
    }

    /// `x` `[b, n, query_dim]` attends to `context` `[b, m, ctx]` (or to itself).
    pub fn forward(&self, x: Tensor<3>, context: Option<Tensor<3>>) -> Tensor<3> {
        let ctx = context.unwrap_or_else(|| x.clone());
        let q = self.to_q.forward(x);
        let k = self.to_k.forward(ctx.clone());
        let v = self.to_v.forward(ctx);
        let out = scaled_dot_product(q, k, v, self.heads);
        self.to_out[0].forward(out)
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::activation::softmax;
    use burn::tensor::Distribution;

    use super::*;

    /// The scores materialised: `softmax(q k^T / sqrt(d)) v` per head (the form the fused op
    /// replaced).
    fn materialised(q: Tensor<3>, k: Tensor<3>, v: Tensor<3>, heads: usize) -> Tensor<3> {
        let [b, n, inner] = q.dims();
        let m = k.dims()[1];
        let d = inner / heads;
        let split = |t: Tensor<3>, len: usize| t.reshape([b, len, heads, d]).swap_dims(1, 2);
        let scores = split(q, n)
            .matmul(split(k, m).swap_dims(2, 3))
            .mul_scalar((d as f64).powf(-0.5));
        softmax(scores, 3)
            .matmul(split(v, m))
            .swap_dims(1, 2)
            .reshape([b, n, inner])
    }

    /// Self-attention over a 32x32 latent (long enough for flex's tiled kernel) and
    /// cross-attention over 77 tokens, on every backend: within 1e-4 of the materialised form.
    /// Slow on purpose (about 40 s): on wgpu, lavapipe JIT-compiles the fused kernels, and this
    /// is the fused self-attention's only check on wgpu; ndarray and flex take under 0.2 s.
    #[test]
    fn fused_attention_matches_the_materialised_scores() {
        for kind in gb_core::test_backends() {
            let device = kind.device();
            for (n, m, heads, d) in [(1024usize, 1024usize, 2usize, 16usize), (256, 77, 4, 8)] {
                let rnd = |len: usize, scale: f64| {
                    Tensor::<3>::random(
                        [2, len, heads * d],
                        Distribution::Normal(0.0, scale),
                        &device,
                    )
                };
                let (q, k, v) = (rnd(n, 2.0), rnd(m, 2.0), rnd(m, 1.0));
                let fused = scaled_dot_product(q.clone(), k.clone(), v.clone(), heads);
                let reference = materialised(q, k, v, heads);
                assert_eq!(fused.dims(), [2, n, heads * d]);
                let worst = (fused - reference).abs().max().into_scalar::<f32>();
                assert!(worst <= 1e-4, "{kind} n={n} m={m}: max difference {worst}");
            }
        }
    }
}
