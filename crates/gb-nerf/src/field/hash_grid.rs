//! The multiresolution hash encoding of instant-ngp (Müller et al. 2022).
//!
//! Definition (mirrored exactly by `tools/nerf_parity/make_fixtures.py`):
//! - per-level growth `b = exp((ln max_res - ln base_res) / (levels - 1))`;
//! - level `l` has `scale = base_res * b^l - 1` and `res = ceil(scale) + 1`;
//! - a point `x` in `[0, 1]^3` (clamped) maps to `pos = x * scale + 0.5`, corner
//!   `g = floor(pos)` and fraction `f = pos - g`;
//! - corner `c` (bits `(cx, cy, cz)` of `0..8`, x the lowest bit) has the trilinear weight
//!   `prod_i (c_i ? f_i : 1 - f_i)` and the table row
//!   `l * T + index(g + c) mod T`, where `index` is the dense stride index
//!   `x + y*res + z*res^2` when `res^3 <= T` and otherwise instant-ngp's spatial hash
//!   `(x * 1) xor (y * 2654435761) xor (z * 805459861)` in wrapping `u32` arithmetic;
//! - the output is the level features concatenated: `levels * features` values per point.
//!
//! Unlike instant-ngp every level owns a full table of `T` rows (simpler addressing, same
//! values). The lookups (indices and weights) are computed where [`LookupSite`] says
//! (`auto`, the default, picks `device` on a GPU card and `host` elsewhere):
//! - `host`: a loop over the points, spread over the CPU cores ([`hash_lookups`],
//!   [`HashGrid::encode`]), then
//!   an upload of `levels * 8` rows and weights per point (1.5 KB with 16 levels);
//! - `device`: tensor operations on the compute device from the uploaded points, 12 bytes
//!   per point ([`HashGrid::encode_points`]), bit-identical to the host loop.
//!
//! Measured on 2 CPU cores, the host loop wins on every backend there: flex 7.5 against 6.1
//! steps/s (`fast`) and 0.55 against 0.41 (`balanced`); wgpu on lavapipe 1.60 against 0.65
//! and 0.144 against 0.070. `device` is meant for discrete GPUs, where an H100 trained the
//! `fast` preset at 2.8 steps/s with host lookups, slower than flex on the same machine's
//! 16 cores; it has not been timed on a GPU yet. The hash is evaluated in the device's integer type: wrapping `i32`
//! (wgpu) or exact `i64` (CPU backends) give the same low bits, and the row keeps only the
//! low `log2_table_size` bits. [`hash_lookups`] is the CPU definition the device path is
//! tested against.

use burn::module::{Module, Param};
use burn::tensor::{Device, Distribution, Int, Tensor, TensorData};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Hyper-parameters of the hash encoding.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HashGridConfig {
    /// Number of resolution levels (reference: 16).
    pub levels: usize,
    /// Features per level (reference: 2).
    pub features_per_level: usize,
    /// log2 of the table size per level (reference: 19).
    pub log2_table_size: u32,
    /// Coarsest grid resolution (reference: 16).
    pub base_resolution: f32,
    /// Finest grid resolution (reference: 2048 times the scene bound; 512 for a unit box).
    pub max_resolution: f32,
    /// Where the rows and weights are computed (TOML `lookups = "auto"`, `"host"` or
    /// `"device"`).
    #[serde(default)]
    pub lookups: LookupSite,
}

/// Where a hash grid computes its lookups (rows and trilinear weights); every site gives the
/// same encoding bit for bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LookupSite {
    /// `device` on a GPU card, `host` on the CPU backends and on software rasterizers such as
    /// lavapipe (the default; [`LookupSite::resolve`]).
    #[default]
    Auto,
    /// A loop on the host, then an upload of `levels * 8` rows and weights per point
    /// (fastest on the CPU backends, and on lavapipe).
    Host,
    /// Tensor operations on the compute device from the uploaded points (12 bytes per
    /// point): meant for GPUs, where the host loop and the upload dominate.
    Device,
}

impl LookupSite {
    /// The site used on `device`: `auto` becomes `device` when `device` runs on a GPU card
    /// ([`gb_core::backend::is_gpu_card`]) and `host` otherwise; the others stay.
    pub fn resolve(self, device: &Device) -> LookupSite {
        match self {
            LookupSite::Auto if gb_core::backend::is_gpu_card(device) => LookupSite::Device,
            LookupSite::Auto => LookupSite::Host,
            site => site,
        }
    }
}

