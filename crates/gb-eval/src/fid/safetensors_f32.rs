//! f32 tensors of a safetensors file (read with the `safetensors` crate), indexed so that
//! loading names the file and the tensor in every error.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::error::FidError;

/// The tensors of one safetensors file, as f32.
#[derive(Debug)]
pub struct F32Tensors {
    path: PathBuf,
    tensors: HashMap<String, (Vec<usize>, String, Vec<u8>)>,
}

impl F32Tensors {
    /// Reads and indexes a safetensors file.
    pub fn read(path: &Path) -> Result<Self, FidError> {
        let bytes = std::fs::read(path).map_err(|source| FidError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&bytes, path)
    }

    /// Indexes safetensors bytes (parsed by the `safetensors` crate, which checks the
    /// header, the offsets and the dtype sizes); `path` only names the file in errors.
    pub fn parse(bytes: &[u8], path: &Path) -> Result<Self, FidError> {
        let parsed =
            safetensors::SafeTensors::deserialize(bytes).map_err(|e| FidError::Format {
                path: path.to_path_buf(),
                message: e.to_string(),
            })?;
        let tensors = parsed
            .tensors()
            .into_iter()
            .map(|(name, view)| {
                let dtype = format!("{:?}", view.dtype());
                (name, (view.shape().to_vec(), dtype, view.data().to_vec()))
            })
            .collect();
        Ok(Self {
            path: path.to_path_buf(),
            tensors,
        })
    }

    /// The names of all tensors.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.tensors.keys().map(String::as_str)
    }

    /// The f32 values of `name`, checking its shape.
    pub fn get(&self, name: &str, expected: &[usize]) -> Result<Vec<f32>, FidError> {
        let (shape, dtype, raw) =
            self.tensors
                .get(name)
                .ok_or_else(|| FidError::MissingTensor {
                    path: self.path.clone(),
                    tensor: name.to_string(),
                })?;
        if shape.as_slice() != expected
            || dtype != "F32"
            || raw.len() != 4 * expected.iter().product::<usize>()
        {
            return Err(FidError::BadTensor {
                path: self.path.clone(),
                tensor: name.to_string(),
                got: shape.clone(),
                dtype: dtype.clone(),
                expected: expected.to_vec(),
            });
        }
        Ok(raw
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect())
    }

    /// The f32 values and shape of `name`, whatever its shape.
    pub fn get_any(&self, name: &str) -> Result<(Vec<usize>, Vec<f32>), FidError> {
        let shape = self
            .tensors
            .get(name)
            .map(|(s, _, _)| s.clone())
            .ok_or_else(|| FidError::MissingTensor {
                path: self.path.clone(),
                tensor: name.to_string(),
            })?;
        let values = self.get(name, &shape)?;
        Ok((shape, values))
    }
}
