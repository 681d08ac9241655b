//! [`save_module`]: write a Burn module as one diffusers-named `*.safetensors` file (the
//! inverse of [`super::load_module`]), so that a model trained here (the tiny built-in prior)
//! is an ordinary diffusers folder that both this crate and diffusers load.

use std::path::Path;

use burn::module::Module;
use burn::store::{BurnToPyTorchAdapter, KeyRemapper, ModuleSnapshot, SafetensorsStore};

use super::{CheckpointError, KeymapSection};

/// Writes every float parameter of `module` to `path` (atomically: temporary file, then
/// rename) under its checkpoint name: Burn paths mapped back with `section.to_checkpoint`,
/// linear weights transposed to PyTorch's `[out, in]` and norm `gamma`/`beta` renamed to
/// `weight`/`bias` by burn's `BurnToPyTorchAdapter`. LoRA factors are not part of a base
/// checkpoint: merge them first ([`crate::lora::merge_lora`]) or write them with
/// [`crate::lora::write_peft_lora`].
pub fn save_module<M: Module>(
    module: &M,
    path: &Path,
    section: &KeymapSection,
) -> Result<(), CheckpointError> {
    let err = |message: String| CheckpointError::Weights {
        path: path.to_path_buf(),
        message,
    };
    let remapper = KeyRemapper::from_patterns(section.to_checkpoint.to_vec()).map_err(|e| {
        CheckpointError::Keymap {
            section: section.name.to_string(),
            pattern: format!("{:?}", section.to_checkpoint),
            message: e.to_string(),
        }
    })?;
    let mut store = SafetensorsStore::from_bytes(None)
        .with_to_adapter(BurnToPyTorchAdapter)
        .remap(remapper);
    module
        .save_into(&mut store)
        .map_err(|e| err(e.to_string()))?;
    let bytes = store.get_bytes().map_err(|e| err(e.to_string()))?;
    gb_core::write_atomic(path, &bytes).map_err(|e| err(e.to_string()))
}