impl HashGridConfig {
    /// Number of output features: `levels * features_per_level`.
    pub fn output_dim(&self) -> usize {
        self.levels * self.features_per_level
    }

    /// Rows per level table.
    pub fn table_size(&self) -> usize {
        1usize << self.log2_table_size
    }

    /// The per-level growth factor `b`.
    pub fn growth(&self) -> f32 {
        if self.levels <= 1 {
            return 1.0;
        }
        ((self.max_resolution.ln() - self.base_resolution.ln()) / (self.levels as f32 - 1.0)).exp()
    }

    /// Initialises a table with instant-ngp's uniform(-1e-4, 1e-4) values.
    pub fn init(&self, device: &Device) -> HashGrid {
        let rows = self.levels * self.table_size();
        let table = Tensor::<2>::random(
            [rows, self.features_per_level],
            Distribution::Uniform(-1e-4, 1e-4),
            device,
        );
        HashGrid {
            table: Param::from_tensor(table),
            config: *self,
        }
    }
}

/// CPU-side lookups of a batch of points: for each point, level and corner, a table row and
/// a trilinear weight.
#[derive(Debug, Clone, PartialEq)]
pub struct HashLookups {
    /// Number of points.
    pub points: usize,
    /// `points * levels * 8` table rows.
    pub rows: Vec<i64>,
    /// `points * levels * 8` trilinear weights.
    pub weights: Vec<f32>,
}

/// The spatial hash of instant-ngp, in wrapping `u32` arithmetic.
pub fn spatial_hash(g: [u32; 3]) -> u32 {
    g[0] ^ g[1].wrapping_mul(2_654_435_761) ^ g[2].wrapping_mul(805_459_861)
}

/// Points per parallel task of [`hash_lookups`].
const LOOKUP_CHUNK: usize = 1024;

/// Computes the table rows and weights of `points` (coordinates in `[0, 1]`, clamped),
/// spread over the cores (rayon) in chunks of points; the result does not depend on the
/// number of threads.
pub fn hash_lookups(config: &HashGridConfig, points: &[[f32; 3]]) -> HashLookups {
    let levels = config.levels;
    let t = config.table_size() as u64;
    let b = config.growth();
    // per level: (scale, resolution, dense indexing)
    let level_params: Vec<(f32, u64, bool)> = (0..levels)
        .map(|l| {
            let scale = config.base_resolution * b.powi(l as i32) - 1.0;
            let res = scale.ceil() as u64 + 1;
            (scale, res, res.saturating_mul(res).saturating_mul(res) <= t)
        })
        .collect();
    let per_point = levels * 8;
    let mut rows = vec![0i64; points.len() * per_point];
    let mut weights = vec![0f32; points.len() * per_point];
    let chunk = LOOKUP_CHUNK * per_point.max(1);
    rows.par_chunks_mut(chunk)
        .zip(weights.par_chunks_mut(chunk))
        .zip(points.par_chunks(LOOKUP_CHUNK))
        .for_each(|((rows, weights), points)| {
            for (k, p) in points.iter().enumerate() {
                for (l, &(scale, res, dense)) in level_params.iter().enumerate() {
                    let mut g = [0u32; 3];
                    let mut f = [0f32; 3];
                    for i in 0..3 {
                        let x = if p[i].is_finite() {
                            p[i].clamp(0.0, 1.0)
                        } else {
                            0.0
                        };
                        let pos = x * scale + 0.5;
                        let fl = pos.floor();
                        g[i] = fl as u32;
                        f[i] = pos - fl;
                    }
                    for c in 0..8u32 {
                        let mut w = 1.0f32;
                        let mut gc = [0u32; 3];
                        for i in 0..3 {
                            let bit = (c >> i) & 1;
                            gc[i] = g[i] + bit;
                            w *= if bit == 1 { f[i] } else { 1.0 - f[i] };
                        }
                        let index = if dense {
                            (gc[0] as u64 + gc[1] as u64 * res + gc[2] as u64 * res * res) % t
                        } else {
                            spatial_hash(gc) as u64 % t
                        };
                        let j = k * per_point + l * 8 + c as usize;
                        rows[j] = (l as u64 * t + index) as i64;
                        weights[j] = w;
                    }
                }
            }
        });
    HashLookups {
        points: points.len(),
        rows,
        weights,
    }
}

