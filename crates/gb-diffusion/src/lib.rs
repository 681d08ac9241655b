//! gb-diffusion: Stable Diffusion inpainting stack in Burn: tokenizer, CLIP text encoder, VAE, U-Net, scheduler, LoRA, checkpoint loading, score distillation.

pub mod checkpoint;
pub mod clip;
pub mod config;
pub mod distill;
pub mod inpaint;
pub mod lora;
pub mod models;
pub mod pipeline;
pub mod precision;
pub mod scheduler;
pub mod tensor_file;
pub mod tokenizer;
