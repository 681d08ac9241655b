//! The workspace's one `.npy` reader and writer, on top of `npyz` behind
//! [`check_npy_header`]: any plain numeric dtype (float, integer, bool; either byte order),
//! C or Fortran order, read as C-order `f64`; C-order `f32`/`f64` arrays encoded to bytes.
//! The scene loader (poses, bounds, depth), the DIODE reader and the disparity maps of the
//! metrics all read through [`read_npy`] and check the kind and shape they need.

use crate::check_npy_header;
use npyz::WriterBuilder;

/// Why `.npy` bytes could not be read.
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
pub enum NpyError {
    /// The header would make `npyz` panic or allocate what it declares.
    #[error("bad .npy header: {0}")]
    Header(String),
    /// Not a `.npy` file, or a header `npyz` rejects.
    #[error("not a .npy file: {0}")]
    Format(String),
    /// A dtype that is not one plain number (records, strings, complex, ...).
    #[error("unsupported dtype {0}")]
    Dtype(String),
    /// The data section is short or unreadable.
    #[error("cannot read data: {0}")]
    Data(String),
}

/// What a `.npy` file's values were before they became `f64`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NpyKind {
    /// `f4` or `f8`.
    Float,
    /// A signed or unsigned integer of 1 to 8 bytes.
    Int,
    /// `b1`.
    Bool,
}

/// A numeric array read from a `.npy` file, in C (row-major) order.
#[derive(Debug, Clone, PartialEq)]
pub struct NpyArray {
    /// The shape.
    pub shape: Vec<u64>,
    /// `shape.product()` values, row-major.
    pub data: Vec<f64>,
    /// What the values were stored as.
    pub kind: NpyKind,
    /// The stored dtype, as numpy writes it (`<f4`, `>i8`, `|b1`, ...).
    pub dtype: String,
}

/// Reads a whole `.npy` file's bytes.
pub fn read_npy(bytes: &[u8]) -> Result<NpyArray, NpyError> {
    check_npy_header(bytes).map_err(NpyError::Header)?;
    let file = npyz::NpyFile::new(bytes).map_err(|e| NpyError::Format(e.to_string()))?;
    let shape = file.shape().to_vec();
    let order = file.order();
    let (type_char, size, dtype) = match file.dtype() {
        npyz::DType::Plain(ts) => (ts.type_char(), ts.size_field(), ts.to_string()),
        other => return Err(NpyError::Dtype(other.descr())),
    };
    let data = |e: std::io::Error| NpyError::Data(e.to_string());
    // every integer type reads through `as f64`: exact up to 2^53, the nearest value above
    macro_rules! values {
        ($t:ty) => {
            file.into_vec::<$t>()
                .map_err(data)?
                .into_iter()
                .map(|v| v as f64)
                .collect()
        };
    }
    use npyz::TypeChar as T;
    let (kind, values): (NpyKind, Vec<f64>) = match (type_char, size) {
        (T::Float, 8) => (NpyKind::Float, file.into_vec::<f64>().map_err(data)?),
        (T::Float, 4) => (NpyKind::Float, values!(f32)),
        (T::Bool, 1) => (
            NpyKind::Bool,
            file.into_vec::<bool>()
                .map_err(data)?
                .into_iter()
                .map(|b| f64::from(u8::from(b)))
                .collect(),
        ),
        (T::Uint, 1) => (NpyKind::Int, values!(u8)),
        (T::Uint, 2) => (NpyKind::Int, values!(u16)),
        (T::Uint, 4) => (NpyKind::Int, values!(u32)),
        (T::Uint, 8) => (NpyKind::Int, values!(u64)),
        (T::Int, 1) => (NpyKind::Int, values!(i8)),
        (T::Int, 2) => (NpyKind::Int, values!(i16)),
        (T::Int, 4) => (NpyKind::Int, values!(i32)),
        (T::Int, 8) => (NpyKind::Int, values!(i64)),
        _ => return Err(NpyError::Dtype(dtype)),
    };
    // npyz reads exactly the shape's count or fails; say so rather than reorder a short buffer
    let count = shape.iter().try_fold(1u64, |n, &d| n.checked_mul(d));
    if count != Some(values.len() as u64) {
        return Err(NpyError::Data(format!(
            "{} values for shape {shape:?}",
            values.len()
        )));
    }
    let data = match order {
        npyz::Order::C => values,
        npyz::Order::Fortran => fortran_to_c(&shape, &values),
    };
    Ok(NpyArray {
        shape,
        data,
        kind,
        dtype,
    })
}