/// The trainable hash tables: `levels * table_size` rows of `features_per_level` values.
#[derive(Module, Debug)]
pub struct HashGrid {
    /// All level tables stacked: `[levels * T, F]`.
    pub table: Param<Tensor<2>>,
    /// The hyper-parameters.
    #[module(skip)]
    pub config: HashGridConfig,
}

impl HashGrid {
    /// Encodes points from precomputed lookups: `[points, levels * features]`. The lookups'
    /// rows and weights move into the tensors (no copy of `points * levels * 8` entries).
    pub fn encode_lookups(&self, lookups: HashLookups) -> Tensor<2> {
        let table = self.table.val();
        let device = table.device();
        let (n, l, f) = (
            lookups.points,
            self.config.levels,
            self.config.features_per_level,
        );
        if n == 0 {
            return Tensor::zeros([0, l * f], &device);
        }
        let rows = gb_core::row_indices(lookups.rows, &device);
        let w = Tensor::<4>::from_data(TensorData::new(lookups.weights, [n, l, 8, 1]), &device);
        let gathered = gb_core::gather_rows(table, rows).reshape([n, l, 8, f]);
        (gathered * w).sum_dim(2).reshape([n, l * f])
    }

    /// Encodes points in `[0, 1]^3` with lookups computed on the CPU:
    /// `[points, levels * features]`.
    pub fn encode(&self, points: &[[f32; 3]]) -> Tensor<2> {
        self.encode_lookups(hash_lookups(&self.config, points))
    }

