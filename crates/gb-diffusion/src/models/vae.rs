//! diffusers' `AutoencoderKL`: `Encoder`, `Decoder`, the mid-block self-attention, and the
//! diagonal-Gaussian latent (of which the encoder half returns the mean).
//!
//! The encoder has no frozen-only code: it runs under autodiff, so that score distillation
//! can backpropagate a latent gradient into the image.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::nn::{GroupNorm, Linear};
use burn::tensor::activation::silu;
use burn::tensor::{DType, Device, Tensor};

use super::attention::scaled_dot_product;
use super::layers::{conv, from_tokens, group_norm, linear, to_tokens};
use super::resnet::{ResnetBlock2D, ResnetSpec};
use super::unet_blocks::{DownBlock, Downsample2D, UpBlock, Upsample2D};
use crate::config::AutoencoderKLConfig;
use crate::precision::{compute_dtype, group_norm_f32, to_dtype};

/// Group-norm epsilon everywhere in the VAE.
const VAE_EPS: f64 = 1e-6;

/// `mid_block.attentions.0`: single-head self-attention over pixels with its own group norm
/// and a residual connection. Checkpoint keys `to_q/to_k/to_v/to_out.0` (the old
/// `query/key/value/proj_attn` are remapped in [`crate::checkpoint::keymap::VAE`]).
#[derive(Module, Debug)]
pub struct VaeAttention {
    /// Group norm before the projections.
    pub group_norm: GroupNorm,
    /// Query projection.
    pub to_q: Linear,
    /// Key projection.
    pub to_k: Linear,
    /// Value projection.
    pub to_v: Linear,
    /// `to_out.0`: output projection.
    pub to_out: Vec<Linear>,
}

impl VaeAttention {
    /// Randomly initialised attention over `channels`.
    pub fn new(channels: usize, groups: usize, device: &Device) -> Self {
        Self {
            group_norm: group_norm(groups, channels, VAE_EPS, device),
            to_q: linear(channels, channels, true, device),
            to_k: linear(channels, channels, true, device),
            to_v: linear(channels, channels, true, device),
            to_out: vec![linear(channels, channels, true, device)],
        }
    }

    /// `[b, c, h, w]` to `[b, c, h, w]`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let [_, _, h, w] = x.dims();
        let t = to_tokens(group_norm_f32(&self.group_norm, x.clone()));
        let q = self.to_q.forward(t.clone());
        let k = self.to_k.forward(t.clone());
        let v = self.to_v.forward(t);
        let out = self.to_out[0].forward(scaled_dot_product(q, k, v, 1));
        from_tokens(out, h, w) + x
    }
}

/// `mid_block` of the encoder and decoder (`UNetMidBlock2D`): ResNet, attention, ResNet.
#[derive(Module, Debug)]
pub struct VaeMidBlock {
    /// Two ResNets.
    pub resnets: Vec<ResnetBlock2D>,
    /// Zero (`mid_block_add_attention = false`) or one attention.
    pub attentions: Vec<VaeAttention>,
}

impl VaeMidBlock {
    fn new(channels: usize, groups: usize, attention: bool, device: &Device) -> Self {
        let spec = ResnetSpec {
            in_ch: channels,
            out_ch: channels,
            temb_ch: None,
            groups,
            eps: VAE_EPS,
        };
        Self {
            resnets: vec![
                ResnetBlock2D::new(spec, device),
                ResnetBlock2D::new(spec, device),
            ],
            attentions: if attention {
                vec![VaeAttention::new(channels, groups, device)]
            } else {
                Vec::new()
            },
        }
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let mut x = self.resnets[0].forward(x, None);
        if let Some(attn) = self.attentions.first() {
            x = attn.forward(x);
        }
        self.resnets[1].forward(x, None)
    }
}

fn vae_resnet(in_ch: usize, out_ch: usize, groups: usize, device: &Device) -> ResnetBlock2D {
    ResnetBlock2D::new(
        ResnetSpec {
            in_ch,
            out_ch,
            temb_ch: None,
            groups,
            eps: VAE_EPS,
        },
        device,
    )
}

/// `encoder`: image to `2 * latent_channels` moments (before `quant_conv`).
#[derive(Module, Debug)]
pub struct Encoder {
    /// Input convolution.
    pub conv_in: Conv2d,
    /// `DownEncoderBlock2D`s.
    pub down_blocks: Vec<DownBlock>,
    /// Mid block.
    pub mid_block: VaeMidBlock,
    /// Output group norm.
    pub conv_norm_out: GroupNorm,
    /// Output convolution.
    pub conv_out: Conv2d,
}

impl Encoder {
    fn new(cfg: &AutoencoderKLConfig, device: &Device) -> Self {
        let boc = &cfg.block_out_channels;
        let n = boc.len();
        let g = cfg.norm_num_groups;
        let mut out_ch = boc[0];
        let down_blocks = (0..n)
            .map(|i| {
                let in_ch = out_ch;
                out_ch = boc[i];
                DownBlock {
                    resnets: (0..cfg.layers_per_block)
                        .map(|j| vae_resnet(if j == 0 { in_ch } else { out_ch }, out_ch, g, device))
                        .collect(),
                    attentions: Vec::new(),
                    downsamplers: if i + 1 < n {
                        vec![Downsample2D::new(out_ch, 0, device)]
                    } else {
                        Vec::new()
                    },
                }
            })
            .collect();
        Self {
            conv_in: conv(cfg.in_channels, boc[0], 3, device),
            down_blocks,
            mid_block: VaeMidBlock::new(boc[n - 1], g, cfg.mid_block_add_attention, device),
            conv_norm_out: group_norm(g, boc[n - 1], VAE_EPS, device),
            conv_out: conv(boc[n - 1], 2 * cfg.latent_channels, 3, device),
        }
    }

