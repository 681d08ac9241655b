//! The reconstruction configuration and the built-in presets
//! (`configs/presets/{fast,balanced,paper}.toml`, embedded at build time).

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::NerfError;
use crate::field::FieldConfig;
use crate::render::image::NormalSource;
use crate::sampler::SamplerConfig;

/// Everything the reconstruction needs: field, sampler, optimisation and rendering.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NerfConfig {
    /// Preset name (informational).
    pub name: String,
    /// The field.
    pub field: FieldConfig,
    /// The sampler.
    pub sampler: SamplerConfig,
    /// Optimisation.
    pub train: TrainSettings,
    /// Rendering of test views and normals.
    pub render: RenderSettings,
}

/// Optimisation settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainSettings {
    /// Training steps.
    pub steps: usize,
    /// Rays per step.
    pub rays_per_batch: usize,
    /// Initial Adam learning rate (reference: 3e-3).
    pub lr: f64,
    /// Learning-rate factor reached after `lr_decay_steps` (reference: 0.1 over 10k steps);
    /// `lr(step) = lr * lr_decay^(step / lr_decay_steps)`.
    pub lr_decay: f64,
    /// Steps over which the learning rate decays by `lr_decay`.
    pub lr_decay_steps: usize,
    /// Which depth supervises the reconstruction (default `sparse`, as a real capture has it).
    #[serde(default)]
    pub depth: DepthSupervision,
    /// Weight of the disparity loss where depth exists (reference: 0.1).
    pub depth_weight: f32,
    /// Weight of the distortion loss of mip-NeRF 360 (0: off, the default), which pulls each
    /// ray's weights into one compact interval against floaters; see
    /// [`crate::train::losses::distortion_loss`]. No preset enables it: on fern with `fast`,
    /// 0.01 and 0.001 lowered the held-out PSNR by 2.7 and 2.6 dB
    /// (`bench/results/nerf-fern-fast-variants-cpu-2core.json`).
    #[serde(default)]
    pub distortion_weight: f32,
    /// Steps between checkpoints (0: only at the end).
    pub checkpoint_every: usize,
    /// Integer downscaling of the training images (1: full resolution).
    pub image_downscale: usize,
    /// Seed of ray selection, jitter and initialisation.
    pub seed: u64,
}

/// The depth that supervises the reconstruction's disparity loss.
///
/// Real captures have no dense depth: the reference code line (DS-NeRF, which SPIn-NeRF,
/// MVIP-NeRF and GB-NeRF build on) supervises with the sparse 3D points of COLMAP's
/// structure from motion. `sparse` uses a scene's COLMAP points (`sparse/0`, which the
/// procedural generator also writes); `dense` uses per-pixel depth maps (the procedural
/// scenes' exact `depth/`, or SPIn-NeRF's inpainted depths), an oracle no capture has;
/// `none` trains on colour alone. A scene without the chosen depth trains on colour alone,
/// with a warning.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DepthSupervision {
    /// COLMAP's sparse points seen by each training view (the default).
    #[default]
    Sparse,
    /// Per-pixel depth maps.
    Dense,
    /// No depth loss.
    None,
}

impl DepthSupervision {
    /// Every choice, in the order the CLI lists them.
    pub const ALL: [Self; 3] = [Self::Sparse, Self::Dense, Self::None];

    /// The name used in configs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Sparse => "sparse",
            Self::Dense => "dense",
            Self::None => "none",
        }
    }
}

impl std::fmt::Display for DepthSupervision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for DepthSupervision {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|d| d.name() == s)
            .ok_or_else(|| format!("unknown depth supervision \"{s}\" (sparse, dense or none)"))
    }
}

/// Rendering settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderSettings {
    /// Where normal maps come from.
    pub normals: NormalSource,
    /// Rays per chunk when rendering whole images.
    pub chunk: usize,
}

const FAST: &str = include_str!("../../../../configs/presets/fast.toml");
const BALANCED: &str = include_str!("../../../../configs/presets/balanced.toml");
const PAPER: &str = include_str!("../../../../configs/presets/paper.toml");

impl NerfConfig {
    /// Parses a TOML configuration; `origin` names it in errors.
    pub fn from_toml(text: &str, origin: &Path) -> Result<Self, NerfError> {
        let cfg: NerfConfig = toml::from_str(text).map_err(|e| NerfError::Config {
            path: origin.to_path_buf(),
            reason: gb_core::messages::at_line(text, e.span(), e.message()),
        })?;
        cfg.validate(origin)?;
        Ok(cfg)
    }

