//! Fine-tuning a Stable Diffusion inpainting prior with the self-supervised inpainting loss.
//!
//! - [`config`]: [`FinetuneConfig`], the TOML-serialisable recipe (LoRA or full training);
//! - [`models`]: [`PriorModels`], the tokenizer, text encoder, U-Net, VAE and schedule, loaded
//!   from a diffusers folder, built from config files (from scratch), and written back;
//! - [`batch`]: deterministic training batches (crop, random mask, modality, prompt);
//! - [`grad_sync`]: the ranks' gradient mean of data-parallel training (over MPI with the
//!   `mpi` feature, `mpi_sync`);
//! - [`loss`]: the 9-channel epsilon-prediction loss of diffusers' inpainting trainers;
//! - [`grad_clip`]: clipping by the global gradient norm (what `clip_grad_norm_` does);
//! - [`trainer`]: [`FinetuneTrainer`], AdamW with gradient accumulation, atomic checkpoints
//!   and an exact resume;
//! - [`vae_stage`]: from-scratch training of a small autoencoder (the tiny prior's first step);
//! - [`validate`]: masked angular error and masked PSNR of 2D inpainting, and fill baselines.

pub mod batch;
pub mod checkpoint;
pub mod config;
pub mod grad_clip;
pub mod grad_sync;
pub mod loss;
pub mod models;
#[cfg(feature = "mpi")]
pub mod mpi_sync;
pub mod trainer;
pub mod vae_stage;
pub mod validate;

pub use config::{FinetuneConfig, TrainTarget};
pub use models::PriorModels;
pub use trainer::{FinetuneTrainer, StepStats};
