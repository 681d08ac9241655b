//! `CLIPTextModel` configuration (transformers' `CLIPTextConfig`).

use serde::{Deserialize, Serialize};

/// The MLP activation of the CLIP text encoder (`hidden_act`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum ClipActivation {
    /// `x * sigmoid(1.702 x)`, used by OpenAI CLIP (SD 1.x).
    #[default]
    #[serde(rename = "quick_gelu")]
    QuickGelu,
    /// Exact (erf) GELU, used by OpenCLIP (SD 2.x).
    #[serde(rename = "gelu")]
    Gelu,
}

/// Mirror of transformers' `CLIPTextConfig` (the fields that shape the network).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ClipTextConfig {
    /// Vocabulary size (49408 for CLIP).
    pub vocab_size: usize,
    /// Width of the residual stream.
    pub hidden_size: usize,
    /// Width of the MLP.
    pub intermediate_size: usize,
    /// Number of transformer layers.
    pub num_hidden_layers: usize,
    /// Number of attention heads.
    pub num_attention_heads: usize,
    /// Number of learned positions (77).
    pub max_position_embeddings: usize,
    /// MLP activation.
    pub hidden_act: ClipActivation,
    /// LayerNorm epsilon.
    pub layer_norm_eps: f64,
    /// Padding token id.
    pub pad_token_id: i64,
    /// Beginning-of-sequence token id.
    pub bos_token_id: i64,
    /// End-of-sequence token id (the pooled output is taken there).
    pub eos_token_id: i64,
    /// Width of the text projection (not used by `CLIPTextModel`).
    pub projection_dim: usize,
}

impl Default for ClipTextConfig {
    /// transformers' defaults (`CLIPTextConfig()`).
    fn default() -> Self {
        Self {
            vocab_size: 49408,
            hidden_size: 512,
            intermediate_size: 2048,
            num_hidden_layers: 12,
            num_attention_heads: 8,
            max_position_embeddings: 77,
            hidden_act: ClipActivation::QuickGelu,
            layer_norm_eps: 1e-5,
            pad_token_id: 1,
            bos_token_id: 49406,
            eos_token_id: 49407,
            projection_dim: 512,
        }
    }
}

impl ClipTextConfig {
    /// Width of one attention head.
    pub fn head_dim(&self) -> usize {
        self.hidden_size / self.num_attention_heads
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_sd15_text_encoder_config() {
        let json = r#"{"architectures":["CLIPTextModel"],"attention_dropout":0.0,
            "bos_token_id":0,"dropout":0.0,"eos_token_id":2,"hidden_act":"quick_gelu",
            "hidden_size":768,"initializer_factor":1.0,"intermediate_size":3072,
            "layer_norm_eps":1e-05,"max_position_embeddings":77,"model_type":"clip_text_model",
            "num_attention_heads":12,"num_hidden_layers":12,"pad_token_id":1,
            "projection_dim":768,"torch_dtype":"float32","vocab_size":49408}"#;
        let c: ClipTextConfig = serde_json::from_str(json).unwrap();
        assert_eq!(c.hidden_size, 768);
        assert_eq!(c.head_dim(), 64);
        assert_eq!(c.hidden_act, ClipActivation::QuickGelu);
        assert_eq!(c.eos_token_id, 2);
    }

    #[test]
    fn parses_gelu_and_fills_defaults() {
        let c: ClipTextConfig = serde_json::from_str(r#"{"hidden_act":"gelu"}"#).unwrap();
        assert_eq!(c.hidden_act, ClipActivation::Gelu);
        assert_eq!(c.max_position_embeddings, 77);
        assert_eq!(c.vocab_size, 49408);
    }

    #[test]
    fn rejects_unknown_activation() {
        let r: Result<ClipTextConfig, _> = serde_json::from_str(r#"{"hidden_act":"relu"}"#);
        assert!(r.is_err());
    }
}
