//! U-Net (and VAE) resolution blocks: `CrossAttnDownBlock2D` / `DownBlock2D` /
//! `DownEncoderBlock2D`, `UNetMidBlock2DCrossAttn`, `CrossAttnUpBlock2D` / `UpBlock2D` /
//! `UpDecoderBlock2D`, and `Downsample2D` / `Upsample2D`.
//!
//! One struct covers the attention and plain variants of each kind: plain blocks have an
//! empty `attentions` list, which gives the same checkpoint keys as diffusers.

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::PaddingConfig2d;
use burn::tensor::{Device, Tensor};

use super::layers::conv;
use super::resnet::ResnetBlock2D;
use super::transformer::Transformer2DModel;

/// `downsamplers.0`: a stride-2 3x3 convolution.
#[derive(Module, Debug)]
pub struct Downsample2D {
    /// The convolution. With `padding = 0` (the VAE) the input is padded by one pixel on
    /// the bottom and right only, as diffusers does.
    pub conv: Conv2d,
}

impl Downsample2D {
    /// Randomly initialised down-sampler with diffusers' `padding` (1 for the U-Net, 0 for
    /// the VAE).
    pub fn new(channels: usize, padding: usize, device: &Device) -> Self {
        let pad = if padding == 0 {
            PaddingConfig2d::Explicit(0, 0, 1, 1)
        } else {
            PaddingConfig2d::Explicit(padding, padding, padding, padding)
        };
        Self {
            conv: Conv2dConfig::new([channels, channels], [3, 3])
                .with_stride([2, 2])
                .with_padding(pad)
                .init(device),
        }
    }

    /// `[b, c, h, w]` to `[b, c, h / 2, w / 2]`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        self.conv.forward(x)
    }
}

/// `upsamplers.0`: nearest-neighbour 2x up-sampling and a 3x3 convolution.
#[derive(Module, Debug)]
pub struct Upsample2D {
    /// The convolution after up-sampling.
    pub conv: Conv2d,
}

impl Upsample2D {
    /// Randomly initialised up-sampler.
    pub fn new(channels: usize, device: &Device) -> Self {
        Self {
            conv: conv(channels, channels, 3, device),
        }
    }

    /// `[b, c, h, w]` to `[b, c, 2h, 2w]`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        self.conv.forward(upsample_nearest_2x(x))
    }
}

/// Nearest-neighbour 2x up-sampling (each pixel repeated in a 2x2 square).
pub fn upsample_nearest_2x(x: Tensor<4>) -> Tensor<4> {
    let [b, c, h, w] = x.dims();
    x.reshape([b, c, h, 1, w, 1])
        .expand([b, c, h, 2, w, 2])
        .reshape([b, c, 2 * h, 2 * w])
}

/// A down block: ResNets (each followed by a transformer in the cross-attention variant),
/// then an optional down-sampler.
#[derive(Module, Debug)]
pub struct DownBlock {
    /// The ResNets.
    pub resnets: Vec<ResnetBlock2D>,
    /// One transformer per ResNet, or none.
    pub attentions: Vec<Transformer2DModel>,
    /// Zero or one down-sampler.
    pub downsamplers: Vec<Downsample2D>,
}

impl DownBlock {
    /// Runs the block; pushes every intermediate output (the U-Net skip connections) onto
    /// `skips` and returns the last.
    pub fn forward(
        &self,
        mut x: Tensor<4>,
        temb: Option<&Tensor<2>>,
        context: Option<&Tensor<3>>,
        skips: &mut Vec<Tensor<4>>,
    ) -> Tensor<4> {
        for (i, resnet) in self.resnets.iter().enumerate() {
            x = resnet.forward(x, temb);
            if let (Some(attn), Some(ctx)) = (self.attentions.get(i), context) {
                x = attn.forward(x, ctx);
            }
            skips.push(x.clone());
        }
        for down in &self.downsamplers {
            x = down.forward(x);
            skips.push(x.clone());
        }
        x
    }
}

/// An up block: ResNets on the input concatenated with a skip connection (each followed
/// by a transformer in the cross-attention variant), then an optional up-sampler.
#[derive(Module, Debug)]
pub struct UpBlock {
    /// The ResNets.
    pub resnets: Vec<ResnetBlock2D>,
    /// One transformer per ResNet, or none.
    pub attentions: Vec<Transformer2DModel>,
    /// Zero or one up-sampler.
    pub upsamplers: Vec<Upsample2D>,
}

impl UpBlock {
    /// Runs the block, popping one skip connection per ResNet (none when `skips` is `None`,
    /// as in the VAE decoder).
    pub fn forward(
        &self,
        mut x: Tensor<4>,
        temb: Option<&Tensor<2>>,
        context: Option<&Tensor<3>>,
        mut skips: Option<&mut Vec<Tensor<4>>>,
    ) -> Tensor<4> {
        for (i, resnet) in self.resnets.iter().enumerate() {
            if let Some(stack) = skips.as_deref_mut() {
                if let Some(skip) = stack.pop() {
                    x = Tensor::cat(vec![x, skip], 1);
                }
            }
            x = resnet.forward(x, temb);
            if let (Some(attn), Some(ctx)) = (self.attentions.get(i), context) {
                x = attn.forward(x, ctx);
            }
        }
        for up in &self.upsamplers {
            x = up.forward(x);
        }
        x
    }
}

/// `mid_block` of the U-Net (`UNetMidBlock2DCrossAttn`): `resnets[0]`, then pairs of
/// transformer and ResNet.
#[derive(Module, Debug)]
pub struct MidBlockCrossAttn {
    /// `len(attentions) + 1` ResNets.
    pub resnets: Vec<ResnetBlock2D>,
    /// The transformers.
    pub attentions: Vec<Transformer2DModel>,
}

impl MidBlockCrossAttn {
    /// Runs the block.
    pub fn forward(&self, x: Tensor<4>, temb: &Tensor<2>, context: &Tensor<3>) -> Tensor<4> {
        let mut x = self.resnets[0].forward(x, Some(temb));
        for (attn, resnet) in self.attentions.iter().zip(self.resnets.iter().skip(1)) {
            x = attn.forward(x, context);
            x = resnet.forward(x, Some(temb));
        }
        x
    }
}
