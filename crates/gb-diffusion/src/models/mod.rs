//! The image half of Stable Diffusion as Burn modules: U-Net and VAE, one block family per
//! file (candle-transformers' stable_diffusion layout). Field names follow the diffusers
//! checkpoint keys; the few that cannot (`ff.net.0`, SD 2.x linear `proj_in`/`proj_out`, the
//! VAE's old attention names) are remapped in [`crate::checkpoint::keymap`].
//!
//! Attention softmax and group-norm statistics run in f32. Frozen inference uses
//! `valid()` modules (no autodiff graph); the VAE encoder also works under autodiff.

pub mod attention;
pub mod embeddings;
pub mod layers;
pub mod load;
pub mod parity;
pub mod resnet;
pub mod transformer;
pub mod unet;
pub mod unet_blocks;
pub mod vae;

pub use load::{load_unet, load_unet_variant, load_vae, load_vae_variant};
pub use unet::UNet2DConditionModel;
pub use vae::AutoencoderKL;
