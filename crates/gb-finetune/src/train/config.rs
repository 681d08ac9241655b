//! The fine-tuning recipe as a TOML-serialisable config.

use serde::{Deserialize, Serialize};

use crate::captions::CaptionMode;
use crate::FinetuneError;

/// What the optimiser updates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum TrainTarget {
    /// LoRA adapters on the U-Net attention projections (and optionally the text encoder's
    /// `q/k/v/out_proj`); the base weights stay bit-identical (the paper's recipe).
    #[default]
    Lora,
    /// Every parameter of the U-Net and the text encoder (training the tiny prior from scratch).
    Full,
}

/// Hyper-parameters of one fine-tuning run. Defaults follow the paper / diffusers'
/// `train_text_to_image_lora.py`: rank 32, alpha 32, AdamW at 1e-4, weight decay 1e-2,
/// gradient clipping at a global norm of 1.0.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FinetuneConfig {
    /// LoRA or full training.
    pub target: TrainTarget,
    /// Optimiser steps.
    pub steps: usize,
    /// Images per micro-batch.
    pub batch: usize,
    /// Micro-batches accumulated per optimiser step.
    pub grad_accum: usize,
    /// AdamW learning rate (constant).
    pub lr: f64,
    /// AdamW decoupled weight decay.
    pub weight_decay: f32,
    /// Global gradient-norm clip (`<= 0` disables).
    pub clip_grad_norm: f64,
    /// LoRA rank.
    pub rank: usize,
    /// LoRA alpha (scale `alpha / rank`).
    pub alpha: f64,
    /// Whether the text encoder also gets LoRA adapters (or is trained, in full mode).
    pub train_text_encoder: bool,
    /// Training resolution in pixels (square crops; a multiple of the VAE factor times the
    /// U-Net's down-sampling).
    pub resolution: usize,
    /// Prompt mode of the paper's ablation (ignored for the RGB-only base stage).
    pub mode: CaptionMode,
    /// Base stage: RGB images only, prompted by the bare caption (training a base prior from
    /// scratch), instead of the RGB/normal modalities of `mode`.
    pub rgb_only: bool,
    /// Seed of every random choice (the stream of step `s` is a function of `seed` and `s`,
    /// which is what makes a resumed run equal an uninterrupted one).
    pub seed: u64,
    /// Write a checkpoint every this many steps (0: only at the end).
    pub checkpoint_every: usize,
    /// Validate every this many steps (0: only at the end).
    pub validate_every: usize,
    /// Held-out samples used for validation.
    pub validation_samples: usize,
    /// DDIM steps of the validation sampler.
    pub validation_ddim_steps: usize,
    /// Samples averaged per hole for the posterior-mean score (1: single sample only; see
    /// [`crate::train::validate`]).
    pub validation_average: usize,
    /// Validation samples with the known region blended in after each DDIM step.
    pub validation_blend_known: bool,
    /// Smallest hole as a fraction of the image.
    pub mask_min_coverage: f32,
    /// Largest hole as a fraction of the image.
    pub mask_max_coverage: f32,
}

impl Default for FinetuneConfig {
    fn default() -> Self {
        Self {
            target: TrainTarget::Lora,
            steps: 1000,
            batch: 1,
            grad_accum: 1,
            lr: 1e-4,
            weight_decay: 1e-2,
            clip_grad_norm: 1.0,
            rank: 32,
            alpha: 32.0,
            train_text_encoder: true,
            resolution: 512,
            mode: CaptionMode::Captions,
            rgb_only: false,
            seed: 0,
            checkpoint_every: 500,
            validate_every: 500,
            validation_samples: 4,
            validation_ddim_steps: 20,
            validation_average: 1,
            validation_blend_known: false,
            mask_min_coverage: 0.05,
            mask_max_coverage: 0.5,
        }
    }
}

impl FinetuneConfig {
    /// Checks every field; the error names the field.
    pub fn validate(&self) -> Result<(), FinetuneError> {
        let bad = |field: &str, message: String| {
            Err(FinetuneError::Config {
                field: field.into(),
                message,
            })
        };
        if self.steps == 0 {
            return bad("steps", "must be at least 1".into());
        }
        if self.batch == 0 {
            return bad("batch", "must be at least 1".into());
        }
        if self.grad_accum == 0 {
            return bad("grad_accum", "must be at least 1".into());
        }
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return bad("lr", format!("{} is not a positive number", self.lr));
        }
        if self.target == TrainTarget::Lora && self.rank == 0 {
            return bad("rank", "a LoRA needs rank >= 1".into());
        }
        if self.validation_average == 0 {
            return bad("validation_average", "must be at least 1".into());
        }
        if self.resolution < 8 {
            return bad("resolution", format!("{} is too small", self.resolution));
        }
        if !(0.0 < self.mask_min_coverage
            && self.mask_min_coverage <= self.mask_max_coverage
            && self.mask_max_coverage < 1.0)
        {
            return bad(
                "mask_min_coverage",
                format!(
                    "need 0 < min ({}) <= max ({}) < 1",
                    self.mask_min_coverage, self.mask_max_coverage
                ),
            );
        }
        Ok(())
    }

    /// Reads a config from TOML text (unknown fields are an error naming them).
    pub fn from_toml(text: &str, origin: &std::path::Path) -> Result<Self, FinetuneError> {
        let cfg: Self = toml::from_str(text).map_err(|e| FinetuneError::Invalid {
            path: origin.to_path_buf(),
            message: gb_core::messages::at_line(text, e.span(), e.message()),
        })?;
        cfg.validate()?;
        Ok(cfg)
    }
}
