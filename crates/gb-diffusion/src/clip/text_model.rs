//! `CLIPTextModel`: embeddings, encoder, final layer norm -> `last_hidden_state`.

use burn::module::Module;
use burn::nn::{LayerNorm, LayerNormConfig};
use burn::tensor::{DType, Device, Int, Tensor, TensorData};

use super::embeddings::ClipTextEmbeddings;
use super::encoder::ClipEncoder;
use crate::checkpoint::{keymap, load_module, CheckpointError, DiffusersFolder, WeightVariant};
use crate::config::ClipTextConfig;
use crate::precision::{layer_norm_f32, to_dtype};

/// Error loading or running the text encoder.
#[derive(Debug, thiserror::Error)]
pub enum TextEncoderError {
    /// Loading the checkpoint failed.
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    /// The ids do not fit the model.
    #[error("invalid input_ids: {0}")]
    InvalidIds(String),
}

/// `text_model`: the transformer proper.
#[derive(Module, Debug)]
pub struct ClipTextTransformer {
    /// Token and position embeddings.
    pub embeddings: ClipTextEmbeddings,
    /// The layer stack.
    pub encoder: ClipEncoder,
    /// Norm applied to the last layer's output.
    pub final_layer_norm: LayerNorm,
}

/// transformers' `CLIPTextModel` (the root holds `text_model`, as the HF keys do).
#[derive(Module, Debug)]
pub struct ClipTextModel {
    /// The transformer.
    pub text_model: ClipTextTransformer,
    /// The configuration it was built from.
    #[module(skip)]
    pub config: ClipTextConfig,
}

impl ClipTextModel {
    /// Randomly initialised model of `config`'s sizes.
    pub fn new(config: &ClipTextConfig, device: &Device) -> Self {
        Self {
            text_model: ClipTextTransformer {
                embeddings: ClipTextEmbeddings::new(config, device),
                encoder: ClipEncoder::new(config, device),
                final_layer_norm: LayerNormConfig::new(config.hidden_size)
                    .with_epsilon(config.layer_norm_eps)
                    .init(device),
            },
            config: config.clone(),
        }
    }

    /// `[batch, seq]` ids to `last_hidden_state` `[batch, seq, hidden]`, in f32 (computed in
    /// the weights' precision, [`crate::precision`]).
    pub fn forward(&self, input_ids: Tensor<2, Int>) -> Tensor<3> {
        let tm = &self.text_model;
        let x = tm.embeddings.forward(input_ids);
        let x = tm.encoder.forward(x);
        to_dtype(layer_norm_f32(&tm.final_layer_norm, x), DType::F32)
    }

    /// Checks a batch of id rows against the vocabulary and position table and builds the
    /// `[batch, seq]` id tensor.
    pub fn ids_tensor(
        &self,
        rows: &[Vec<i64>],
        device: &Device,
    ) -> Result<Tensor<2, Int>, TextEncoderError> {
        let seq = rows.first().map(Vec::len).unwrap_or(0);
        if rows.is_empty() || seq == 0 {
            return Err(TextEncoderError::InvalidIds("empty batch".into()));
        }
        if seq > self.config.max_position_embeddings {
            return Err(TextEncoderError::InvalidIds(format!(
                "sequence length {seq} exceeds max_position_embeddings {}",
                self.config.max_position_embeddings
            )));
        }
        let mut flat = Vec::with_capacity(rows.len() * seq);
        for (i, row) in rows.iter().enumerate() {
            if row.len() != seq {
                return Err(TextEncoderError::InvalidIds(format!(
                    "row {i} has {} ids, row 0 has {seq}",
                    row.len()
                )));
            }
            for &id in row {
                if id < 0 || id as usize >= self.config.vocab_size {
                    return Err(TextEncoderError::InvalidIds(format!(
                        "id {id} in row {i} outside the vocabulary (size {})",
                        self.config.vocab_size
                    )));
                }
                flat.push(id);
            }
        }
        Ok(Tensor::from_data(
            TensorData::new(flat, [rows.len(), seq]),
            device,
        ))
    }
}

/// Loads `text_encoder/` (config + weights) of a diffusers folder, without autodiff.
pub fn load_text_encoder(
    folder: &DiffusersFolder,
    variant: WeightVariant,
    device: &Device,
) -> Result<ClipTextModel, TextEncoderError> {
    let section = keymap::TEXT_ENCODER;
    let config: ClipTextConfig = folder.config(section.name, "config.json")?;
    let files = folder.weight_files(section.name, variant)?;
    let model = ClipTextModel::new(&config, device);
    let (model, report) = load_module(model, &files, &section)?;
    tracing::debug!(tensors = report.applied.len(), "text encoder loaded");
    Ok(model)
}
