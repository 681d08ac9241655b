//! [`load_module`]: apply one component's `*.safetensors` files to a Burn module.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::store::{
    ApplyError, FloatCastAdapter, KeyRemapper, ModuleAdapter, ModuleSnapshot, PyTorchToBurnAdapter,
    SafetensorsStore,
};
use burn::tensor::DType;

use super::{CheckpointError, KeymapSection};

/// What a successful [`load_module`] did.
#[derive(Debug, Clone, Default)]
pub struct LoadReport {
    /// Module parameter paths that were loaded.
    pub applied: Vec<String>,
    /// Checkpoint keys (after remapping) that no module parameter used and that the keymap
    /// section does not list as ignored. Logged as a warning.
    pub unused: Vec<String>,
}

/// Loads `files` (safetensors, possibly sharded, any float dtype) into `module`.
///
/// Keys are remapped with `section`'s rules; linear weights are transposed and norm
/// `weight`/`bias` renamed by burn's `PyTorchToBurnAdapter`; f16/bf16 tensors are cast to
/// f32. Every parameter of the module must be found in exactly the expected shape,
/// otherwise the error names the tensor, the expected shape and the file(s).
pub fn load_module<M: Module>(
    mut module: M,
    files: &[PathBuf],
    section: &KeymapSection,
) -> Result<(M, LoadReport), CheckpointError> {
    let remapper = remapper(section)?;
    let mut applied: BTreeSet<String> = BTreeSet::new();
    let mut unused_everywhere: Option<BTreeSet<String>> = None;
    for file in files {
        if !file.is_file() {
            return Err(CheckpointError::MissingFile {
                path: file.clone(),
                what: format!("safetensors weights of {}", section.name),
            });
        }
        super::header::check_file_layout(file).map_err(|message| CheckpointError::Weights {
            path: file.clone(),
            message,
        })?;
        let mut store = SafetensorsStore::from_file(file.clone())
            .with_from_adapter(adapter())
            .remap(remapper.clone())
            .allow_partial(true)
            .validate(false);
        let result = module
            .load_from(&mut store)
            .map_err(|e| CheckpointError::Weights {
                path: file.clone(),
                message: e.to_string(),
            })?;
        if let Some(err) = result.errors.first() {
            return Err(apply_error(err, file));
        }
        applied.extend(result.applied.iter().cloned());
        let unused: BTreeSet<String> = result.unused.iter().cloned().collect();
        unused_everywhere = Some(match unused_everywhere {
            None => unused,
            Some(prev) => prev.intersection(&unused).cloned().collect(),
        });
    }
    check_complete(&module, &applied, files, section)?;
    let mut unused = Vec::new();
    for key in unused_everywhere.unwrap_or_default() {
        if !section.is_ignored(&key)? {
            unused.push(key);
        }
    }
    if !unused.is_empty() {
        tracing::warn!(
            component = section.name,
            "{} checkpoint tensors unused: {:?}",
            unused.len(),
            unused
        );
    }
    Ok((
        module,
        LoadReport {
            applied: applied.into_iter().collect(),
            unused,
        },
    ))
}

/// The adapter chain used for every diffusers/transformers file.
fn adapter() -> impl ModuleAdapter + 'static {
    PyTorchToBurnAdapter.chain(FloatCastAdapter::to(DType::F32))
}

fn remapper(section: &KeymapSection) -> Result<KeyRemapper, CheckpointError> {
    KeyRemapper::from_patterns(section.rules.to_vec()).map_err(|e| CheckpointError::Keymap {
        section: section.name.to_string(),
        pattern: format!("{:?}", section.rules),
        message: e.to_string(),
    })
}

/// Fails on the first module parameter that no file provided.
fn check_complete<M: Module>(
    module: &M,
    applied: &BTreeSet<String>,
    files: &[PathBuf],
    section: &KeymapSection,
) -> Result<(), CheckpointError> {
    let expected = module.collect(None, None, false);
    for tensor in expected {
        if !applied.contains(&tensor.name) {
            return Err(CheckpointError::MissingTensor {
                tensor: pytorch_key(&tensor.name),
                module_path: tensor.name.clone(),
                expected: tensor.shape.iter().copied().collect(),
                files: describe_files(files, section),
            });
        }
    }
    Ok(())
}

/// The PyTorch-style key of a Burn parameter path (norm `gamma`/`beta` are `weight`/`bias`).
fn pytorch_key(path: &str) -> String {
    if let Some(stem) = path.strip_suffix(".gamma") {
        format!("{stem}.weight")
    } else if let Some(stem) = path.strip_suffix(".beta") {
        format!("{stem}.bias")
    } else {
        path.to_string()
    }
}

fn describe_files(files: &[PathBuf], section: &KeymapSection) -> String {
    if files.is_empty() {
        return format!("(no weight files given for {})", section.name);
    }
    files
        .iter()
        .map(|f| f.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

fn apply_error(err: &ApplyError, file: &Path) -> CheckpointError {
    match err {
        ApplyError::ShapeMismatch {
            path,
            expected,
            found,
        } => CheckpointError::ShapeMismatch {
            tensor: pytorch_key(path),
            file: file.to_path_buf(),
            expected: expected.iter().copied().collect(),
            found: found.iter().copied().collect(),
        },
        ApplyError::DTypeMismatch {
            path,
            expected,
            found,
        } => CheckpointError::Tensor {
            tensor: pytorch_key(path),
            file: file.to_path_buf(),
            message: format!("dtype {found:?} where {expected:?} was expected"),
        },
        ApplyError::AdapterError { path, message } | ApplyError::LoadError { path, message } => {
            CheckpointError::Tensor {
                tensor: pytorch_key(path),
                file: file.to_path_buf(),
                message: message.clone(),
            }
        }
    }
}
