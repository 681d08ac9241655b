//! diffusers' `Transformer2DModel` (continuous input) with `BasicTransformerBlock`s:
//! self-attention, cross-attention and a GEGLU feed-forward, each after a layer norm.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::nn::{GroupNorm, LayerNorm, LayerNormConfig, Linear};
use burn::tensor::activation::gelu;
use burn::tensor::{Device, Tensor};

use super::attention::Attention;
use super::layers::{conv, from_tokens, group_norm, linear, to_tokens};
use crate::precision::{group_norm_f32, layer_norm_f32};

/// `ff.net.0`: `proj` to twice the inner width, then `hidden * gelu(gate)`.
#[derive(Module, Debug)]
pub struct GeGlu {
    /// Projection to `2 * inner`.
    pub proj: Linear,
}

impl GeGlu {
    /// `[b, n, dim]` to `[b, n, inner]`.
    pub fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        let h = self.proj.forward(x);
        let inner = h.dims()[2] / 2;
        let hidden = h.clone().narrow(2, 0, inner);
        let gate = h.narrow(2, inner, inner);
        hidden * gelu(gate)
    }
}

/// `ff`: checkpoint keys `ff.net.0.proj` and `ff.net.2` (remapped to `net_0`, `net_2`).
#[derive(Module, Debug)]
pub struct FeedForward {
    /// `ff.net.0`: the GEGLU.
    pub net_0: GeGlu,
    /// `ff.net.2`: projection back to the model width (`net.1` is dropout).
    pub net_2: Linear,
}

/// `transformer_blocks.N`: `x += attn1(norm1(x)); x += attn2(norm2(x), ctx); x += ff(norm3(x))`.
#[derive(Module, Debug)]
pub struct BasicTransformerBlock {
    /// Norm before self-attention.
    pub norm1: LayerNorm,
    /// Self-attention.
    pub attn1: Attention,
    /// Norm before cross-attention.
    pub norm2: LayerNorm,
    /// Cross-attention on the text embeddings.
    pub attn2: Attention,
    /// Norm before the feed-forward.
    pub norm3: LayerNorm,
    /// GEGLU feed-forward.
    pub ff: FeedForward,
}

impl BasicTransformerBlock {
    /// Randomly initialised block of width `dim`.
    pub fn new(dim: usize, heads: usize, context_dim: usize, device: &Device) -> Self {
        let head_dim = dim / heads;
        let ln = || LayerNormConfig::new(dim).with_epsilon(1e-5).init(device);
        let inner = dim * 4;
        Self {
            norm1: ln(),
            attn1: Attention::new(dim, None, heads, head_dim, device),
            norm2: ln(),
            attn2: Attention::new(dim, Some(context_dim), heads, head_dim, device),
            norm3: ln(),
            ff: FeedForward {
                net_0: GeGlu {
                    proj: linear(dim, inner * 2, true, device),
                },
                net_2: linear(inner, dim, true, device),
            },
        }
    }

    /// `[b, n, dim]` with context `[b, m, context_dim]`.
    pub fn forward(&self, x: Tensor<3>, context: &Tensor<3>) -> Tensor<3> {
        let x = self
            .attn1
            .forward(layer_norm_f32(&self.norm1, x.clone()), None)
            + x;
        let x = self.attn2.forward(
            layer_norm_f32(&self.norm2, x.clone()),
            Some(context.clone()),
        ) + x;
        let h = self
            .ff
            .net_0
            .forward(layer_norm_f32(&self.norm3, x.clone()));
        self.ff.net_2.forward(h) + x
    }
}

/// `attentions.N` of a U-Net block: group norm, `proj_in`, transformer blocks, `proj_out`,
/// plus the input. SD 1.x uses 1x1 convolutions for the projections, SD 2.x
/// (`use_linear_projection`) linear layers, stored as `proj_in_linear`/`proj_out_linear`
/// (see [`crate::checkpoint::keymap::UNET_LINEAR_PROJECTION`]).
#[derive(Module, Debug)]
pub struct Transformer2DModel {
    /// Group norm (eps 1e-6).
    pub norm: GroupNorm,
    /// SD 1.x input projection (1x1 convolution).
    pub proj_in: Option<Conv2d>,
    /// SD 2.x input projection (linear).
    pub proj_in_linear: Option<Linear>,
    /// The transformer blocks.
    pub transformer_blocks: Vec<BasicTransformerBlock>,
    /// SD 1.x output projection (1x1 convolution).
    pub proj_out: Option<Conv2d>,
    /// SD 2.x output projection (linear).
    pub proj_out_linear: Option<Linear>,
}

/// Shape of one [`Transformer2DModel`].
#[derive(Debug, Clone, Copy)]
pub struct TransformerSpec {
    /// Channels in and out.
    pub channels: usize,
    /// Attention heads.
    pub heads: usize,
    /// Width of the text embeddings.
    pub context_dim: usize,
    /// Group-norm groups.
    pub groups: usize,
    /// Number of transformer blocks.
    pub layers: usize,
    /// Linear (SD 2.x) instead of 1x1-convolution projections.
    pub linear_projection: bool,
}

impl Transformer2DModel {
    /// Randomly initialised model.
    pub fn new(s: TransformerSpec, device: &Device) -> Self {
        let c = s.channels;
        let (proj_in, proj_in_linear, proj_out, proj_out_linear) = if s.linear_projection {
            (
                None,
                Some(linear(c, c, true, device)),
                None,
                Some(linear(c, c, true, device)),
            )
        } else {
            (
                Some(conv(c, c, 1, device)),
                None,
                Some(conv(c, c, 1, device)),
                None,
            )
        };
        Self {
            norm: group_norm(s.groups, c, 1e-6, device),
            proj_in,
            proj_in_linear,
            transformer_blocks: (0..s.layers)
                .map(|_| BasicTransformerBlock::new(c, s.heads, s.context_dim, device))
                .collect(),
            proj_out,
            proj_out_linear,
        }
    }

    /// `[b, c, h, w]` with context `[b, m, context_dim]` to `[b, c, h, w]`.
    pub fn forward(&self, x: Tensor<4>, context: &Tensor<3>) -> Tensor<4> {
        let [_, _, h, w] = x.dims();
        let residual = x.clone();
        let x = group_norm_f32(&self.norm, x);
        let mut t = match (&self.proj_in, &self.proj_in_linear) {
            (Some(c), _) => to_tokens(c.forward(x)),
            (None, Some(l)) => l.forward(to_tokens(x)),
            (None, None) => to_tokens(x),
        };
        for block in &self.transformer_blocks {
            t = block.forward(t, context);
        }
        let out = match (&self.proj_out, &self.proj_out_linear) {
            (Some(c), _) => c.forward(from_tokens(t, h, w)),
            (None, Some(l)) => from_tokens(l.forward(t), h, w),
            (None, None) => from_tokens(t, h, w),
        };
        out + residual
    }
}