    /// `[b, in_channels, h, w]` to `[b, 2 * latent, h / f, w / f]`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let mut x = self.conv_in.forward(x);
        let mut unused = Vec::new();
        for block in &self.down_blocks {
            x = block.forward(x, None, None, &mut unused);
            unused.clear();
        }
        x = self.mid_block.forward(x);
        self.conv_out
            .forward(silu(group_norm_f32(&self.conv_norm_out, x)))
    }
}

/// `decoder`: latent to image.
#[derive(Module, Debug)]
pub struct Decoder {
    /// Input convolution.
    pub conv_in: Conv2d,
    /// Mid block.
    pub mid_block: VaeMidBlock,
    /// `UpDecoderBlock2D`s.
    pub up_blocks: Vec<UpBlock>,
    /// Output group norm.
    pub conv_norm_out: GroupNorm,
    /// Output convolution.
    pub conv_out: Conv2d,
}

impl Decoder {
    fn new(cfg: &AutoencoderKLConfig, device: &Device) -> Self {
        let rev: Vec<usize> = cfg.block_out_channels.iter().rev().copied().collect();
        let n = rev.len();
        let g = cfg.norm_num_groups;
        let mut out_ch = rev[0];
        let up_blocks = (0..n)
            .map(|i| {
                let prev = out_ch;
                out_ch = rev[i];
                UpBlock {
                    resnets: (0..cfg.layers_per_block + 1)
                        .map(|j| vae_resnet(if j == 0 { prev } else { out_ch }, out_ch, g, device))
                        .collect(),
                    attentions: Vec::new(),
                    upsamplers: if i + 1 < n {
                        vec![Upsample2D::new(out_ch, device)]
                    } else {
                        Vec::new()
                    },
                }
            })
            .collect();
        Self {
            conv_in: conv(cfg.latent_channels, rev[0], 3, device),
            mid_block: VaeMidBlock::new(rev[0], g, cfg.mid_block_add_attention, device),
            up_blocks,
            conv_norm_out: group_norm(g, rev[n - 1], VAE_EPS, device),
            conv_out: conv(rev[n - 1], cfg.out_channels, 3, device),
        }
    }

    /// `[b, latent, h, w]` to `[b, out_channels, h * f, w * f]`.
    pub fn forward(&self, z: Tensor<4>) -> Tensor<4> {
        let mut x = self.mid_block.forward(self.conv_in.forward(z));
        for block in &self.up_blocks {
            x = block.forward(x, None, None, None);
        }
        self.conv_out
            .forward(silu(group_norm_f32(&self.conv_norm_out, x)))
    }
}

/// The variational autoencoder between images in `[-1, 1]` and SD latents.
#[derive(Module, Debug)]
pub struct AutoencoderKL {
    /// Image encoder.
    pub encoder: Encoder,
    /// Latent decoder.
    pub decoder: Decoder,
    /// 1x1 convolution on the encoder moments.
    pub quant_conv: Option<Conv2d>,
    /// 1x1 convolution before the decoder.
    pub post_quant_conv: Option<Conv2d>,
    /// Latent channels.
    #[module(skip)]
    pub latent_channels: usize,
    /// `scaling_factor` of the config (latents the U-Net sees = mean * scaling_factor).
    #[module(skip)]
    pub scaling_factor: f64,
}

impl AutoencoderKL {
    /// A randomly initialised VAE of the configured shape.
    pub fn new(cfg: &AutoencoderKLConfig, device: &Device) -> Self {
        let l2 = 2 * cfg.latent_channels;
        Self {
            encoder: Encoder::new(cfg, device),
            decoder: Decoder::new(cfg, device),
            quant_conv: cfg.use_quant_conv.then(|| conv(l2, l2, 1, device)),
            post_quant_conv: cfg
                .use_post_quant_conv
                .then(|| conv(cfg.latent_channels, cfg.latent_channels, 1, device)),
            latent_channels: cfg.latent_channels,
            scaling_factor: cfg.scaling_factor,
        }
    }

    /// Mean and log-variance of the latent distribution, each `[b, latent, h / f, w / f]`,
    /// unscaled. Differentiable when the module and `image` live on an autodiff device.
    /// Computes in the weights' precision and returns f32 ([`crate::precision`]).
    pub fn encode_moments(&self, image: Tensor<4>) -> (Tensor<4>, Tensor<4>) {
        let dtype = compute_dtype(&self.encoder.conv_in.weight);
        let mut m = self.encoder.forward(to_dtype(image, dtype));
        if let Some(q) = &self.quant_conv {
            m = q.forward(m);
        }
        let m = to_dtype(m, DType::F32);
        let l = self.latent_channels;
        let mean = m.clone().narrow(1, 0, l);
        let logvar = m.narrow(1, l, l).clamp(-30.0, 20.0);
        (mean, logvar)
    }

    /// The mean of the latent distribution of `image` (in `[-1, 1]`), unscaled.
    pub fn encode_mean(&self, image: Tensor<4>) -> Tensor<4> {
        self.encode_moments(image).0
    }

    /// Decodes unscaled latents to an image in about `[-1, 1]`, in the weights' precision;
    /// returns f32.
    pub fn decode(&self, latents: Tensor<4>) -> Tensor<4> {
        let latents = to_dtype(latents, compute_dtype(&self.decoder.conv_in.weight));
        let z = match &self.post_quant_conv {
            Some(p) => p.forward(latents),
            None => latents,
        };
        to_dtype(self.decoder.forward(z), DType::F32)
    }
}
