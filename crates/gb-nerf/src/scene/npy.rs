//! Small `.npy` helpers on top of `npyz`: read a float array (f32 or f64, C or Fortran
//! order) as C-order `f64`, and encode C-order `f32`/`f64` arrays to bytes.
// Component loops over xyz / matrix entries read clearer with indices than with zips.
#![allow(clippy::needless_range_loop)]

use super::SceneError;
use npyz::WriterBuilder;
use std::path::Path;

/// A float array read from a `.npy` file, in C (row-major) order.
#[derive(Debug, Clone, PartialEq)]
pub struct NpyArray {
    /// The shape.
    pub shape: Vec<u64>,
    /// `shape.product()` values, row-major.
    pub data: Vec<f64>,
}

/// Reads a float `.npy` file (`<f4`/`<f8`, big-endian too) into C order.
pub fn read_float_array(path: &Path) -> Result<NpyArray, SceneError> {
    let bytes = std::fs::read(path).map_err(|e| SceneError::io(path, e))?;
    let npy_err = |reason: String| SceneError::Npy {
        path: path.to_path_buf(),
        reason,
    };
    gb_core::check_npy_header(&bytes).map_err(npy_err)?;
    let file = npyz::NpyFile::new(&bytes[..]).map_err(|e| npy_err(e.to_string()))?;
    let shape = file.shape().to_vec();
    let order = file.order();
    let dtype = file.dtype();
    let (is_float, size) = match &dtype {
        npyz::DType::Plain(ts) => (ts.type_char() == npyz::TypeChar::Float, ts.size_field()),
        other => return Err(npy_err(format!("unsupported dtype {}", other.descr()))),
    };
    let data: Vec<f64> = match (is_float, size) {
        (true, 8) => file.into_vec::<f64>().map_err(|e| npy_err(e.to_string()))?,
        (true, 4) => file
            .into_vec::<f32>()
            .map_err(|e| npy_err(e.to_string()))?
            .into_iter()
            .map(f64::from)
            .collect(),
        _ => {
            return Err(npy_err(format!(
                "dtype {} is not float32 or float64",
                dtype.descr()
            )))
        }
    };
    let data = match order {
        npyz::Order::C => data,
        npyz::Order::Fortran => fortran_to_c(&shape, &data),
    };
    Ok(NpyArray { shape, data })
}

/// Reorders a Fortran-order buffer to C order.
fn fortran_to_c(shape: &[u64], data: &[f64]) -> Vec<f64> {
    let dims: Vec<usize> = shape.iter().map(|&d| d as usize).collect();
    let n = data.len();
    let mut out = vec![0.0; n];
    let mut idx = vec![0usize; dims.len()];
    for (c_pos, slot) in out.iter_mut().enumerate() {
        // decompose c_pos into a multi-index (last axis fastest)
        let mut rem = c_pos;
        for a in (0..dims.len()).rev() {
            idx[a] = rem % dims[a].max(1);
            rem /= dims[a].max(1);
        }
        // Fortran offset: first axis fastest
        let mut f_pos = 0;
        let mut stride = 1;
        for a in 0..dims.len() {
            f_pos += idx[a] * stride;
            stride *= dims[a];
        }
        *slot = data[f_pos];
    }
    out
}

/// Encodes a C-order `f64` array as `.npy` bytes (`<f8`).
pub fn encode_f64(shape: &[u64], data: &[f64]) -> std::io::Result<Vec<u8>> {
    let mut buf = Vec::new();
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(shape)
        .writer(&mut buf)
        .begin_nd()?;
    w.extend(data.iter().copied())?;
    w.finish()?;
    Ok(buf)
}

/// Encodes a C-order `f32` array as `.npy` bytes (`<f4`).
pub fn encode_f32(shape: &[u64], data: &[f32]) -> std::io::Result<Vec<u8>> {
    let mut buf = Vec::new();
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(shape)
        .writer(&mut buf)
        .begin_nd()?;
    w.extend(data.iter().copied())?;
    w.finish()?;
    Ok(buf)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f32_round_trip_and_fortran_reorder() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.npy");
        std::fs::write(
            &p,
            encode_f32(&[2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap(),
        )
        .unwrap();
        let a = read_float_array(&p).unwrap();
        assert_eq!(a.shape, vec![2, 3]);
        assert_eq!(a.data, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        // Fortran buffer of [[1,2,3],[4,5,6]] is 1,4,2,5,3,6
        assert_eq!(
            fortran_to_c(&[2, 3], &[1.0, 4.0, 2.0, 5.0, 3.0, 6.0]),
            vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
        );
    }

    #[test]
    fn garbage_is_an_error_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("poses_bounds.npy");
        std::fs::write(&p, b"nonsense").unwrap();
        let e = read_float_array(&p).unwrap_err().to_string();
        assert!(e.contains("poses_bounds.npy"), "{e}");
    }
}
