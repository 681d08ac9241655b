//! Configuration structs that mirror the `config.json` files of a diffusers-layout
//! checkpoint folder. Every struct deserialises straight from the JSON written by
//! diffusers/transformers, with the library defaults for absent fields.

pub mod clip;
pub mod model_index;
pub mod read;
pub mod scheduler;
pub mod unet;
pub mod vae;

pub use clip::{ClipActivation, ClipTextConfig};
pub use model_index::{ComponentRef, ModelIndex};
pub use read::{read_json_config, ConfigError};
pub use scheduler::{BetaSchedule, PredictionType, SchedulerConfig, TimestepSpacing};
pub use unet::{PerBlock, UNet2DConditionConfig};
pub use vae::AutoencoderKLConfig;
