//! Reconstruction: configuration and presets, training data, losses, the trainer,
//! checkpoints and the PNG outputs of test views.

pub mod checkpoint;
pub mod config;
pub mod data;
pub mod error;
pub mod losses;
pub mod output;
pub mod trainer;

pub use config::{DepthSupervision, NerfConfig, RenderSettings, TrainSettings};
pub use error::NerfError;
pub use trainer::{FitSummary, ReconstructionLoss, StepStats, Trainer};
