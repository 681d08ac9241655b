//! `vae/config.json`: diffusers' `AutoencoderKL` configuration.

use serde::{Deserialize, Serialize};

use super::ConfigError;

/// The fields of diffusers' `AutoencoderKL` `config.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AutoencoderKLConfig {
    /// Image channels in (3).
    #[serde(default = "d_three")]
    pub in_channels: usize,
    /// Image channels out (3).
    #[serde(default = "d_three")]
    pub out_channels: usize,
    /// Encoder blocks: `DownEncoderBlock2D`.
    pub down_block_types: Vec<String>,
    /// Decoder blocks: `UpDecoderBlock2D`.
    pub up_block_types: Vec<String>,
    /// Channels of each resolution level.
    pub block_out_channels: Vec<usize>,
    /// ResNets per encoder block (decoder blocks have one more).
    #[serde(default = "d_one")]
    pub layers_per_block: usize,
    /// Activation (`silu`).
    #[serde(default = "d_silu")]
    pub act_fn: String,
    /// Latent channels (4).
    #[serde(default = "d_four")]
    pub latent_channels: usize,
    /// Groups of every group norm.
    #[serde(default = "d_32")]
    pub norm_num_groups: usize,
    /// Image resolution the VAE was trained at.
    #[serde(default)]
    pub sample_size: Option<usize>,
    /// Latents are multiplied by this before the U-Net sees them (0.18215 for SD 1.x/2.x).
    #[serde(default = "d_scaling")]
    pub scaling_factor: f64,
    /// Whether the mid blocks have self-attention.
    #[serde(default = "d_true")]
    pub mid_block_add_attention: bool,
    /// Whether `quant_conv` exists.
    #[serde(default = "d_true")]
    pub use_quant_conv: bool,
    /// Whether `post_quant_conv` exists.
    #[serde(default = "d_true")]
    pub use_post_quant_conv: bool,
}

fn d_three() -> usize {
    3
}
fn d_one() -> usize {
    1
}
fn d_four() -> usize {
    4
}
fn d_32() -> usize {
    32
}
fn d_silu() -> String {
    "silu".into()
}
fn d_scaling() -> f64 {
    0.18215
}
fn d_true() -> bool {
    true
}

impl AutoencoderKLConfig {
    /// Reads `config.json` and checks that this implementation supports it.
    pub fn from_file(path: &std::path::Path) -> Result<Self, ConfigError> {
        let cfg: Self = super::read_json_config(path)?;
        cfg.validate(path)?;
        Ok(cfg)
    }

    /// The spatial down-sampling factor from image to latent (`2^(levels - 1)`).
    pub fn scale_factor(&self) -> usize {
        1 << (self.block_out_channels.len().saturating_sub(1))
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
        if self.down_block_types.len() != n
            || self
                .down_block_types
                .iter()
                .any(|t| t != "DownEncoderBlock2D")
        {
            return bad("down_block_types", format!("{:?}", self.down_block_types));
        }
        if self.up_block_types.len() != n
            || self.up_block_types.iter().any(|t| t != "UpDecoderBlock2D")
        {
            return bad("up_block_types", format!("{:?}", self.up_block_types));
        }
        if let Some(c) = self
            .block_out_channels
            .iter()
            .find(|&&c| c == 0 || c % self.norm_num_groups != 0)
        {
            return bad(
                "block_out_channels",
                format!("{c} (not a multiple of norm_num_groups)"),
            );
        }
        if self.act_fn != "silu" {
            return bad("act_fn", self.act_fn.clone());
        }
        Ok(())
    }
}
