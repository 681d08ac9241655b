//! Per-ray compositing weights along chosen pixels: what a depth map hides (a second surface
//! in front, a surface smeared in depth), for diagnosing a field's geometry.

use burn::module::Module;
use gb_core::{f32_values, TensorValuesError};

use super::image::{render_pixels, ImageSettings};
use crate::field::NerfField;
use crate::scene::Camera;

/// One ray's samples and their compositing weights (skipped samples weigh 0).
#[derive(Debug, Clone, PartialEq)]
pub struct RayProfile {
    /// The pixel's continuous coordinates.
    pub pixel: [f32; 2],
    /// Sample z-depths, front to back.
    pub t: Vec<f32>,
    /// Compositing weight of each sample.
    pub weights: Vec<f32>,
    /// Rendered (expected) z-depth.
    pub depth: f32,
    /// Accumulated opacity.
    pub opacity: f32,
}

impl RayProfile {
    /// The weight-averaged spread of the sample depths around the ray's mean depth (the
    /// standard deviation under the normalised weights; 0 for a ray that hits nothing).
    pub fn spread(&self) -> f32 {
        let total: f32 = self.weights.iter().sum();
        if total <= 0.0 {
            return 0.0;
        }
        let mean = self
            .t
            .iter()
            .zip(&self.weights)
            .map(|(t, w)| t * w)
            .sum::<f32>()
            / total;
        let var = self
            .t
            .iter()
            .zip(&self.weights)
            .map(|(t, w)| w * (t - mean) * (t - mean))
            .sum::<f32>()
            / total;
        var.max(0.0).sqrt()
    }

    /// The weight in front of `z * (1 - tol)`, within `z * (1 ± tol)`, and behind it.
    pub fn mass_around(&self, z: f32, tol: f32) -> [f32; 3] {
        let (lo, hi) = (z * (1.0 - tol), z * (1.0 + tol));
        let mut m = [0.0; 3];
        for (t, w) in self.t.iter().zip(&self.weights) {
            let k = if *t < lo {
                0
            } else if *t <= hi {
                1
            } else {
                2
            };
            m[k] += w;
        }
        m
    }
}

/// Renders the rays through `pixels` of `camera` exactly as [`super::render_image`] does
/// (same samples, same skipping, no jitter) and returns each ray's weights.
pub fn render_profiles(
    field: &NerfField,
    camera: &Camera,
    pixels: &[[f32; 2]],
    settings: &ImageSettings,
) -> Result<Vec<RayProfile>, TensorValuesError> {
    let field = field.valid();
    let mut out = Vec::with_capacity(pixels.len());
    for chunk in pixels.chunks(settings.chunk.max(1)) {
        let (r, samples) = render_pixels(&field, camera, chunk, settings)?;
        let weights = f32_values(r.weights.into_data(), "ray weights")?;
        let depth = f32_values(r.depth.into_data(), "rendered depth")?;
        let opacity = f32_values(r.opacity.into_data(), "rendered opacity")?;
        let s = samples.samples;
        for (i, p) in chunk.iter().enumerate() {
            out.push(RayProfile {
                pixel: *p,
                t: samples.t[i * s..(i + 1) * s].to_vec(),
                weights: weights[i * s..(i + 1) * s].to_vec(),
                depth: depth[i],
                opacity: opacity[i],
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn profile(t: &[f32], w: &[f32]) -> RayProfile {
        RayProfile {
            pixel: [0.5, 0.5],
            t: t.to_vec(),
            weights: w.to_vec(),
            depth: 0.0,
            opacity: w.iter().sum(),
        }
    }

    #[test]
    fn spread_is_zero_for_one_sample_and_half_the_gap_for_two_equal_ones() {
        assert_eq!(profile(&[1.0, 2.0, 3.0], &[0.0, 0.7, 0.0]).spread(), 0.0);
        let s = profile(&[1.0, 2.0, 3.0], &[0.4, 0.0, 0.4]).spread();
        assert!((s - 1.0).abs() < 1e-6, "{s}");
        assert_eq!(profile(&[1.0, 2.0], &[0.0, 0.0]).spread(), 0.0);
    }

    #[test]
    fn mass_around_splits_the_weight_in_front_at_and_behind_a_depth() {
        let p = profile(&[1.0, 1.9, 2.05, 3.0], &[0.1, 0.2, 0.3, 0.4]);
        let m = p.mass_around(2.0, 0.05);
        assert_eq!(m, [0.1, 0.5, 0.4]);
    }
}
