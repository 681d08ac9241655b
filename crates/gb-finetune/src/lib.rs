//! gb-finetune: RGB/normal datasets, random inpainting masks and LoRA fine-tuning of the
//! geometric prior (GB-NeRF's first contribution), plus the recipe of the tiny built-in prior.
//!
//! - [`sample`]: one RGB/normal pair in memory, and the [`sample::PairSource`] interface;
//! - [`diode`], [`synthetic`]: the DIODE layout and the procedural pairs as pair sources;
//! - [`normal_map`]: normal vectors <-> normal-map images (one convention with the renderer);
//! - [`captions`]: caption files and the three prompt modes of the paper's ablation;
//! - [`masks`]: random rectangles, ellipses and brush strokes for the self-supervised loss;
//! - [`train`]: the inpainting loss, the LoRA / from-scratch trainer, checkpoints, validation.

pub mod captions;
pub mod crop;
pub mod diode;
pub mod error;
pub mod masks;
pub mod normal_map;
pub mod run;
pub mod sample;
pub mod synthetic;
pub mod tiny_prior;
pub mod train;
pub mod validate_only;

pub use error::FinetuneError;
