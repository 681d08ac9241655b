//! Files that ship with the repository (`assets/`): the tiny built-in prior and the CLIP
//! tokenizer vocabulary.

use std::path::PathBuf;

/// The repository's `assets/` folder (`$GB_ASSETS` when set, for installed binaries).
pub fn assets_dir() -> PathBuf {
    match std::env::var_os("GB_ASSETS") {
        Some(d) => PathBuf::from(d),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../assets"),
    }
}

/// The tiny built-in inpainting prior: a diffusers folder plus its geometric LoRA
/// (`pytorch_lora_weights.safetensors`), trained by `cargo xtask finetune --synthetic
/// --from-scratch` from `configs/tiny-prior/`.
pub fn tiny_prior_dir() -> PathBuf {
    assets_dir().join("tiny-prior")
}
