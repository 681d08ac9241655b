//! `unet/config.json`: diffusers' `UNet2DConditionModel` configuration.

use serde::{Deserialize, Serialize};

use super::ConfigError;

/// A config value that diffusers accepts either as one integer or as one per block.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum PerBlock {
    /// The same value for every block.
    One(usize),
    /// One value per down block (up blocks use the list reversed).
    Each(Vec<usize>),
}

impl PerBlock {
    /// The value for down block `i` of `n`.
    pub fn get(&self, i: usize) -> usize {
        match self {
            PerBlock::One(v) => *v,
            PerBlock::Each(list) => list[i.min(list.len().saturating_sub(1))],
        }
    }

    fn len_ok(&self, n: usize) -> bool {
        match self {
            PerBlock::One(_) => true,
            PerBlock::Each(list) => list.len() == n,
        }
    }
}

/// The fields of diffusers' `UNet2DConditionModel` `config.json` that SD 1.x/2.x use.
///
/// Note `attention_head_dim`: for SD 1.x/2.x configs it is the *number of heads* of each
/// transformer (a historical misnomer in diffusers), unless `num_attention_heads` is set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UNet2DConditionConfig {
    /// Input channels: 4 for text-to-image, 9 for inpainting (latent + mask + masked latent).
    #[serde(default = "d_four")]
    pub in_channels: usize,
    /// Output channels (the predicted noise / v).
    #[serde(default = "d_four")]
    pub out_channels: usize,
    /// Latent resolution the model was trained at.
    #[serde(default)]
    pub sample_size: Option<usize>,
    /// Order of the sinusoidal timestep embedding: `cos, sin` when true.
    #[serde(default = "d_true")]
    pub flip_sin_to_cos: bool,
    /// `downscale_freq_shift` of the sinusoidal timestep embedding.
    #[serde(default)]
    pub freq_shift: f64,
    /// Down block kinds: `CrossAttnDownBlock2D` or `DownBlock2D`.
    pub down_block_types: Vec<String>,
    /// Mid block kind: `UNetMidBlock2DCrossAttn`.
    #[serde(default = "d_mid")]
    pub mid_block_type: Option<String>,
    /// Up block kinds: `CrossAttnUpBlock2D` or `UpBlock2D`.
    pub up_block_types: Vec<String>,
    /// Output channels of each resolution level.
    pub block_out_channels: Vec<usize>,
    /// ResNet layers per down block (up blocks have one more).
    #[serde(default = "d_two")]
    pub layers_per_block: usize,
    /// Padding of the down-sampling convolutions.
    #[serde(default = "d_one")]
    pub downsample_padding: usize,
    /// Output scale of the mid block's ResNets.
    #[serde(default = "d_one_f")]
    pub mid_block_scale_factor: f64,
    /// Activation (`silu`).
    #[serde(default = "d_silu")]
    pub act_fn: String,
    /// Groups of every group norm.
    #[serde(default = "d_32")]
    pub norm_num_groups: usize,
    /// Epsilon of the ResNet group norms and the output norm.
    #[serde(default = "d_eps")]
    pub norm_eps: f64,
    /// Width of the text embeddings the cross-attention reads.
    #[serde(default = "d_1280")]
    pub cross_attention_dim: usize,
    /// Heads per transformer for SD 1.x/2.x configs (see the struct documentation).
    #[serde(default = "d_heads")]
    pub attention_head_dim: PerBlock,
    /// Heads per transformer when set explicitly (newer configs).
    #[serde(default)]
    pub num_attention_heads: Option<PerBlock>,
    /// Transformer layers per attention block.
    #[serde(default = "d_tlpb")]
    pub transformer_layers_per_block: PerBlock,
    /// SD 2.x: `proj_in`/`proj_out` are linear layers instead of 1x1 convolutions.
    #[serde(default)]
    pub use_linear_projection: bool,
    /// SD 2.1: compute attention in f32 (always the case here).
    #[serde(default)]
    pub upcast_attention: bool,
    /// Unsupported when true.
    #[serde(default)]
    pub only_cross_attention: bool,
    /// Unsupported when true.
    #[serde(default)]
    pub dual_cross_attention: bool,
    /// Only `default` is supported.
    #[serde(default = "d_default")]
    pub resnet_time_scale_shift: String,
    /// Only `null` (no class embedding) is supported.
    #[serde(default)]
    pub class_embed_type: Option<String>,
    /// Only `null` is supported.
    #[serde(default)]
    pub addition_embed_type: Option<String>,
    /// Only `positional` is supported.
    #[serde(default = "d_positional")]
    pub time_embedding_type: String,
    /// Kernel of `conv_in` (3).
    #[serde(default = "d_three")]
    pub conv_in_kernel: usize,
    /// Kernel of `conv_out` (3).
    #[serde(default = "d_three")]
    pub conv_out_kernel: usize,
}

