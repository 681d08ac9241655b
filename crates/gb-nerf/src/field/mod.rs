//! Radiance fields: the instant-ngp hash-grid field and the vanilla positional-encoding
//! NeRF MLP, behind one [`NerfField`] module chosen by [`FieldConfig`].
//!
//! A field takes points in its normalised coordinates `[0, 1]^3` (see
//! [`crate::sampler::SceneSpace`]) and unit world-space view directions, and returns the
//! density `sigma >= 0` (per unit of world length) and the colour in `[0, 1]`.

pub mod hash_grid;
pub mod mlp;
pub mod positional;

use burn::module::Module;
use burn::tensor::activation::sigmoid;
use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};

pub use hash_grid::{hash_lookups, HashGrid, HashGridConfig, HashLookups, LookupSite};
pub use mlp::Mlp;
pub use positional::{positional_dim, positional_encoding};

/// The largest raw density logit; `sigma = exp(clamp(raw, -15, 15))` ("truncated exp").
const MAX_LOG_DENSITY: f32 = 15.0;

fn is_zero(v: &f32) -> bool {
    *v == 0.0
}

/// Which field to build, with its sizes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FieldConfig {
    /// instant-ngp: hash encoding, then a density MLP and a colour MLP.
    Hash {
        /// The hash encoding.
        grid: HashGridConfig,
        /// Hidden width of both MLPs (reference: 64).
        hidden: usize,
        /// Geometry features passed from the density to the colour MLP (reference: 15).
        geo_features: usize,
        /// Positional-encoding frequencies of the view direction.
        dir_freqs: usize,
        /// Added to the raw density logit, `sigma = exp(raw + bias)` (TOML `density_bias`,
        /// default 0). A negative bias starts the field nearly empty (the raw logit starts
        /// near 0, so `sigma` starts near `exp(bias)` everywhere) for the occupancy grid to
        /// skip; nerfacc's instant-ngp example uses -1.
        #[serde(default, skip_serializing_if = "is_zero")]
        density_bias: f32,
    },
    /// The original NeRF MLP on positionally encoded inputs.
    Vanilla {
        /// Frequencies of the position encoding (reference: 10).
        pos_freqs: usize,
        /// Frequencies of the direction encoding (reference: 4).
        dir_freqs: usize,
        /// Hidden width (reference: 256).
        width: usize,
        /// Linear layers of the density trunk (reference: 8, skip at 4).
        depth: usize,
    },
}

impl FieldConfig {
    /// Builds a randomly initialised field on `device`.
    pub fn init(&self, device: &Device) -> NerfField {
        match self {
            FieldConfig::Hash {
                grid,
                hidden,
                geo_features,
                dir_freqs,
                ..
            } => NerfField {
                grid: Some(grid.init(device)),
                density_net: Mlp::new(
                    grid.output_dim(),
                    *hidden,
                    1 + geo_features,
                    2,
                    None,
                    device,
                ),
                color_net: Mlp::new(
                    geo_features + positional_dim(*dir_freqs),
                    *hidden,
                    3,
                    3,
                    None,
                    device,
                ),
                config: self.clone(),
            },
            FieldConfig::Vanilla {
                pos_freqs,
                dir_freqs,
                width,
                depth,
            } => NerfField {
                grid: None,
                density_net: Mlp::new(
                    positional_dim(*pos_freqs),
                    *width,
                    1 + width,
                    *depth,
                    Some(depth / 2 + depth % 2),
                    device,
                ),
                color_net: Mlp::new(
                    width + positional_dim(*dir_freqs),
                    (width / 2).max(1),
                    3,
                    2,
                    None,
                    device,
                ),
                config: self.clone(),
            },
        }
    }

    fn dir_freqs(&self) -> usize {
        match self {
            FieldConfig::Hash { dir_freqs, .. } | FieldConfig::Vanilla { dir_freqs, .. } => {
                *dir_freqs
            }
        }
    }
}

/// A radiance field (see the module docs).
#[derive(Module, Debug)]
pub struct NerfField {
    /// The hash encoding (hash fields only).
    pub grid: Option<HashGrid>,
    /// Encoded position -> `[raw density, geometry features]`.
    pub density_net: Mlp,
    /// `[geometry features, encoded direction]` -> raw colour.
    pub color_net: Mlp,
    /// The configuration it was built from.
    #[module(skip)]
    pub config: FieldConfig,
}

fn points_tensor(points: &[[f32; 3]], device: &Device) -> Tensor<2> {
    let flat: Vec<f32> = points.iter().flatten().copied().collect();
    Tensor::from_data(TensorData::new(flat, [points.len(), 3]), device)
}

impl NerfField {
    /// The device the parameters live on.
    pub fn device(&self) -> Device {
        self.density_net.layers[0].weight.val().device()
    }

    /// `[N, 1 + geo]` output of the density network.
    fn trunk(&self, points: &[[f32; 3]]) -> Tensor<2> {
        let device = self.device();
        let enc = match &self.grid {
            Some(grid) => match grid.config.lookups.resolve(&device) {
                LookupSite::Device => grid.encode_points(points_tensor(points, &device)),
                _ => grid.encode(points),
            },
            None => {
                let freqs = match &self.config {
                    FieldConfig::Vanilla { pos_freqs, .. } => *pos_freqs,
                    FieldConfig::Hash { .. } => 0,
                };
                let x = points_tensor(points, &device)
                    .mul_scalar(2.0)
                    .sub_scalar(1.0);
                positional_encoding(x, freqs)
            }
        };
        self.density_net.forward(enc)
    }

