//! LoRA: reading diffusers/PEFT and kohya files, attaching them to Burn modules through
//! burn's reparameterisation (`LoraAdapter` on linear weights, [`ConvLoraAdapter`] on
//! convolution kernels), writing the diffusers/PEFT format, and merging into the weights.
//!
//! Order of use: load the base weights first (`checkpoint::load_module`), then
//! [`apply_lora`]; [`merge_lora`] folds the adapters into dense weights for inference.

pub mod apply;
pub mod conv_adapter;
pub mod error;
pub mod file;
mod pipeline;
pub mod tensor_io;
pub mod write;

pub use apply::{apply_lora, merge_lora, LoraComponent};

/// The LoRA file name a fine-tuned prior folder carries (diffusers' `save_lora_weights`).
pub const LORA_FILE_NAME: &str = "pytorch_lora_weights.safetensors";
pub use conv_adapter::ConvLoraAdapter;
pub use error::LoraError;
pub use file::{LoraEntry, LoraFile};
pub use pipeline::{merge_pipeline_lora, MergedLora};
pub use write::{collect_lora, write_peft_lora, CollectedLora, LoraExport};
