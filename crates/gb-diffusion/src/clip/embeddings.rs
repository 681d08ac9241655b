//! Token + learned position embeddings.

use burn::module::Module;
use burn::nn::{Embedding, EmbeddingConfig};
use burn::tensor::{Device, Int, Tensor};

use crate::config::ClipTextConfig;

/// `text_model.embeddings`: token embedding plus absolute position embedding.
#[derive(Module, Debug)]
pub struct ClipTextEmbeddings {
    /// `token_embedding`: `[vocab_size, hidden_size]`.
    pub token_embedding: Embedding,
    /// `position_embedding`: `[max_position_embeddings, hidden_size]`.
    pub position_embedding: Embedding,
}

impl ClipTextEmbeddings {
    /// Randomly initialised embeddings of the configured sizes.
    pub fn new(config: &ClipTextConfig, device: &Device) -> Self {
        Self {
            token_embedding: EmbeddingConfig::new(config.vocab_size, config.hidden_size)
                .init(device),
            position_embedding: EmbeddingConfig::new(
                config.max_position_embeddings,
                config.hidden_size,
            )
            .init(device),
        }
    }

    /// `[batch, seq]` ids to `[batch, seq, hidden]`; positions are `0..seq`.
    pub fn forward(&self, input_ids: Tensor<2, Int>) -> Tensor<3> {
        let [batch, seq] = input_ids.dims();
        let device = input_ids.device();
        let positions = Tensor::<1, Int>::arange(0..seq as i64, &device)
            .reshape([1, seq])
            .expand([batch, seq]);
        self.token_embedding.forward(input_ids) + self.position_embedding.forward(positions)
    }
}
