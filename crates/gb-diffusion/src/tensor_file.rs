//! Small safetensors helpers for the parity CLI: read named f32 / i64 tensors, write f32
//! and i64 tensors.

use std::path::{Path, PathBuf};

use safetensors::tensor::TensorView;
use safetensors::{Dtype, SafeTensors};

use crate::lora::tensor_io::{f32_bytes, view_to_f32};

/// Error reading or writing a tensor file.
#[derive(Debug, thiserror::Error)]
pub enum TensorFileError {
    /// IO or format error.
    #[error("tensor file {path}: {message}")]
    File {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The named tensor is absent or of the wrong dtype.
    #[error("tensor file {path}: tensor `{name}`: {message}")]
    Tensor {
        /// The file.
        path: PathBuf,
        /// The tensor name.
        name: String,
        /// What is wrong.
        message: String,
    },
}

/// A tensor to write.
#[derive(Debug, Clone)]
pub enum TensorOut {
    /// f32 values and shape.
    F32(Vec<f32>, Vec<usize>),
    /// i64 values and shape.
    I64(Vec<i64>, Vec<usize>),
}

fn with_tensor<T>(
    path: &Path,
    name: &str,
    f: impl FnOnce(&TensorView<'_>) -> Result<T, String>,
) -> Result<T, TensorFileError> {
    let bytes = std::fs::read(path).map_err(|e| TensorFileError::File {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let st = SafeTensors::deserialize(&bytes).map_err(|e| TensorFileError::File {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let view = st.tensor(name).map_err(|e| TensorFileError::Tensor {
        path: path.to_path_buf(),
        name: name.to_string(),
        message: e.to_string(),
    })?;
    f(&view).map_err(|message| TensorFileError::Tensor {
        path: path.to_path_buf(),
        name: name.to_string(),
        message,
    })
}

/// Reads float tensor `name` (f32/f16/bf16/f64) as f32 values and its shape.
pub fn read_f32(path: &Path, name: &str) -> Result<(Vec<f32>, Vec<usize>), TensorFileError> {
    with_tensor(path, name, |v| {
        view_to_f32(v)
            .map(|vals| (vals, v.shape().to_vec()))
            .ok_or_else(|| format!("dtype {:?} is not a float type", v.dtype()))
    })
}

/// Reads integer tensor `name` (i64 or i32) as i64 values and its shape.
pub fn read_i64(path: &Path, name: &str) -> Result<(Vec<i64>, Vec<usize>), TensorFileError> {
    with_tensor(path, name, |v| {
        let vals: Vec<i64> = match v.dtype() {
            Dtype::I64 => v
                .data()
                .chunks_exact(8)
                .map(|c| i64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
                .collect(),
            Dtype::I32 => v
                .data()
                .chunks_exact(4)
                .map(|c| i32::from_le_bytes([c[0], c[1], c[2], c[3]]) as i64)
                .collect(),
            other => return Err(format!("dtype {other:?} is not i64/i32")),
        };
        Ok((vals, v.shape().to_vec()))
    })
}

/// Writes `tensors` to `path` (atomically).
pub fn write_tensors(path: &Path, tensors: &[(&str, TensorOut)]) -> Result<(), TensorFileError> {
    let err = |message: String| TensorFileError::File {
        path: path.to_path_buf(),
        message,
    };
    let owned: Vec<(String, Dtype, Vec<usize>, Vec<u8>)> = tensors
        .iter()
        .map(|(name, t)| match t {
            TensorOut::F32(v, s) => (name.to_string(), Dtype::F32, s.clone(), f32_bytes(v)),
            TensorOut::I64(v, s) => (
                name.to_string(),
                Dtype::I64,
                s.clone(),
                v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
        })
        .collect();
    let views = owned
        .iter()
        .map(|(n, d, s, b)| {
            TensorView::new(*d, s.clone(), b)
                .map(|v| (n.clone(), v))
                .map_err(|e| err(format!("tensor {n}: {e}")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let bytes = safetensors::serialize(views, None).map_err(|e| err(e.to_string()))?;
    gb_core::write_atomic(path, &bytes).map_err(|e| err(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_f32_and_i64() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.safetensors");
        write_tensors(
            &p,
            &[
                ("a", TensorOut::F32(vec![1.5, -2.0], vec![2])),
                ("ids", TensorOut::I64(vec![1, 49407, 3, 4], vec![2, 2])),
            ],
        )
        .unwrap();
        assert_eq!(read_f32(&p, "a").unwrap(), (vec![1.5, -2.0], vec![2]));
        assert_eq!(read_i64(&p, "ids").unwrap().0, vec![1, 49407, 3, 4]);
        let err = read_f32(&p, "ids").unwrap_err().to_string();
        assert!(err.contains("ids"), "{err}");
        let err = read_f32(&p, "missing").unwrap_err().to_string();
        assert!(err.contains("missing"), "{err}");
    }
}
