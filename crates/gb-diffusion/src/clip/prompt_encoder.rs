//! The one prompt encoder: CLIP tokenizer + text model, a prompt to its
//! `last_hidden_state` (`[1, 77, D]`), used by every user of a prior (the inpainting
//! pipeline, the distillation playground, the guided NeRF).

use burn::tensor::{Device, Int, Tensor};

use super::text_model::ClipTextModel;
use crate::distill::conditioning::PromptEncoder;
use crate::distill::DistillError;
use crate::tokenizer::ClipTokenizer;

/// Why a prompt could not be encoded.
#[derive(Debug, thiserror::Error)]
pub enum PromptError {
    /// The tokenizer refused it.
    #[error("tokenizer: {0}")]
    Tokenizer(String),
    /// The token ids do not fit the text model.
    #[error("text encoder: {0}")]
    TextEncoder(String),
}

/// Token ids of `prompts`, one row each, as the text model's input `[n, 77]`.
fn ids(
    tokenizer: &ClipTokenizer,
    model: &ClipTextModel,
    prompts: &[&str],
    device: &Device,
) -> Result<Tensor<2, Int>, PromptError> {
    let mut rows = Vec::with_capacity(prompts.len());
    for p in prompts {
        let ids = tokenizer
            .encode(p)
            .map_err(|e| PromptError::Tokenizer(e.to_string()))?;
        rows.push(ids.into_iter().map(i64::from).collect::<Vec<i64>>());
    }
    model
        .ids_tensor(&rows, device)
        .map_err(|e| PromptError::TextEncoder(e.to_string()))
}

/// Text embeddings `[n, 77, D]` of `prompts` (`last_hidden_state`).
pub fn encode_prompts(
    tokenizer: &ClipTokenizer,
    model: &ClipTextModel,
    prompts: &[&str],
    device: &Device,
) -> Result<Tensor<3>, PromptError> {
    Ok(model.forward(ids(tokenizer, model, prompts, device)?))
}

/// CLIP tokenizer + text model as a [`PromptEncoder`].
pub struct ClipPromptEncoder {
    tokenizer: ClipTokenizer,
    model: ClipTextModel,
    device: Device,
}

impl ClipPromptEncoder {
    /// The encoder of `tokenizer` and `model`, running on `device` (the model's device).
    pub fn new(tokenizer: ClipTokenizer, model: ClipTextModel, device: Device) -> Self {
        Self {
            tokenizer,
            model,
            device,
        }
    }

    /// Text embeddings `[n, 77, D]` of `prompts`.
    pub fn encode(&self, prompts: &[&str]) -> Result<Tensor<3>, PromptError> {
        encode_prompts(&self.tokenizer, &self.model, prompts, &self.device)
    }
}

impl PromptEncoder for ClipPromptEncoder {
    fn encode_prompt(&self, prompt: &str) -> Result<Tensor<3>, DistillError> {
        self.encode(&[prompt])
            .map_err(|e| DistillError::PromptEncoder {
                prompt: prompt.to_string(),
                source: Box::new(e),
            })
    }
}
