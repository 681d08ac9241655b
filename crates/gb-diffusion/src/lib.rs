//! gb-diffusion: Stable Diffusion inpainting stack in Burn: tokenizer, CLIP text encoder, VAE, U-Net, scheduler, LoRA, checkpoint loading, score distillation.

pub mod checkpoint;
pub mod config;
pub mod tokenizer;
pub mod clip;
pub mod distill;
pub mod models;
pub mod inpaint;
pub mod scheduler;
pub mod lora;
pub mod tensor_file;
