//! gb-inpaint: the GB-NeRF pipeline. A NeRF is reconstructed from the unmasked pixels of the
//! training views while a Stable Diffusion inpainting prior (optionally with the RGB / normal
//! LoRA of the paper) guides what fills the hole, through score distillation on RGB renders
//! and on normal maps:
//!
//! `L = L_rgb(unmasked) + 0.1 L_depth(unmasked) + lambda_rgb L_rgb_guidance(mask) + lambda_normal L_normal_guidance(mask)`
//!
//! - [`method`]: the method configurations (`configs/methods/*.toml`: gb-nerf,
//!   gb-nerf-unseen, gb-nerf-auto, bsd, mvip-nerf, spin-nerf-sds, csd, none, pre-inpainted),
//!   prompts, and how lambda maps to the paper's scale;
//! - [`auto`]: `lambda_rgb` / `lambda_normal = "auto"`, weights each scene picks for itself
//!   on a pseudo-hole that no training view sees;
//! - [`prior`]: loading the prior folder and attaching a LoRA;
//! - [`personalize`]: the per-scene LoRA, fine-tuned on the scene's unmasked pixels before
//!   guidance starts;
//! - [`crop`]: the mask's bounding-box crop, rendered at the prior's resolution (RGB, pasted
//!   on the ground truth or not) and as a normal map;
//! - [`guidance`]: one guidance term injected as `lambda * s(t) * (z * g.detach()).sum()`;
//! - [`trainer`]: the guided trainer (one backward per step, NaN policy, checkpoints,
//!   resume, `train_log.jsonl`);
//! - [`resume`]: what a checkpoint keeps for an exact resume besides the reconstruction
//!   (run identity, counters, visibility maps);
//! - [`pre_inpainted`]: the SPIn-NeRF + LaMa baseline's inputs;
//! - [`report`], [`gif`]: the run's `report.html` and its orbit animation, drawn with
//!   gb-report (the page, the SVG charts, the GIF encoder);
//! - [`oracle`]: oracle guidance for experiments (the exact score of the object-free image);
//! - [`visibility`]: visibility-aware guidance (the prior acts only where no training view
//!   sees the surface);
//! - [`run`]: one object-removal run as a library call ([`run::run`] on a [`RunSpec`],
//!   returning a [`RunSummary`], its `metrics.json`);
//! - [`export`]: the run's inpainted scene as a nerfstudio dataset (`OUT/export/`).
//!
//! The method grid (many runs, their tables, cluster files) is the gb-grid crate above this
//! one.
//!
//! The command line is `cargo xtask inpaint` (xtask/src/cmd/inpaint.rs), a thin call of
//! [`run::run`].

pub mod auto;
pub mod crop;
pub mod error;
pub mod export;
pub mod fill;
pub mod geometry;
pub mod gif;
pub mod guidance;
pub mod method;
pub mod oracle;
pub mod personalize;
pub mod pre_inpainted;
pub mod prior;
pub mod reference;
pub mod report;
pub mod resume;
pub mod run;
pub mod trainer;
pub mod visibility;

pub use error::InpaintError;
pub use guidance::Modality;
pub use method::{MethodConfig, PromptOverrides, Prompts, SceneCaptions};
pub use prior::{load_prior, lora_for, PriorInfo, PriorOptions, SdPrior};
pub use run::{export_run, run, RunSpec, RunSummary};
pub use trainer::{FitOptions, FitSummary, GuidedTrainer, StepRecord, TermRecord};
