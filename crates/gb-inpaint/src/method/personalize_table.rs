//! `[personalize]` of a method: the per-scene LoRA's recipe ([`crate::personalize`] trains
//! it).

use std::path::PathBuf;

use gb_finetune::captions::CaptionMode;
use gb_finetune::train::{FinetuneConfig, TrainTarget};
use serde::{Deserialize, Serialize};

/// The personalisation of a method (`[personalize]` in its config).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PersonalizeSettings {
    /// AdamW steps (0: off, the default).
    pub steps: usize,
    /// Learning rate (the tiny prior's geometric LoRA recipe: 1e-3).
    pub lr: f64,
    /// LoRA rank.
    pub rank: usize,
    /// LoRA alpha (scale `alpha / rank`).
    pub alpha: f64,
    /// Patches per step.
    pub batch: usize,
    /// Whether the text encoder gets adapters too.
    pub train_text_encoder: bool,
    /// Seed of the adapters, patches, holes, noise and timesteps.
    pub seed: u64,
    /// A folder of object-free images of the training views (`NAME.png`, the view's size):
    /// their masked squares are trained on too (module docs). Views without one are
    /// patched as usual.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub object_free: Option<PathBuf>,
}

impl Default for PersonalizeSettings {
    fn default() -> Self {
        Self {
            steps: 0,
            lr: 1e-3,
            rank: 8,
            alpha: 8.0,
            batch: 4,
            train_text_encoder: false,
            seed: 0,
            object_free: None,
        }
    }
}

impl PersonalizeSettings {
    /// Whether personalisation runs.
    pub fn enabled(&self) -> bool {
        self.steps > 0
    }

    /// Whether these are the default settings (off).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// The fine-tuning recipe at the prior's `resolution`.
    pub(crate) fn recipe(&self, resolution: usize) -> FinetuneConfig {
        FinetuneConfig {
            target: TrainTarget::Lora,
            steps: self.steps,
            batch: self.batch,
            grad_accum: 1,
            lr: self.lr,
            rank: self.rank,
            alpha: self.alpha,
            train_text_encoder: self.train_text_encoder,
            resolution,
            mode: CaptionMode::Captions,
            rgb_only: true,
            seed: self.seed,
            checkpoint_every: 0,
            validate_every: 0,
            ..FinetuneConfig::default()
        }
    }
}