    /// A built-in preset (`fast`, `balanced`, `paper`) or a path to a TOML file.
    pub fn preset(name: &str) -> Result<Self, NerfError> {
        let text = match name {
            "fast" => FAST,
            "balanced" => BALANCED,
            "paper" => PAPER,
            other if other.ends_with(".toml") => {
                let path = Path::new(other);
                let text = std::fs::read_to_string(path).map_err(|e| NerfError::Config {
                    path: path.to_path_buf(),
                    reason: e.to_string(),
                })?;
                return Self::from_toml(&text, path);
            }
            other => return Err(NerfError::UnknownPreset(other.to_string())),
        };
        Self::from_toml(text, Path::new(&format!("configs/presets/{name}.toml")))
    }

    fn validate(&self, origin: &Path) -> Result<(), NerfError> {
        let bad = |reason: &str| {
            Err(NerfError::Config {
                path: origin.to_path_buf(),
                reason: reason.to_string(),
            })
        };
        let t = &self.train;
        if t.steps == 0 {
            return bad("train.steps must be > 0");
        }
        if t.rays_per_batch == 0 {
            return bad("train.rays_per_batch must be > 0");
        }
        if t.lr.is_nan() || t.lr <= 0.0 || t.lr.is_infinite() {
            return bad("train.lr must be a positive number");
        }
        if t.lr_decay_steps == 0 || t.lr_decay.is_nan() || t.lr_decay <= 0.0 {
            return bad("train.lr_decay and train.lr_decay_steps must be > 0");
        }
        if !(t.distortion_weight.is_finite() && t.distortion_weight >= 0.0) {
            return bad("train.distortion_weight must be a finite number >= 0");
        }
        if t.image_downscale == 0 {
            return bad("train.image_downscale must be >= 1");
        }
        if self.sampler.samples_per_ray == 0 {
            return bad("sampler.samples_per_ray must be > 0");
        }
        if let Some(o) = &self.sampler.occupancy {
            if o.resolution == 0 || o.update_every == 0 {
                return bad("sampler.occupancy.resolution and update_every must be > 0");
            }
        }
        Ok(())
    }

    /// The learning rate at `step`.
    pub fn lr_at(&self, step: usize) -> f64 {
        self.train.lr
            * self
                .train
                .lr_decay
                .powf(step as f64 / self.train.lr_decay_steps as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_parse_and_span_the_trade() {
        let f = NerfConfig::preset("fast").unwrap();
        let b = NerfConfig::preset("balanced").unwrap();
        let p = NerfConfig::preset("paper").unwrap();
        assert!(f.train.steps < b.train.steps && b.train.steps < p.train.steps);
        assert!((p.train.lr - 3e-3).abs() < 1e-12);
        assert!((p.lr_at(10_000) - 3e-4).abs() < 1e-9);
        assert!((p.train.depth_weight - 0.1).abs() < 1e-9);
        match &p.field {
            FieldConfig::Hash { grid, .. } => {
                assert_eq!(
                    (grid.levels, grid.features_per_level, grid.log2_table_size),
                    (16, 2, 19)
                );
                assert_eq!(grid.base_resolution, 16.0);
            }
            other => panic!("paper preset field: {other:?}"),
        }
        assert!(matches!(
            NerfConfig::preset("nope"),
            Err(NerfError::UnknownPreset(_))
        ));
    }

    #[test]
    fn bad_config_names_the_file() {
        let err = NerfConfig::from_toml("name = 1", Path::new("x.toml")).unwrap_err();
        assert!(err.to_string().starts_with("x.toml:"), "{err}");
    }

    #[test]
    fn unknown_fields_and_zero_values_are_one_line_errors() {
        let typo = FAST.replace("lr_decay = 0.1", "lr_decay = 0.1\nlr_decya = 0.5");
        let err = NerfConfig::from_toml(&typo, Path::new("t.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("lr_decya") && err.contains("line "), "{err}");
        assert_eq!(err.lines().count(), 1, "{err}");
        for (from, to, field) in [
            ("steps = 400", "steps = 0", "train.steps"),
            ("lr = 1e-2", "lr = -1e-2", "train.lr"),
            (
                "samples_per_ray = 40",
                "samples_per_ray = 0",
                "samples_per_ray",
            ),
        ] {
            let err = NerfConfig::from_toml(&FAST.replace(from, to), Path::new("t.toml"))
                .unwrap_err()
                .to_string();
            assert!(err.contains(field), "{err}");
        }
    }
}
