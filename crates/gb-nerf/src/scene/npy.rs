//! `.npy` files of a scene (poses, bounds, depth): float arrays read through the
//! workspace's one reader ([`gb_core::npy`]), errors naming the file.

use super::SceneError;
use std::path::Path;

pub use gb_core::npy::{encode_f32, encode_f64, NpyArray};

/// Reads a float `.npy` file (`f4`/`f8`, either byte order, C or Fortran order) into C
/// order. Integer and bool arrays are refused.
pub fn read_float_array(path: &Path) -> Result<NpyArray, SceneError> {
    let bytes = std::fs::read(path).map_err(|e| SceneError::io(path, e))?;
    let npy_err = |reason: String| SceneError::Npy {
        path: path.to_path_buf(),
        reason,
    };
    let array = gb_core::npy::read_npy(&bytes).map_err(|e| npy_err(e.to_string()))?;
    if array.kind != gb_core::npy::NpyKind::Float {
        return Err(npy_err(format!(
            "dtype {} is not float32 or float64",
            array.dtype
        )));
    }
    Ok(array)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f32_round_trip() {
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
    }

    #[test]
    fn garbage_and_integers_are_errors_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("poses_bounds.npy");
        std::fs::write(&p, b"nonsense").unwrap();
        let e = read_float_array(&p).unwrap_err().to_string();
        assert!(e.contains("poses_bounds.npy"), "{e}");
        let ints = gb_core::npy::encode_raw(
            "{'descr': '<i4', 'fortran_order': False, 'shape': (1,), }",
            &7i32.to_le_bytes(),
        );
        std::fs::write(&p, ints).unwrap();
        let e = read_float_array(&p).unwrap_err().to_string();
        assert!(
            e.contains("poses_bounds.npy") && e.contains("<i4 is not float32"),
            "{e}"
        );
    }
}
