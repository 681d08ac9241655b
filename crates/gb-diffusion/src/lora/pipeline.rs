//! A LoRA file merged into a pipeline's U-Net and text encoder in one call (the key tables
//! chosen from the U-Net's config), shared by every loader of a prior.

use super::{apply_lora, merge_lora, LoraComponent, LoraError, LoraFile};
use crate::checkpoint::keymap;
use crate::clip::text_model::ClipTextModel;
use crate::config::UNet2DConditionConfig;
use crate::models::UNet2DConditionModel;

/// A U-Net and text encoder with a LoRA merged in, and how many weights each got.
pub struct MergedLora {
    /// The U-Net with its adapters merged.
    pub unet: UNet2DConditionModel,
    /// The text encoder with its adapters merged.
    pub text_encoder: ClipTextModel,
    /// Adapted U-Net weights.
    pub unet_weights: usize,
    /// Adapted text-encoder weights.
    pub text_encoder_weights: usize,
}

/// Attaches every entry of `file` to `unet` (configured by `unet_config`) and
/// `text_encoder`, then merges them into the weights. A file that adapts neither network is
/// an error naming it.
pub fn merge_pipeline_lora(
    unet: UNet2DConditionModel,
    unet_config: &UNet2DConditionConfig,
    text_encoder: ClipTextModel,
    file: &LoraFile,
) -> Result<MergedLora, LoraError> {
    let section = if unet_config.use_linear_projection {
        keymap::UNET_LINEAR_PROJECTION
    } else {
        keymap::UNET
    };
    let (unet, unet_weights) = apply_lora(unet, file, LoraComponent::Unet, &section)?;
    let (text_encoder, text_encoder_weights) = apply_lora(
        text_encoder,
        file,
        LoraComponent::TextEncoder,
        &keymap::TEXT_ENCODER,
    )?;
    if unet_weights + text_encoder_weights == 0 {
        return Err(LoraError::File {
            path: file.path.clone(),
            message: "no entry for the U-Net or the text encoder (nothing to attach)".into(),
        });
    }
    Ok(MergedLora {
        unet: merge_lora(unet),
        text_encoder: merge_lora(text_encoder),
        unet_weights,
        text_encoder_weights,
    })
}
