//! Loading the U-Net and VAE from a diffusers-layout folder through
//! [`crate::checkpoint::load_module`] and the keymap sections for each component.

use std::path::Path;

use burn::tensor::Device;

use super::{AutoencoderKL, UNet2DConditionModel};
use crate::checkpoint::{keymap, load_module, CheckpointError, DiffusersFolder, WeightVariant};
use crate::config::{AutoencoderKLConfig, UNet2DConditionConfig};

/// Loads `<root>/unet/config.json` and its `*.safetensors` (`.fp16` variants cast to f32).
/// The error names the missing or misshaped tensor, its expected shape and the file.
pub fn load_unet(
    root: &Path,
    device: &Device,
) -> Result<(UNet2DConditionModel, UNet2DConditionConfig), CheckpointError> {
    load_unet_variant(root, WeightVariant::Auto, device)
}

/// [`load_unet`] with a choice of weight files (full precision or `.fp16`).
pub fn load_unet_variant(
    root: &Path,
    variant: WeightVariant,
    device: &Device,
) -> Result<(UNet2DConditionModel, UNet2DConditionConfig), CheckpointError> {
    let folder = DiffusersFolder::open(root)?;
    let dir = folder.component_dir("unet")?;
    let cfg = UNet2DConditionConfig::from_file(&dir.join("config.json"))?;
    let files = folder.weight_files("unet", variant)?;
    let section = if cfg.use_linear_projection {
        keymap::UNET_LINEAR_PROJECTION
    } else {
        keymap::UNET
    };
    let (model, report) = load_module(UNet2DConditionModel::new(&cfg, device), &files, &section)?;
    tracing::debug!(
        tensors = report.applied.len(),
        "loaded unet from {}",
        dir.display()
    );
    Ok((model, cfg))
}

/// Loads `<root>/vae/config.json` and its `*.safetensors`; both the current and the old
/// (pre-0.14) attention key names are accepted.
pub fn load_vae(
    root: &Path,
    device: &Device,
) -> Result<(AutoencoderKL, AutoencoderKLConfig), CheckpointError> {
    load_vae_variant(root, WeightVariant::Auto, device)
}

/// [`load_vae`] with a choice of weight files (full precision or `.fp16`).
pub fn load_vae_variant(
    root: &Path,
    variant: WeightVariant,
    device: &Device,
) -> Result<(AutoencoderKL, AutoencoderKLConfig), CheckpointError> {
    let folder = DiffusersFolder::open(root)?;
    let dir = folder.component_dir("vae")?;
    let cfg = AutoencoderKLConfig::from_file(&dir.join("config.json"))?;
    let files = folder.weight_files("vae", variant)?;
    let (model, report) = load_module(AutoencoderKL::new(&cfg, device), &files, &keymap::VAE)?;
    tracing::debug!(
        tensors = report.applied.len(),
        "loaded vae from {}",
        dir.display()
    );
    Ok((model, cfg))
}
