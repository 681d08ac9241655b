//! diffusers' `UNet2DConditionModel` (SD 1.x / 2.x, including the 9-channel inpainting
//! variant).

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::nn::GroupNorm;
use burn::tensor::activation::silu;
use burn::tensor::{DType, Device, Tensor};

use super::embeddings::{timestep_embedding, TimestepEmbedding};
use super::layers::{conv, group_norm};
use super::resnet::{ResnetBlock2D, ResnetSpec};
use super::transformer::{Transformer2DModel, TransformerSpec};
use super::unet_blocks::{DownBlock, Downsample2D, MidBlockCrossAttn, UpBlock, Upsample2D};
use crate::config::UNet2DConditionConfig;
use crate::precision::{compute_dtype, group_norm_f32, to_dtype};

/// The conditional U-Net: predicts noise (or v) from a noisy latent, a timestep and text
/// embeddings.
#[derive(Module, Debug)]
pub struct UNet2DConditionModel {
    /// Input convolution (`in_channels -> block_out_channels[0]`).
    pub conv_in: Conv2d,
    /// Timestep MLP.
    pub time_embedding: TimestepEmbedding,
    /// Down blocks.
    pub down_blocks: Vec<DownBlock>,
    /// Mid block.
    pub mid_block: MidBlockCrossAttn,
    /// Up blocks.
    pub up_blocks: Vec<UpBlock>,
    /// Output group norm.
    pub conv_norm_out: GroupNorm,
    /// Output convolution.
    pub conv_out: Conv2d,
    /// Width of the sinusoidal timestep embedding (`block_out_channels[0]`).
    #[module(skip)]
    pub time_proj_dim: usize,
    /// `flip_sin_to_cos` of the config.
    #[module(skip)]
    pub flip_sin_to_cos: bool,
    /// `freq_shift` of the config.
    #[module(skip)]
    pub freq_shift: f64,
    /// Input channels (9 for inpainting).
    #[module(skip)]
    pub in_channels: usize,
}