    fn activate_density(&self, raw: Tensor<2>) -> Tensor<1> {
        let n = raw.dims()[0];
        let raw = match self.config {
            FieldConfig::Hash { density_bias, .. } if density_bias != 0.0 => {
                raw.add_scalar(density_bias)
            }
            _ => raw,
        };
        raw.clamp(-MAX_LOG_DENSITY, MAX_LOG_DENSITY)
            .exp()
            .reshape([n])
    }

    /// Density only: `[N]`, for occupancy updates and finite-difference normals.
    pub fn density(&self, points: &[[f32; 3]]) -> Tensor<1> {
        if points.is_empty() {
            return Tensor::zeros([0], &self.device());
        }
        let h = self.trunk(points);
        self.activate_density(h.narrow(1, 0, 1))
    }

    /// Density `[N]` and colour `[N, 3]` at `points` seen along unit world `dirs`.
    pub fn forward(&self, points: &[[f32; 3]], dirs: &[[f32; 3]]) -> (Tensor<1>, Tensor<2>) {
        self.forward_with(points, dirs, false)
    }

    /// [`Self::forward`] with the density network's output (the density and the features the
    /// colour head reads) detached when `appearance_only`: a loss on the result then moves
    /// the colour head alone, never the geometry or the shared encoding.
    pub fn forward_with(
        &self,
        points: &[[f32; 3]],
        dirs: &[[f32; 3]],
        appearance_only: bool,
    ) -> (Tensor<1>, Tensor<2>) {
        let device = self.device();
        let n = points.len();
        if n == 0 {
            return (Tensor::zeros([0], &device), Tensor::zeros([0, 3], &device));
        }
        let h = self.trunk(points);
        let h = if appearance_only { h.detach() } else { h };
        let width = h.dims()[1];
        let sigma = self.activate_density(h.clone().narrow(1, 0, 1));
        let geo = h.narrow(1, 1, width - 1);
        let d = positional_encoding(points_tensor(dirs, &device), self.config.dir_freqs());
        let rgb = sigmoid(self.color_net.forward(Tensor::cat(vec![geo, d], 1)));
        (sigma, rgb)
    }
}

/// A small hash field for the crate's unit tests.
#[cfg(test)]
pub(crate) fn tiny_hash_config() -> FieldConfig {
    FieldConfig::Hash {
        grid: HashGridConfig {
            levels: 4,
            features_per_level: 2,
            log2_table_size: 10,
            base_resolution: 4.0,
            max_resolution: 32.0,
            lookups: Default::default(),
        },
        hidden: 16,
        geo_features: 7,
        dir_freqs: 2,
        density_bias: 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_fields_give_finite_positive_density_and_unit_colour() {
        let device = gb_core::BackendKind::Flex.device();
        let configs = [
            tiny_hash_config(),
            FieldConfig::Vanilla {
                pos_freqs: 4,
                dir_freqs: 2,
                width: 16,
                depth: 4,
            },
        ];
        for cfg in configs {
            let f = cfg.init(&device);
            let pts = [[0.1, 0.2, 0.3], [0.9, 0.5, 0.0], [0.5, 0.5, 0.5]];
            let dirs = [[0.0, 0.0, -1.0]; 3];
            let (s, c) = f.forward(&pts, &dirs);
            let s: Vec<f32> = s.into_data().try_to_vec::<f32>().unwrap();
            let c: Vec<f32> = c.into_data().try_to_vec::<f32>().unwrap();
            assert_eq!((s.len(), c.len()), (3, 9));
            assert!(s.iter().all(|v| v.is_finite() && *v > 0.0));
            assert!(c.iter().all(|v| (0.0..=1.0).contains(v)));
            let d: Vec<f32> = f.density(&pts).into_data().try_to_vec::<f32>().unwrap();
            for i in 0..3 {
                assert!((d[i] - s[i]).abs() <= 1e-6 * s[i].abs().max(1.0));
            }
        }
    }

    /// `density_bias` scales the density by `exp(bias)` and leaves the colour alone; a config
    /// without the key reads as 0 and is written without it.
    #[test]
    fn density_bias_scales_the_density_and_defaults_to_zero() {
        let device = gb_core::BackendKind::Flex.device();
        let plain = tiny_hash_config().init(&device);
        let mut biased = plain.clone();
        if let FieldConfig::Hash { density_bias, .. } = &mut biased.config {
            *density_bias = -3.0;
        }
        let pts = [[0.1, 0.2, 0.3], [0.9, 0.5, 0.0]];
        let dirs = [[0.0, 0.0, -1.0]; 2];
        let values = |t: Tensor<1>| t.into_data().try_to_vec::<f32>().unwrap();
        let (s0, c0) = plain.forward(&pts, &dirs);
        let (s1, c1) = biased.forward(&pts, &dirs);
        for (a, b) in values(s0).iter().zip(values(s1)) {
            let want = a * (-3f32).exp();
            assert!((b - want).abs() <= 1e-5 * want, "{b} vs {want}");
        }
        let flat = |t: Tensor<2>| t.into_data().try_to_vec::<f32>().unwrap();
        assert_eq!(flat(c0), flat(c1));

        let text = toml::to_string(&tiny_hash_config()).unwrap();
        assert!(!text.contains("density_bias"), "{text}");
        let back: FieldConfig = toml::from_str(&text).unwrap();
        assert_eq!(back, tiny_hash_config());
        let with: FieldConfig = toml::from_str(&format!("density_bias = -1.0\n{text}")).unwrap();
        assert!(matches!(with, FieldConfig::Hash { density_bias, .. } if density_bias == -1.0));
    }
}
