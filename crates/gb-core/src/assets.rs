//! Files that ship with the project (`assets/`): the tiny built-in prior and the CLIP
//! tokenizer vocabulary. Libraries and tests find them in the source tree; the `gb-nerf`
//! command embeds them and points [`assets_dir`] at its unpacked copy
//! ([`use_assets_dir`]), so an installed command needs no source tree.

use std::path::PathBuf;
use std::sync::OnceLock;

static ASSETS_DIR: OnceLock<PathBuf> = OnceLock::new();

/// Makes [`assets_dir`] return `dir` for the rest of the process (the first call wins;
/// `$GB_ASSETS` still takes precedence).
pub fn use_assets_dir(dir: PathBuf) {
    let _ = ASSETS_DIR.set(dir);
}

/// The assets folder: `$GB_ASSETS` when set, else the folder given to [`use_assets_dir`],
/// else the repository's `assets/` (the source tree this crate was built from).
pub fn assets_dir() -> PathBuf {
    if let Some(d) = std::env::var_os("GB_ASSETS") {
        return PathBuf::from(d);
    }
    match ASSETS_DIR.get() {
        Some(d) => d.clone(),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../assets"),
    }
}

/// The tiny built-in inpainting prior: a diffusers folder plus its geometric LoRA
/// (`pytorch_lora_weights.safetensors`), trained by `cargo xtask finetune --synthetic
/// --from-scratch` from `configs/tiny-prior/`.
pub fn tiny_prior_dir() -> PathBuf {
    assets_dir().join("tiny-prior")
}
