//! The method-grid flags of `cargo xtask ablate`, which `bench quality` runs as a
//! benchmark: one definition for both commands.

use std::path::PathBuf;

use gb_core::BackendKind;
use gb_grid::GridSettings;
use gb_nerf::train::DepthSupervision;

/// The settings of the method grid, shared by `cargo xtask ablate` and `bench quality`.
#[derive(clap::Args, Debug, Clone)]
pub struct GridArgs {
    /// Comma-separated methods (default: the whole grid: none, spin-nerf-sds, mvip-nerf,
    /// csd, gb-nerf, gb-nerf-unseen, sds-lora, bsd).
    #[arg(long, value_delimiter = ',')]
    pub methods: Option<Vec<String>>,
    /// Preset name (fast, balanced, paper) or a TOML file, for every run.
    #[arg(long, default_value = "fast")]
    pub preset: String,
    /// The diffusion prior of the guided methods: tiny (default), a folder or a hub id.
    #[arg(long)]
    pub prior: Option<String>,
    /// Override the preset's number of training steps (at least 1).
    #[arg(long, value_parser = gb_core::cli::at_least_one)]
    pub steps: Option<usize>,
    /// Compute backend: ndarray, flex or wgpu.
    #[arg(long, value_enum)]
    pub device: Option<BackendKind>,
    /// Depth supervision of every run: sparse (the preset default), dense or none.
    #[arg(long)]
    pub depth: Option<DepthSupervision>,
    /// Each run also writes `probe/`: the hidden region's depth error, normals and ray
    /// weights per test view (`inpaint --probe`).
    #[arg(long)]
    pub probe: bool,
}

impl GridArgs {
    /// The grid's shared settings on `scene` with training seed `seed` (no LoRA override, the
    /// default metric weights, no orbit, no nerfstudio export: the benchmarks score the test
    /// views, and the export of the training views cost 70 s of the 2 min a `none` run of
    /// `bench quality` took on 2 cores).
    pub fn settings(&self, scene: PathBuf, seed: Option<u64>) -> GridSettings {
        GridSettings {
            scene,
            preset: self.preset.clone(),
            prior: self.prior.clone().unwrap_or_else(|| "tiny".into()),
            lora: None,
            steps: self.steps,
            seed,
            depth: self.depth,
            device: self.device.unwrap_or_default().name().into(),
            weights: None,
            orbit_frames: 0,
            export: gb_inpaint::export::ExportMode::None,
            probe: self.probe,
        }
    }
}
