//! Helpers shared by the sd-text parity tests: fixture paths and safetensors reading.

#![allow(dead_code)]

use std::path::PathBuf;

use burn::tensor::{Tensor, TensorData};
use gb_diffusion::lora::tensor_io::view_to_f32;
use safetensors::{Dtype, SafeTensors};

/// `tests/fixtures/sd_text`.
pub fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sd_text")
}

/// Reads one float tensor (any float dtype) as f32 values and shape.
pub fn read_f32(file: &str, name: &str) -> (Vec<f32>, Vec<usize>) {
    let bytes = std::fs::read(fixtures().join(file)).unwrap();
    let st = SafeTensors::deserialize(&bytes).unwrap();
    let view = st.tensor(name).unwrap();
    (view_to_f32(&view).unwrap(), view.shape().to_vec())
}

/// Reads an i64 tensor as rows of its last dimension.
pub fn read_i64_rows(file: &str, name: &str) -> Vec<Vec<i64>> {
    let bytes = std::fs::read(fixtures().join(file)).unwrap();
    let st = SafeTensors::deserialize(&bytes).unwrap();
    let view = st.tensor(name).unwrap();
    assert_eq!(view.dtype(), Dtype::I64);
    let cols = *view.shape().last().unwrap();
    let values: Vec<i64> = view
        .data()
        .chunks_exact(8)
        .map(|c| i64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    values.chunks(cols).map(|r| r.to_vec()).collect()
}

/// Max |a - b| between a Burn tensor and expected values of the same shape.
pub fn max_abs_err<const D: usize>(actual: Tensor<D>, expected: &(Vec<f32>, Vec<usize>)) -> f32 {
    assert_eq!(actual.dims().to_vec(), expected.1, "shape");
    let data: TensorData = actual.into_data();
    let values = data.convert::<f32>().try_to_vec::<f32>().unwrap();
    values
        .iter()
        .zip(&expected.0)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max)
}

/// Copies a fixture model folder into a temp dir, so a test can alter it.
pub fn copy_dir(src: &std::path::Path, dst: &std::path::Path) {
    std::fs::create_dir_all(dst).unwrap();
    for entry in std::fs::read_dir(src).unwrap() {
        let entry = entry.unwrap();
        let to = dst.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &to);
        } else {
            std::fs::copy(entry.path(), &to).unwrap();
        }
    }
}
