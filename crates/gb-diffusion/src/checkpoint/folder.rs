//! A diffusers-layout checkpoint folder: `model_index.json` and one sub-folder per
//! component holding `config.json` and `*.safetensors` weights.

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;

use super::CheckpointError;
use crate::config::{read_json_config, ModelIndex};

/// Which weight files of a component to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WeightVariant {
    /// Full-precision files when present, else the `.fp16` variant.
    #[default]
    Auto,
    /// Only the plain (usually f32) files.
    Full,
    /// Only the `*.fp16.safetensors` files (cast to f32 on load).
    Fp16,
}

/// An opened diffusers pipeline folder.
#[derive(Debug, Clone)]
pub struct DiffusersFolder {
    /// The folder.
    pub root: PathBuf,
    /// Its `model_index.json`, when the folder has one (single-component folders may not).
    pub index: Option<ModelIndex>,
}

impl DiffusersFolder {
    /// Opens `root`, reading `model_index.json` when present.
    pub fn open(root: impl Into<PathBuf>) -> Result<Self, CheckpointError> {
        let root = root.into();
        if !root.is_dir() {
            return Err(CheckpointError::MissingFile {
                path: root,
                what: "a diffusers pipeline folder".into(),
            });
        }
        let index_path = root.join("model_index.json");
        let index = if index_path.is_file() {
            Some(read_json_config(&index_path)?)
        } else {
            None
        };
        Ok(Self { root, index })
    }

    /// The sub-folder of component `name`, which must exist.
    pub fn component_dir(&self, name: &str) -> Result<PathBuf, CheckpointError> {
        let dir = self.root.join(name);
        if dir.is_dir() {
            Ok(dir)
        } else {
            Err(CheckpointError::MissingFile {
                path: dir,
                what: format!("the `{name}` component folder"),
            })
        }
    }

    /// Reads `<name>/config.json` (or another JSON file name, e.g. the scheduler's
    /// `scheduler_config.json`) into `T`.
    pub fn config<T: DeserializeOwned>(
        &self,
        name: &str,
        file: &str,
    ) -> Result<T, CheckpointError> {
        let path = self.component_dir(name)?.join(file);
        if !path.is_file() {
            return Err(CheckpointError::MissingFile {
                path,
                what: format!("the `{name}` configuration"),
            });
        }
        Ok(read_json_config(&path)?)
    }

    /// The safetensors files of component `name` for `variant` (all shards, sorted).
    pub fn weight_files(
        &self,
        name: &str,
        variant: WeightVariant,
    ) -> Result<Vec<PathBuf>, CheckpointError> {
        let dir = self.component_dir(name)?;
        let (full, fp16) = list_safetensors(&dir)?;
        let chosen = match variant {
            WeightVariant::Full => full,
            WeightVariant::Fp16 => fp16,
            WeightVariant::Auto if !full.is_empty() => full,
            WeightVariant::Auto => fp16,
        };
        if chosen.is_empty() {
            return Err(CheckpointError::MissingFile {
                path: dir,
                what: format!("*.safetensors weights ({variant:?})"),
            });
        }
        Ok(chosen)
    }
}

/// Splits the `*.safetensors` files of `dir` into plain and `.fp16` variants.
fn list_safetensors(dir: &Path) -> Result<(Vec<PathBuf>, Vec<PathBuf>), CheckpointError> {
    let entries = std::fs::read_dir(dir).map_err(|e| CheckpointError::Weights {
        path: dir.to_path_buf(),
        message: e.to_string(),
    })?;
    let mut full = Vec::new();
    let mut fp16 = Vec::new();
    for entry in entries.flatten() {
        let path = entry.path();
        let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
            continue;
        };
        let Some(stem) = name.strip_suffix(".safetensors") else {
            continue;
        };
        if stem.ends_with(".fp16") || stem.contains(".fp16-") {
            fp16.push(path);
        } else if !stem.contains('.') {
            full.push(path);
        }
    }
    full.sort();
    fp16.sort();
    Ok((full, fp16))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn picks_variants_and_reports_missing() {
        let dir = tempfile::tempdir().unwrap();
        let unet = dir.path().join("unet");
        std::fs::create_dir(&unet).unwrap();
        for f in [
            "diffusion_pytorch_model.fp16.safetensors",
            "config.json",
            "diffusion_pytorch_model.bin",
        ] {
            std::fs::write(unet.join(f), b"x").unwrap();
        }
        let folder = DiffusersFolder::open(dir.path()).unwrap();
        assert!(folder.index.is_none());
        let auto = folder.weight_files("unet", WeightVariant::Auto).unwrap();
        assert_eq!(
            auto,
            vec![unet.join("diffusion_pytorch_model.fp16.safetensors")]
        );
        let err = folder
            .weight_files("unet", WeightVariant::Full)
            .unwrap_err();
        assert!(err.to_string().contains("unet"), "{err}");
        let err = folder.component_dir("vae").unwrap_err();
        assert!(err.to_string().contains("vae"), "{err}");

        std::fs::write(unet.join("diffusion_pytorch_model.safetensors"), b"x").unwrap();
        let auto = folder.weight_files("unet", WeightVariant::Auto).unwrap();
        assert_eq!(auto, vec![unet.join("diffusion_pytorch_model.safetensors")]);
    }
}
