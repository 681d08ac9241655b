//! A minimal reader for f32 tensors in a safetensors file (8-byte little-endian header size,
//! JSON header, raw little-endian data), so that loading names the file and the tensor in
//! every error.

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

    /// Indexes safetensors bytes; `path` only names the file in errors.
    pub fn parse(bytes: &[u8], path: &Path) -> Result<Self, FidError> {
        let format = |message: String| FidError::Format {
            path: path.to_path_buf(),
            message,
        };
        if bytes.len() < 8 {
            return Err(format("shorter than the 8-byte header size".into()));
        }
        let n = u64::from_le_bytes(bytes[..8].try_into().unwrap_or([0; 8])) as usize;
        let header = bytes
            .get(8..8 + n)
            .ok_or_else(|| format(format!("header of {n} bytes runs past the end")))?;
        let data = &bytes[8 + n..];
        let json: serde_json::Value = serde_json::from_slice(header)
            .map_err(|e| format(format!("header is not JSON: {e}")))?;
        let obj = json
            .as_object()
            .ok_or_else(|| format("header is not a JSON object".into()))?;
        let mut tensors = HashMap::new();
        for (name, info) in obj {
            if name == "__metadata__" {
                continue;
            }
            let dtype = info
                .get("dtype")
                .and_then(|d| d.as_str())
                .unwrap_or("?")
                .to_string();
            let shape: Vec<usize> = info
                .get("shape")
                .and_then(|s| s.as_array())
                .map(|a| {
                    a.iter()
                        .filter_map(|v| v.as_u64().map(|v| v as usize))
                        .collect()
                })
                .ok_or_else(|| format(format!("tensor '{name}' has no shape")))?;
            let offsets: Vec<usize> = info
                .get("data_offsets")
                .and_then(|s| s.as_array())
                .map(|a| {
                    a.iter()
                        .filter_map(|v| v.as_u64().map(|v| v as usize))
                        .collect()
                })
                .ok_or_else(|| format(format!("tensor '{name}' has no data_offsets")))?;
            if offsets.len() != 2 || offsets[0] > offsets[1] || offsets[1] > data.len() {
                return Err(format(format!(
                    "tensor '{name}' has bad data_offsets {offsets:?}"
                )));
            }
            tensors.insert(
                name.clone(),
                (shape, dtype, data[offsets[0]..offsets[1]].to_vec()),
            );
        }
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
