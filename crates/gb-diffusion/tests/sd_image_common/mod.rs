//! Helpers shared by the sd-image parity tests (fixtures from
//! tools/parity/make_image_fixtures.py).

#![allow(dead_code)]

use std::path::PathBuf;

use burn::tensor::{Device, Tensor, TensorData};
use safetensors::SafeTensors;

/// `tests/fixtures/sd_image/<name>`.
pub fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/sd_image")
        .join(name)
}

/// Reads tensor `key` of a fixture file as f32 values and shape.
pub fn read_f32(file: &str, key: &str) -> (Vec<f32>, Vec<usize>) {
    let bytes = std::fs::read(fixture(file)).expect("fixture file");
    let st = SafeTensors::deserialize(&bytes).expect("safetensors");
    let view = st.tensor(key).unwrap_or_else(|_| panic!("{key} in {file}"));
    let shape = view.shape().to_vec();
    let values = match view.dtype() {
        safetensors::Dtype::F32 => view
            .data()
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect(),
        safetensors::Dtype::I64 => view
            .data()
            .chunks_exact(8)
            .map(|c| i64::from_le_bytes(c.try_into().unwrap()) as f32)
            .collect(),
        other => panic!("unexpected dtype {other:?} for {key}"),
    };
    (values, shape)
}

/// Reads a 4-D f32 fixture tensor onto `device`.
pub fn tensor4(file: &str, key: &str, device: &Device) -> Tensor<4> {
    let (v, s) = read_f32(file, key);
    Tensor::from_data(TensorData::new(v, [s[0], s[1], s[2], s[3]]), device)
}

/// Reads a 3-D f32 fixture tensor onto `device`.
pub fn tensor3(file: &str, key: &str, device: &Device) -> Tensor<3> {
    let (v, s) = read_f32(file, key);
    Tensor::from_data(TensorData::new(v, [s[0], s[1], s[2]]), device)
}

/// Maximum absolute difference between a tensor and expected values (shape checked).
pub fn max_abs_err<const D: usize>(got: Tensor<D>, want: &[f32], want_shape: &[usize]) -> f32 {
    assert_eq!(got.dims().as_slice(), want_shape, "shape");
    let got: Vec<f32> = got.into_data().convert::<f32>().try_to_vec().unwrap();
    got.iter()
        .zip(want)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max)
}
