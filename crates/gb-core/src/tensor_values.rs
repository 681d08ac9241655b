//! Reading a tensor's values back to the host: a dtype surprise is an error that says what
//! was expected, never an empty vector that silently stands in for the values.
//!
//! Each read waits for the device to finish what it was given, so the hot loops read through
//! [`read_f32`], which counts the reads made on the calling thread ([`device_reads`]): tests
//! hold a training step to its budget of reads.

use std::cell::Cell;

use burn::tensor::{Tensor, TensorData};

thread_local! {
    static READS: Cell<usize> = const { Cell::new(0) };
}

/// Device-to-host reads made through [`read_f32`] on this thread so far.
pub fn device_reads() -> usize {
    READS.with(Cell::get)
}

/// Reads `tensor` back to the host as `f32` values: one device read, counted.
pub fn read_f32<const D: usize>(
    tensor: Tensor<D>,
    what: &'static str,
) -> Result<Vec<f32>, TensorValuesError> {
    READS.with(|r| r.set(r.get() + 1));
    f32_values(tensor.into_data(), what)
}

/// A tensor's values were not of the expected element type.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{what}: expected {expected} values, the tensor holds {found}")]
pub struct TensorValuesError {
    /// What the values are (for example "rendered depth").
    pub what: &'static str,
    /// The element type expected.
    pub expected: &'static str,
    /// The element type found.
    pub found: String,
}

/// The values of `data` as `f32`; `what` names them in the error.
pub fn f32_values(data: TensorData, what: &'static str) -> Result<Vec<f32>, TensorValuesError> {
    let found = format!("{:?}", data.dtype());
    data.try_into_vec::<f32>().map_err(|_| TensorValuesError {
        what,
        expected: "f32",
        found,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f32_data_is_read_and_other_dtypes_are_named_in_the_error() {
        let ok = f32_values(TensorData::new(vec![1.5f32, -2.0], [2]), "depth").unwrap();
        assert_eq!(ok, vec![1.5, -2.0]);
        let err = f32_values(TensorData::new(vec![1i32, 2, 3], [3]), "depth").unwrap_err();
        assert_eq!(err.what, "depth");
        assert_eq!(err.expected, "f32");
        assert_eq!(err.found, "I32");
        assert_eq!(
            err.to_string(),
            "depth: expected f32 values, the tensor holds I32"
        );
        let err = f32_values(TensorData::new(vec![0.5f64], [1]), "sigma").unwrap_err();
        assert_eq!(err.found, "F64");
    }
}
