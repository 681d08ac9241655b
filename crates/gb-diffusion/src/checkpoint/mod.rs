//! Loading weights from a diffusers-layout checkpoint folder (or a Hugging Face hub id)
//! into Burn modules.
//!
//! - [`keymap`]: THE table of every key remapping, one section per component.
//! - [`load`]: [`load_module`], which applies `*.safetensors` files to a module through a
//!   keymap section, checking that every tensor is present and well-shaped.
//! - [`folder`]: the diffusers folder (`model_index.json`, sub-folders, `.fp16` variants).
//! - [`save`]: [`save_module`], the inverse: a module to a diffusers-named safetensors file.
//! - [`header`]: a safetensors file's layout checked from its header (truncated files).
//! - [`hub`]: resolving a hub id to a local folder through the hub cache, offline first,
//!   and downloading a pipeline snapshot into that cache with `hf-hub`.
//! - [`resolve`]: [`resolve_prior`], the one resolver of a prior specification (`tiny`, a
//!   folder, a hub id).

pub mod error;
pub mod folder;
pub mod header;
pub mod hub;
pub mod keymap;
pub mod load;
pub mod resolve;
pub mod save;

pub use error::CheckpointError;
pub use folder::{DiffusersFolder, WeightVariant};
pub use keymap::KeymapSection;
pub use load::{load_module, LoadReport};
pub use resolve::{locate_model, resolve_prior, resolve_prior_with, PriorSpec};
pub use save::save_module;