impl UNet2DConditionModel {
    /// A randomly initialised U-Net of the configured shape (the config must have passed
    /// [`UNet2DConditionConfig::validate`]).
    pub fn new(cfg: &UNet2DConditionConfig, device: &Device) -> Self {
        let boc = &cfg.block_out_channels;
        let n = boc.len();
        let temb = cfg.time_embed_dim();
        let groups = cfg.norm_num_groups;
        let eps = cfg.norm_eps;
        let resnet = |in_ch, out_ch| {
            ResnetBlock2D::new(
                ResnetSpec {
                    in_ch,
                    out_ch,
                    temb_ch: Some(temb),
                    groups,
                    eps,
                },
                device,
            )
        };
        let transformer = |channels, heads, layers| {
            Transformer2DModel::new(
                TransformerSpec {
                    channels,
                    heads,
                    context_dim: cfg.cross_attention_dim,
                    groups,
                    layers,
                    linear_projection: cfg.use_linear_projection,
                },
                device,
            )
        };

        let mut down_blocks = Vec::with_capacity(n);
        let mut out_ch = boc[0];
        for (i, kind) in cfg.down_block_types.iter().enumerate() {
            let in_ch = out_ch;
            out_ch = boc[i];
            let cross = kind == "CrossAttnDownBlock2D";
            let layers = cfg.transformer_layers_per_block.get(i);
            down_blocks.push(DownBlock {
                resnets: (0..cfg.layers_per_block)
                    .map(|j| resnet(if j == 0 { in_ch } else { out_ch }, out_ch))
                    .collect(),
                attentions: if cross {
                    (0..cfg.layers_per_block)
                        .map(|_| transformer(out_ch, cfg.heads(i), layers))
                        .collect()
                } else {
                    Vec::new()
                },
                downsamplers: if i + 1 < n {
                    vec![Downsample2D::new(out_ch, cfg.downsample_padding, device)]
                } else {
                    Vec::new()
                },
            });
        }

        let mid_ch = boc[n - 1];
        let mut mid_resnets = vec![resnet(mid_ch, mid_ch), resnet(mid_ch, mid_ch)];
        for r in &mut mid_resnets {
            r.output_scale_factor = cfg.mid_block_scale_factor;
        }
        let mid_block = MidBlockCrossAttn {
            resnets: mid_resnets,
            attentions: vec![transformer(
                mid_ch,
                cfg.heads(n - 1),
                cfg.transformer_layers_per_block.get(n - 1),
            )],
        };

        let mut up_blocks = Vec::with_capacity(n);
        let rev: Vec<usize> = boc.iter().rev().copied().collect();
        let mut out_ch = rev[0];
        for (i, kind) in cfg.up_block_types.iter().enumerate() {
            let prev_out = out_ch;
            out_ch = rev[i];
            let in_ch = rev[(i + 1).min(n - 1)];
            let down_index = n - 1 - i;
            let cross = kind == "CrossAttnUpBlock2D";
            let num_layers = cfg.layers_per_block + 1;
            let layers = cfg.transformer_layers_per_block.get(down_index);
            up_blocks.push(UpBlock {
                resnets: (0..num_layers)
                    .map(|j| {
                        let skip = if j == num_layers - 1 { in_ch } else { out_ch };
                        let res_in = if j == 0 { prev_out } else { out_ch };
                        resnet(res_in + skip, out_ch)
                    })
                    .collect(),
                attentions: if cross {
                    (0..num_layers)
                        .map(|_| transformer(out_ch, cfg.heads(down_index), layers))
                        .collect()
                } else {
                    Vec::new()
                },
                upsamplers: if i + 1 < n {
                    vec![Upsample2D::new(out_ch, device)]
                } else {
                    Vec::new()
                },
            });
        }

        Self {
            conv_in: conv(cfg.in_channels, boc[0], 3, device),
            time_embedding: TimestepEmbedding::new(boc[0], temb, device),
            down_blocks,
            mid_block,
            up_blocks,
            conv_norm_out: group_norm(groups, boc[0], eps, device),
            conv_out: conv(boc[0], cfg.out_channels, 3, device),
            time_proj_dim: boc[0],
            flip_sin_to_cos: cfg.flip_sin_to_cos,
            freq_shift: cfg.freq_shift,
            in_channels: cfg.in_channels,
        }
    }

    /// Predicts noise: `sample` `[b, in_channels, h, w]` (h and w divisible by
    /// `2^(levels-1)`), `timesteps` one per batch item (or one for all), text embeddings
    /// `[b, m, cross_attention_dim]`. Returns `[b, out_channels, h, w]` in f32; inside it
    /// computes in its weights' precision ([`crate::precision`]).
    pub fn forward(
        &self,
        sample: Tensor<4>,
        timesteps: &[f32],
        encoder_hidden_states: Tensor<3>,
    ) -> Tensor<4> {
        let batch = sample.dims()[0];
        let device = sample.device();
        let ts: Vec<f32> = if timesteps.len() == 1 {
            vec![timesteps[0]; batch]
        } else {
            timesteps.to_vec()
        };
        let t_emb = timestep_embedding(
            &ts,
            self.time_proj_dim,
            self.flip_sin_to_cos,
            self.freq_shift,
            &device,
        );
        let dtype = compute_dtype(&self.conv_in.weight);
        let emb = self.time_embedding.forward(to_dtype(t_emb, dtype));
        let ctx = to_dtype(encoder_hidden_states, dtype);

        let mut x = self.conv_in.forward(to_dtype(sample, dtype));
        let mut skips = vec![x.clone()];
        for block in &self.down_blocks {
            x = block.forward(x, Some(&emb), Some(&ctx), &mut skips);
        }
        x = self.mid_block.forward(x, &emb, &ctx);
        for block in &self.up_blocks {
            x = block.forward(x, Some(&emb), Some(&ctx), Some(&mut skips));
        }
        let out = self
            .conv_out
            .forward(silu(group_norm_f32(&self.conv_norm_out, x)));
        to_dtype(out, DType::F32)
    }
}
