//! Seeded Gaussian noise generated on the host, so that the same seed gives the same noise
//! (and therefore the same gradient) on every backend.

use burn::tensor::{Device, Tensor, TensorData};
use rand::Rng;

/// Standard normal samples by the Box-Muller transform (pairs of uniforms in (0, 1]).
pub fn standard_normal(rng: &mut impl Rng, count: usize) -> Vec<f32> {
    let mut out = Vec::with_capacity(count + 1);
    while out.len() < count {
        let u1: f64 = 1.0 - rng.random::<f64>();
        let u2: f64 = rng.random::<f64>();
        let radius = (-2.0 * u1.ln()).sqrt();
        let angle = std::f64::consts::TAU * u2;
        out.push((radius * angle.cos()) as f32);
        out.push((radius * angle.sin()) as f32);
    }
    out.truncate(count);
    out
}

/// A `[B, C, H, W]` tensor of standard normal noise on `device`.
pub fn normal_tensor(rng: &mut impl Rng, shape: [usize; 4], device: &Device) -> Tensor<4> {
    let values = standard_normal(rng, shape.iter().product());
    Tensor::from_data(TensorData::new(values, shape), device)
}
