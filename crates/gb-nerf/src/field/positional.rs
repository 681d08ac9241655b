//! The sinusoidal positional encoding of the original NeRF.

use burn::tensor::{Tensor, TensorData};

/// Output width of [`positional_encoding`] for 3-D inputs.
pub fn positional_dim(n_freqs: usize) -> usize {
    3 + 6 * n_freqs
}

/// `[x, sin(2^0 pi x), cos(2^0 pi x), ..., sin(2^(F-1) pi x), cos(2^(F-1) pi x)]` for
/// `x: [N, 3]`; output `[N, 3 + 6F]`, laid out as `x`, then per frequency `sin` of the three
/// coordinates followed by their `cos`.
pub fn positional_encoding(x: Tensor<2>, n_freqs: usize) -> Tensor<2> {
    let [n, _] = x.dims();
    if n_freqs == 0 {
        return x;
    }
    let device = x.device();
    let freqs: Vec<f32> = (0..n_freqs)
        .map(|k| std::f32::consts::PI * (1u64 << k) as f32)
        .collect();
    let freqs = Tensor::<3>::from_data(TensorData::new(freqs, [1, n_freqs, 1]), &device);
    let scaled = x.clone().unsqueeze_dim::<3>(1) * freqs; // [N, F, 3]
    let enc = Tensor::cat(vec![scaled.clone().sin(), scaled.cos()], 2); // [N, F, 6]
    Tensor::cat(vec![x, enc.reshape([n, n_freqs * 6])], 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_closed_form() {
        let device = gb_core::BackendKind::Flex.device();
        let x = Tensor::<2>::from_floats([[0.1f32, -0.2, 0.3]], &device);
        let out: Vec<f32> = positional_encoding(x, 2)
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        assert_eq!(out.len(), positional_dim(2));
        let xs = [0.1f32, -0.2, 0.3];
        for k in 0..2 {
            let f = std::f32::consts::PI * (1 << k) as f32;
            for i in 0..3 {
                assert!((out[3 + k * 6 + i] - (f * xs[i]).sin()).abs() < 1e-6);
                assert!((out[3 + k * 6 + 3 + i] - (f * xs[i]).cos()).abs() < 1e-6);
            }
        }
    }
}