/// Reorders a Fortran-order (first axis fastest) buffer of `shape` to C order. A buffer
/// shorter than the shape declares reads as zeros past its end ([`read_npy`] refuses one
/// before it gets here).
fn fortran_to_c<V: Copy + Default>(shape: &[u64], data: &[V]) -> Vec<V> {
    let dims: Vec<usize> = shape.iter().map(|&d| d as usize).collect();
    let mut out = vec![V::default(); data.len()];
    let mut idx = vec![0usize; dims.len()];
    for (c_pos, slot) in out.iter_mut().enumerate() {
        // the multi-index of c_pos (last axis fastest)
        let mut rem = c_pos;
        for a in (0..dims.len()).rev() {
            idx[a] = rem % dims[a].max(1);
            rem /= dims[a].max(1);
        }
        // its Fortran offset (first axis fastest)
        let (mut f_pos, mut stride) = (0usize, 1usize);
        for (a, &d) in dims.iter().enumerate() {
            f_pos += idx[a] * stride;
            stride = stride.saturating_mul(d);
        }
        *slot = data.get(f_pos).copied().unwrap_or_default();
    }
    out
}

/// Encodes a C-order array as `.npy` bytes, in numpy's default dtype of `T`.
fn encode<T: npyz::AutoSerialize + Copy>(shape: &[u64], data: &[T]) -> std::io::Result<Vec<u8>> {
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

/// Encodes a C-order `f64` array as `.npy` bytes (`<f8`).
pub fn encode_f64(shape: &[u64], data: &[f64]) -> std::io::Result<Vec<u8>> {
    encode(shape, data)
}

/// Encodes a C-order `f32` array as `.npy` bytes (`<f4`).
pub fn encode_f32(shape: &[u64], data: &[f32]) -> std::io::Result<Vec<u8>> {
    encode(shape, data)
}

/// The bytes of a version 1.0 `.npy` file with the header dictionary `dict` (padded as
/// numpy pads it) and the raw `data` after it, unchecked: for fixtures and tests that need a
/// header of their own (another dtype, Fortran order, a shape the data does not fill).
pub fn encode_raw(dict: &str, data: &[u8]) -> Vec<u8> {
    let mut text = dict.to_string();
    while !(10 + text.len() + 1).is_multiple_of(64) {
        text.push(' ');
    }
    text.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend((text.len() as u16).to_le_bytes());
    out.extend(text.bytes());
    out.extend(data);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn npy(dict: &str, data: &[u8]) -> Vec<u8> {
        encode_raw(dict, data)
    }

    #[test]
    fn floats_round_trip_in_c_order() {
        let a = read_npy(&encode_f32(&[2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.5]).unwrap()).unwrap();
        assert_eq!(a.shape, vec![2, 3]);
        assert_eq!(a.data, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.5]);
        assert_eq!((a.kind, a.dtype.as_str()), (NpyKind::Float, "<f4"));
        let b = read_npy(&encode_f64(&[2], &[0.1, -7.25]).unwrap()).unwrap();
        assert_eq!((b.data, b.kind), (vec![0.1, -7.25], NpyKind::Float));
    }

    #[test]
    fn fortran_order_is_reordered() {
        // the Fortran buffer of [[1, 2, 3], [4, 5, 6]] is 1, 4, 2, 5, 3, 6
        let data: Vec<u8> = [1.0f64, 4.0, 2.0, 5.0, 3.0, 6.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let dict = "{'descr': '<f8', 'fortran_order': True, 'shape': (2, 3), }";
        let a = read_npy(&npy(dict, &data)).unwrap();
        assert_eq!(a.data, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        // a buffer shorter than its shape reads as zeros past its end
        assert_eq!(fortran_to_c(&[2, 2], &[1u8, 3]), vec![1, 0]);
    }

    #[test]
    fn integers_and_bools_read_as_their_values() {
        let data: Vec<u8> = [-3i16, 700].iter().flat_map(|v| v.to_be_bytes()).collect();
        let a = read_npy(&npy(
            "{'descr': '>i2', 'fortran_order': False, 'shape': (2,), }",
            &data,
        ))
        .unwrap();
        assert_eq!((a.data, a.kind), (vec![-3.0, 700.0], NpyKind::Int));
        let b = read_npy(&npy(
            "{'descr': '|b1', 'fortran_order': False, 'shape': (3,), }",
            &[1, 0, 1],
        ))
        .unwrap();
        assert_eq!((b.data, b.kind), (vec![1.0, 0.0, 1.0], NpyKind::Bool));
    }

    #[test]
    fn each_failure_says_what_is_wrong() {
        let e = read_npy(b"nonsense").unwrap_err();
        assert!(matches!(e, NpyError::Format(_)), "{e}");
        let complex = npy(
            "{'descr': '<c8', 'fortran_order': False, 'shape': (1,), }",
            &[0; 8],
        );
        let e = read_npy(&complex).unwrap_err();
        assert_eq!(e.to_string(), "unsupported dtype <c8");
        let short = npy(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (4,), }",
            &[0; 8],
        );
        assert!(matches!(read_npy(&short).unwrap_err(), NpyError::Data(_)));
        let huge = npy(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (18446744073709551615, 2), }",
            &[],
        );
        assert!(matches!(read_npy(&huge).unwrap_err(), NpyError::Header(_)));
    }
}
