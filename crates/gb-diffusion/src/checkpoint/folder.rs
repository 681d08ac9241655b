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
    /// Opens `root`, reading `model_index.json` when present. A single file (a `.ckpt`,
    /// `.bin` or single-file `.safetensors` checkpoint) is refused with the command that
    /// converts it.
    pub fn open(root: impl Into<PathBuf>) -> Result<Self, CheckpointError> {
        let root = root.into();
        if root.is_file() {
            return Err(CheckpointError::SingleFile {
                pickle: if is_pickle(&root) {
                    " (a PyTorch pickle, which is never loaded: unpickling can run code)".into()
                } else {
                    String::new()
                },
                advice: format!(
                    "python -c \"from diffusers import StableDiffusionInpaintPipeline as P; \
                     P.from_single_file('{}').save_pretrained('prior', safe_serialization=True)\"",
                    root.display()
                ),
                path: root,
            });
        }
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
            if let Some(pickle) = pickle_files(&dir).into_iter().next() {
                return Err(self.pickle_error(name, pickle));
            }
            return Err(CheckpointError::MissingFile {
                path: dir,
                what: format!("*.safetensors weights ({variant:?})"),
            });
        }
        Ok(chosen)
    }
}

impl DiffusersFolder {
    /// Checks, before anything is loaded, that every weight-holding component folder present
    /// (`unet`, `vae`, `text_encoder`) has `.safetensors` weights: one holding only PyTorch
    /// pickles is refused with the command that converts the pipeline.
    pub fn check_weight_formats(&self) -> Result<(), CheckpointError> {
        for name in ["unet", "vae", "text_encoder"] {
            let dir = self.root.join(name);
            if !dir.is_dir() {
                continue;
            }
            let (full, fp16) = list_safetensors(&dir)?;
            if full.is_empty() && fp16.is_empty() {
                if let Some(pickle) = pickle_files(&dir).into_iter().next() {
                    return Err(self.pickle_error(name, pickle));
                }
            }
        }
        Ok(())
    }

    fn pickle_error(&self, component: &str, path: PathBuf) -> CheckpointError {
        CheckpointError::PickleWeights {
            path,
            component: component.to_string(),
            advice: format!(
                "python -c \"from diffusers import StableDiffusionInpaintPipeline as P; \
                 P.from_pretrained('{}').save_pretrained('prior-safetensors', \
                 safe_serialization=True)\"",
                self.root.display()
            ),
        }
    }
}

/// File extensions of PyTorch pickle checkpoints.
pub const PICKLE_EXTENSIONS: [&str; 5] = ["bin", "ckpt", "pt", "pth", "pkl"];

/// Whether `path` is a PyTorch pickle: a pickle extension, or (for a file not named
/// `.safetensors` / `.json`) the first bytes of a pickle (protocol 2+, `0x80`) or of
/// `torch.save`'s zip archive (`PK\x03\x04`).
pub fn is_pickle(path: &Path) -> bool {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    if PICKLE_EXTENSIONS.contains(&ext.as_str()) {
        return true;
    }
    if ext == "safetensors" || ext == "json" {
        return false;
    }
    let mut magic = [0u8; 4];
    std::fs::File::open(path)
        .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut magic))
        .is_ok()
        && (magic[0] == 0x80 || magic == *b"PK\x03\x04")
}

/// The PyTorch pickle files directly inside `dir`, sorted.
fn pickle_files(dir: &Path) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_file() && is_pickle(p))
        .collect();
    out.sort();
    out
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

    #[test]
    fn pickles_are_refused_with_the_conversion_command() {
        let dir = tempfile::tempdir().unwrap();
        let ckpt = dir.path().join("model.ckpt");
        std::fs::write(&ckpt, b"\x80\x02}q\x00.").unwrap();
        assert!(is_pickle(&ckpt));
        let err = DiffusersFolder::open(&ckpt).unwrap_err().to_string();
        assert!(
            err.contains("model.ckpt")
                && err.contains("pickle")
                && err.contains("from_single_file"),
            "{err}"
        );
        let single = dir.path().join("model.safetensors");
        std::fs::write(&single, b"{}").unwrap();
        let err = DiffusersFolder::open(&single).unwrap_err().to_string();
        assert!(
            err.contains("single-file") && !err.contains("pickle"),
            "{err}"
        );

        let vae = dir.path().join("vae");
        std::fs::create_dir(&vae).unwrap();
        std::fs::write(vae.join("diffusion_pytorch_model.bin"), b"PK\x03\x04rest").unwrap();
        let folder = DiffusersFolder::open(dir.path()).unwrap();
        for err in [
            folder.check_weight_formats().unwrap_err(),
            folder.weight_files("vae", WeightVariant::Auto).unwrap_err(),
        ] {
            let err = err.to_string();
            assert!(
                err.contains("diffusion_pytorch_model.bin")
                    && err.contains("`vae`")
                    && err.contains("safe_serialization=True"),
                "{err}"
            );
        }
        std::fs::write(vae.join("diffusion_pytorch_model.safetensors"), b"x").unwrap();
        assert!(folder.check_weight_formats().is_ok());
    }
}