fn d_four() -> usize {
    4
}
fn d_true() -> bool {
    true
}
fn d_mid() -> Option<String> {
    Some("UNetMidBlock2DCrossAttn".into())
}
fn d_two() -> usize {
    2
}
fn d_one() -> usize {
    1
}
fn d_three() -> usize {
    3
}
fn d_one_f() -> f64 {
    1.0
}
fn d_silu() -> String {
    "silu".into()
}
fn d_32() -> usize {
    32
}
fn d_eps() -> f64 {
    1e-5
}
fn d_1280() -> usize {
    1280
}
fn d_heads() -> PerBlock {
    PerBlock::One(8)
}
fn d_tlpb() -> PerBlock {
    PerBlock::One(1)
}
fn d_default() -> String {
    "default".into()
}
fn d_positional() -> String {
    "positional".into()
}

impl UNet2DConditionConfig {
    /// The square image resolution the model was trained at: its latent `sample_size`
    /// (64, SD 1.5's, when the config does not say) times the VAE's spatial factor.
    pub fn native_resolution(&self, vae_factor: usize) -> usize {
        self.sample_size.unwrap_or(64) * vae_factor
    }

    /// Reads `config.json` and checks that this implementation supports it.
    pub fn from_file(path: &std::path::Path) -> Result<Self, ConfigError> {
        let cfg: Self = super::read_json_config(path)?;
        cfg.validate(path)?;
        Ok(cfg)
    }

    /// Heads of the transformers in down block `i` (and of the mid block for the last `i`).
    pub fn heads(&self, i: usize) -> usize {
        self.num_attention_heads
            .as_ref()
            .unwrap_or(&self.attention_head_dim)
            .get(i)
    }

    /// Whether this is an inpainting U-Net for latents of `latent_channels`: its input is the
    /// noisy latent, the mask and the masked-image latent (`2 * latent_channels + 1`, 9 for
    /// Stable Diffusion's 4) and it predicts `latent_channels`.
    pub fn is_inpainting_for(&self, latent_channels: usize) -> bool {
        self.in_channels == 2 * latent_channels + 1 && self.out_channels == latent_channels
    }

    /// Width of the time embedding (`4 * block_out_channels[0]`).
    pub fn time_embed_dim(&self) -> usize {
        self.block_out_channels[0] * 4
    }

    /// Checks every field this implementation relies on; the error names the field.
    pub fn validate(&self, path: &std::path::Path) -> Result<(), ConfigError> {
        let bad = |field: &str, value: String| {
            Err(ConfigError::Unsupported {
                path: path.to_path_buf(),
                field: field.into(),
                value,
            })
        };
        let n = self.block_out_channels.len();
        if n == 0 {
            return bad("block_out_channels", "[]".into());
        }
        if self.down_block_types.len() != n {
            return bad(
                "down_block_types",
                format!("{:?} (need {n})", self.down_block_types),
            );
        }
        if self.up_block_types.len() != n {
            return bad(
                "up_block_types",
                format!("{:?} (need {n})", self.up_block_types),
            );
        }
        for t in &self.down_block_types {
            if t != "CrossAttnDownBlock2D" && t != "DownBlock2D" {
                return bad("down_block_types", t.clone());
            }
        }
        for t in &self.up_block_types {
            if t != "CrossAttnUpBlock2D" && t != "UpBlock2D" {
                return bad("up_block_types", t.clone());
            }
        }
        if self.mid_block_type.as_deref() != Some("UNetMidBlock2DCrossAttn") {
            return bad("mid_block_type", format!("{:?}", self.mid_block_type));
        }
        if !self.attention_head_dim.len_ok(n) {
            return bad(
                "attention_head_dim",
                format!("{:?}", self.attention_head_dim),
            );
        }
        if let Some(h) = &self.num_attention_heads {
            if !h.len_ok(n) {
                return bad("num_attention_heads", format!("{h:?}"));
            }
        }
        if !self.transformer_layers_per_block.len_ok(n) {
            return bad(
                "transformer_layers_per_block",
                format!("{:?}", self.transformer_layers_per_block),
            );
        }
        for (i, &c) in self.block_out_channels.iter().enumerate() {
            if c == 0 || c % self.norm_num_groups != 0 {
                return bad(
                    "block_out_channels",
                    format!("{c} (not a multiple of norm_num_groups)"),
                );
            }
            let h = self.heads(i);
            if h == 0 || c % h != 0 {
                return bad("attention_head_dim", format!("{h} heads for {c} channels"));
            }
        }
        if self.act_fn != "silu" {
            return bad("act_fn", self.act_fn.clone());
        }
        if self.only_cross_attention {
            return bad("only_cross_attention", "true".into());
        }
        if self.dual_cross_attention {
            return bad("dual_cross_attention", "true".into());
        }
        if self.resnet_time_scale_shift != "default" {
            return bad(
                "resnet_time_scale_shift",
                self.resnet_time_scale_shift.clone(),
            );
        }
        if let Some(c) = &self.class_embed_type {
            return bad("class_embed_type", c.clone());
        }
        if let Some(c) = &self.addition_embed_type {
            return bad("addition_embed_type", c.clone());
        }
        if self.time_embedding_type != "positional" {
            return bad("time_embedding_type", self.time_embedding_type.clone());
        }
        if self.conv_in_kernel != 3 {
            return bad("conv_in_kernel", self.conv_in_kernel.to_string());
        }
        if self.conv_out_kernel != 3 {
            return bad("conv_out_kernel", self.conv_out_kernel.to_string());
        }
        Ok(())
    }
}
