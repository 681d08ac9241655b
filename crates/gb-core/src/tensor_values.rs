//! Reading a tensor's values back to the host: a dtype surprise is an error that says what
//! was expected, never an empty vector that silently stands in for the values.

use burn::tensor::TensorData;

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
