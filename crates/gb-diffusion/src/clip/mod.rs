//! CLIP text encoder (transformers' `CLIPTextModel`) as Burn modules whose field names
//! follow the Hugging Face keys, so a checkpoint loads without renaming:
//! `text_model.embeddings.{token,position}_embedding`, `text_model.encoder.layers.N.
//! {self_attn.{q,k,v,out}_proj, layer_norm1, mlp.{fc1,fc2}, layer_norm2}`,
//! `text_model.final_layer_norm`.

pub mod attention;
pub mod embeddings;
pub mod encoder;
pub mod mlp;
pub mod prompt_encoder;
pub mod text_model;

pub use prompt_encoder::{encode_prompts, ClipPromptEncoder, PromptError};
pub use text_model::{load_text_encoder, ClipTextModel, TextEncoderError};
