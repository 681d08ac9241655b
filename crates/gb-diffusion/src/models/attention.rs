//! diffusers' `Attention` (self- and cross-attention with `to_q`, `to_k`, `to_v`,
//! `to_out.0`) and the scaled dot-product it uses, with the softmax in f32.

use burn::module::Module;
use burn::nn::Linear;
use burn::tensor::activation::softmax;
use burn::tensor::{DType, Device, Tensor};

use super::layers::linear;

/// Multi-head scaled dot-product attention: `q` `[b, n, heads * d]`, `k`/`v` `[b, m, heads * d]`
/// to `[b, n, heads * d]`. Scores and softmax are computed in f32.
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
    let q = split(q, n);
    let k = split(k, m);
    let v = split(v, m);
    let scores = q
        .matmul(k.swap_dims(2, 3))
        .mul_scalar((d as f64).powf(-0.5));
    let probs = softmax(scores, 3);
    probs
        .matmul(v)
        .swap_dims(1, 2)
        .reshape([b, n, inner])
        .cast(dtype)
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
