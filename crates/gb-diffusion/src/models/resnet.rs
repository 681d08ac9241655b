//! diffusers' `ResnetBlock2D` (the `default` time-scale-shift variant).

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::nn::{GroupNorm, Linear};
use burn::tensor::activation::silu;
use burn::tensor::{Device, Tensor};

use super::layers::{conv, group_norm, linear};
use crate::precision::group_norm_f32;

/// `norm1 -> SiLU -> conv1 (+ time_emb_proj(SiLU(temb))) -> norm2 -> SiLU -> conv2`, plus the
/// input (through `conv_shortcut` when the channel count changes), divided by
/// `output_scale_factor`.
#[derive(Module, Debug)]
pub struct ResnetBlock2D {
    /// First group norm.
    pub norm1: GroupNorm,
    /// First 3x3 convolution.
    pub conv1: Conv2d,
    /// Projection of the time embedding (absent in the VAE).
    pub time_emb_proj: Option<Linear>,
    /// Second group norm.
    pub norm2: GroupNorm,
    /// Second 3x3 convolution.
    pub conv2: Conv2d,
    /// 1x1 convolution on the skip path when `in != out`.
    pub conv_shortcut: Option<Conv2d>,
    /// Divides the output (1 for SD).
    #[module(skip)]
    pub output_scale_factor: f64,
}

/// Shape of one [`ResnetBlock2D`].
#[derive(Debug, Clone, Copy)]
pub struct ResnetSpec {
    /// Input channels.
    pub in_ch: usize,
    /// Output channels.
    pub out_ch: usize,
    /// Width of the time embedding, or `None` (VAE).
    pub temb_ch: Option<usize>,
    /// Group-norm groups.
    pub groups: usize,
    /// Group-norm epsilon.
    pub eps: f64,
}

impl ResnetBlock2D {
    /// Randomly initialised block.
    pub fn new(s: ResnetSpec, device: &Device) -> Self {
        Self {
            norm1: group_norm(s.groups, s.in_ch, s.eps, device),
            conv1: conv(s.in_ch, s.out_ch, 3, device),
            time_emb_proj: s.temb_ch.map(|t| linear(t, s.out_ch, true, device)),
            norm2: group_norm(s.groups, s.out_ch, s.eps, device),
            conv2: conv(s.out_ch, s.out_ch, 3, device),
            conv_shortcut: (s.in_ch != s.out_ch).then(|| conv(s.in_ch, s.out_ch, 1, device)),
            output_scale_factor: 1.0,
        }
    }

    /// `[b, in, h, w]` (and `temb` `[b, temb_ch]`) to `[b, out, h, w]`.
    pub fn forward(&self, x: Tensor<4>, temb: Option<&Tensor<2>>) -> Tensor<4> {
        let mut h = self
            .conv1
            .forward(silu(group_norm_f32(&self.norm1, x.clone())));
        if let (Some(proj), Some(temb)) = (&self.time_emb_proj, temb) {
            let t = proj.forward(silu(temb.clone()));
            let [b, c] = t.dims();
            h = h + t.reshape([b, c, 1, 1]);
        }
        let h = self.conv2.forward(silu(group_norm_f32(&self.norm2, h)));
        let skip = match &self.conv_shortcut {
            Some(c) => c.forward(x),
            None => x,
        };
        let out = skip + h;
        if self.output_scale_factor == 1.0 {
            out
        } else {
            out.div_scalar(self.output_scale_factor)
        }
    }
}