    /// Encodes points `[N, 3]` (on the table's device) with the lookups computed on the
    /// device: `[N, levels * features]`. Non-finite coordinates count as 0 and the others
    /// are clamped to `[0, 1]`, as in [`hash_lookups`].
    pub fn encode_points(&self, points: Tensor<2>) -> Tensor<2> {
        let table = self.table.val();
        let device = table.device();
        let c = &self.config;
        let (n, levels, feats) = (points.dims()[0], c.levels, c.features_per_level);
        if n == 0 {
            return Tensor::zeros([0, levels * feats], &device);
        }
        let t = c.table_size() as i64;
        let b = c.growth();
        // per-level constants, [1, L, 1, 1]
        let mut scale = Vec::with_capacity(levels);
        let mut res = Vec::with_capacity(levels);
        let mut dense = Vec::with_capacity(levels);
        let mut offset = Vec::with_capacity(levels);
        for l in 0..levels {
            let s = c.base_resolution * b.powi(l as i32) - 1.0;
            let r = s.ceil() as i64 + 1;
            scale.push(s);
            res.push(r);
            dense.push(i64::from(r.saturating_mul(r).saturating_mul(r) <= t));
            offset.push(l as i64 * t);
        }
        let per_level_f =
            |v: Vec<f32>| Tensor::<4>::from_data(TensorData::new(v, [1, levels, 1, 1]), &device);
        let per_level_i = |v: Vec<i64>| {
            Tensor::<4, Int>::from_data(TensorData::new(v, [1, levels, 1, 1]), &device)
        };
        // corner bits, x the lowest: [1, 1, 8, 3]
        let bits: Vec<i64> = (0..8)
            .flat_map(|c: i64| (0..3).map(move |i| (c >> i) & 1))
            .collect();
        let bits_f: Vec<f32> = bits.iter().map(|&v| v as f32).collect();
        let bits_i = Tensor::<4, Int>::from_data(TensorData::new(bits, [1, 1, 8, 3]), &device);
        let bits_f = Tensor::<4>::from_data(TensorData::new(bits_f, [1, 1, 8, 3]), &device);

        let finite = points.clone().abs().lower_elem(f32::INFINITY);
        let x = points
            .mask_fill(finite.bool_not(), 0.0)
            .clamp(0.0, 1.0)
            .reshape([n, 1, 1, 3]);
        let pos = (x * per_level_f(scale)).add_scalar(0.5); // [N, L, 1, 3]
        let g = pos.clone().floor();
        let frac = pos - g.clone();
        let one_minus = frac.clone().neg().add_scalar(1.0);
        let bits_not = bits_f.clone().neg().add_scalar(1.0);
        let sel = frac * bits_f + one_minus * bits_not; // [N, L, 8, 3]
        let w = sel.clone().narrow(3, 0, 1) * sel.clone().narrow(3, 1, 1) * sel.narrow(3, 2, 1);
        let gc = g.int() + bits_i; // [N, L, 8, 3]
        let (gx, gy, gz) = (
            gc.clone().narrow(3, 0, 1),
            gc.clone().narrow(3, 1, 1),
            gc.narrow(3, 2, 1),
        );
        let res_t = per_level_i(res.clone());
        let res2_t = per_level_i(res.iter().map(|r| r * r).collect());
        let dense_index = gx.clone() + gy.clone() * res_t + gz.clone() * res2_t;
        // 2654435761 as a wrapping i32 (same low 32 bits in any integer width)
        let hashed = gx
            .bitwise_xor(gy.mul_scalar(2_654_435_761u32 as i32 as i64))
            .bitwise_xor(gz.mul_scalar(805_459_861i64));
        let dense_t = per_level_i(dense);
        let index = (dense_index * dense_t.clone() + hashed * dense_t.neg().add_scalar(1))
            .bitwise_and_scalar(t - 1);
        let rows = (index + per_level_i(offset)).reshape([n * levels * 8]);
        let gathered = gb_core::gather_rows(table, rows).reshape([n, levels, 8, feats]);
        (gathered * w).sum_dim(2).reshape([n, levels * feats])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> HashGridConfig {
        HashGridConfig {
            levels: 4,
            features_per_level: 2,
            log2_table_size: 10,
            base_resolution: 4.0,
            max_resolution: 64.0,
            lookups: LookupSite::Host,
        }
    }

    #[test]
    fn weights_are_a_partition_of_unity_and_rows_in_range() {
        let c = cfg();
        let pts = [
            [0.0, 0.0, 0.0],
            [0.3, 0.7, 0.11],
            [1.0, 1.0, 1.0],
            [f32::NAN, 2.0, -1.0],
        ];
        let lk = hash_lookups(&c, &pts);
        for chunk in lk.weights.chunks(8) {
            let s: f32 = chunk.iter().sum();
            assert!((s - 1.0).abs() < 1e-5, "{s}");
        }
        for (i, r) in lk.rows.iter().enumerate() {
            let level = (i / 8) % c.levels;
            let lo = (level * c.table_size()) as i64;
            assert!(*r >= lo && *r < lo + c.table_size() as i64);
        }
    }

    #[test]
    fn coarse_level_is_dense_and_fine_level_hashed() {
        let c = cfg();
        // level 0: scale 3, res 4, 64 <= 1024 -> dense index
        let lk = hash_lookups(&c, &[[0.5, 0.5, 0.5]]);
        // pos = 0.5*3+0.5 = 2.0 -> g = 2, f = 0: corner 0 has weight 1
        assert_eq!(lk.rows[0], 2 + 2 * 4 + 2 * 16);
        assert!((lk.weights[0] - 1.0).abs() < 1e-6);
        // level 3: scale 63, res 64 -> hashed
        let g = [32u32, 32, 32];
        assert_eq!(
            lk.rows[3 * 8],
            (3 * 1024 + spatial_hash(g) as u64 % 1024) as i64
        );
    }

    /// The device lookups give the CPU definition's encoding on every test backend, for
    /// dense and hashed levels, corners, faces and non-finite coordinates.
    #[test]
    fn device_lookups_match_the_cpu_definition() {
        let c = HashGridConfig {
            levels: 6,
            features_per_level: 2,
            log2_table_size: 12,
            base_resolution: 4.0,
            max_resolution: 700.0,
            lookups: LookupSite::Device,
        };
        let mut pts: Vec<[f32; 3]> = (0..300)
            .map(|i| {
                let f = i as f32 / 300.0;
                [f, (f * 7.31).fract(), (f * 13.7 + 0.01).fract()]
            })
            .collect();
        pts.extend([
            [0.0, 0.0, 0.0],
            [1.0, 1.0, 1.0],
            [0.5, 0.5, 0.5],
            [f32::NAN, 2.0, -1.0],
            [f32::INFINITY, f32::NEG_INFINITY, 0.25],
        ]);
        for kind in gb_core::test_backends() {
            let device = kind.device();
            let grid = c.init(&device);
            let host: Vec<f32> = grid.encode(&pts).into_data().try_to_vec::<f32>().unwrap();
            let flat: Vec<f32> = pts.iter().flatten().copied().collect();
            let p = Tensor::<2>::from_data(TensorData::new(flat, [pts.len(), 3]), &device);
            let dev: Vec<f32> = grid
                .encode_points(p)
                .into_data()
                .convert::<f32>()
                .try_to_vec::<f32>()
                .unwrap();
            assert_eq!(host.len(), dev.len());
            let worst = host
                .iter()
                .zip(&dev)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            assert!(worst <= 1e-9, "{kind}: max difference {worst}");
        }
    }

    /// Lookups of a set larger than one parallel chunk equal the lookups of each point alone.
    #[test]
    fn parallel_lookups_equal_point_by_point_lookups() {
        let c = cfg();
        let pts: Vec<[f32; 3]> = (0..2 * LOOKUP_CHUNK + 77)
            .map(|i| {
                let f = i as f32 / 2000.0;
                [f.fract(), (f * 3.7).fract(), (f * 9.1).fract()]
            })
            .collect();
        let all = hash_lookups(&c, &pts);
        assert_eq!(all.points, pts.len());
        let per = c.levels * 8;
        for (k, p) in pts.iter().enumerate() {
            let one = hash_lookups(&c, std::slice::from_ref(p));
            assert_eq!(all.rows[k * per..(k + 1) * per], one.rows[..], "point {k}");
            assert_eq!(
                all.weights[k * per..(k + 1) * per],
                one.weights[..],
                "point {k}"
            );
        }
    }

    #[test]
    fn the_lookup_site_is_read_from_toml_and_defaults_to_auto() {
        let base = "levels = 2\nfeatures_per_level = 2\nlog2_table_size = 8\n\
                    base_resolution = 4.0\nmax_resolution = 16.0\n";
        let c: HashGridConfig = toml::from_str(base).unwrap();
        assert_eq!(c.lookups, LookupSite::Auto);
        let c: HashGridConfig = toml::from_str(&format!("{base}lookups = \"host\"\n")).unwrap();
        assert_eq!(c.lookups, LookupSite::Host);
        let c: HashGridConfig = toml::from_str(&format!("{base}lookups = \"device\"\n")).unwrap();
        assert_eq!(c.lookups, LookupSite::Device);
        assert!(toml::from_str::<HashGridConfig>(&format!("{base}lookups = \"gpu\"\n")).is_err());
    }

    /// `auto` computes on the host on the CPU backends and on lavapipe (no GPU card: the CI
    /// machine), and explicit sites are kept on every backend.
    #[test]
    fn auto_lookups_stay_on_the_host_without_a_gpu_card() {
        for kind in gb_core::test_backends() {
            let device = kind.device();
            let card = gb_core::backend::is_gpu_card(&device);
            if kind != gb_core::BackendKind::Wgpu {
                assert!(!card, "{kind} is a CPU backend");
            }
            let want = if card {
                LookupSite::Device
            } else {
                LookupSite::Host
            };
            assert_eq!(LookupSite::Auto.resolve(&device), want, "{kind}");
            assert_eq!(
                LookupSite::Host.resolve(&device),
                LookupSite::Host,
                "{kind}"
            );
            assert_eq!(
                LookupSite::Device.resolve(&device),
                LookupSite::Device,
                "{kind}"
            );
        }
    }

    #[test]
    fn encoding_interpolates_table_values() {
        let c = cfg();
        let device = gb_core::BackendKind::Flex.device();
        let grid = c.init(&device);
        let p = [[0.21f32, 0.43, 0.77]];
        let out: Vec<f32> = grid.encode(&p).into_data().try_to_vec::<f32>().unwrap();
        let table: Vec<f32> = grid.table.val().into_data().try_to_vec::<f32>().unwrap();
        let lk = hash_lookups(&c, &p);
        for l in 0..c.levels {
            for f in 0..2 {
                let mut e = 0.0;
                for k in 0..8 {
                    let i = l * 8 + k;
                    e += lk.weights[i] * table[lk.rows[i] as usize * 2 + f];
                }
                assert!((out[l * 2 + f] - e).abs() < 1e-9, "level {l}");
            }
        }
    }
}
