//! A method grid on one scene (the paper's baselines, its ablation and the CSD w3 sweep) as
//! independent cells, so that a cluster can run them: [`Grid::plan`] resolves and checks
//! the grid, [`Grid::write`] stores it as `GRID/grid.toml` (with the sweep's method files),
//! [`run_cell`] runs cell `I` into its own resumable folder `GRID/<cell dir>/`, and
//! [`merge`] writes the tables from the finished cells and lists the missing ones.
//! [`emit`] writes a Slurm array script and a Kubernetes Indexed Job that run cell
//! `$SLURM_ARRAY_TASK_ID` / `$JOB_COMPLETION_INDEX`. The single-process `cargo xtask ablate`
//! is the same grid run in a loop. There is no scheduler of our own. [`finetune_job`] writes
//! the jobs of a data-parallel fine-tuning run (a Slurm job of N MPI tasks, a Kubeflow
//! `MPIJob`).

pub mod ablate;
pub mod emit;
pub mod finetune_job;
mod merge;
mod plan;

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

pub use merge::{merge, MergeReport};
pub use plan::grid_methods;

use crate::ablate::RunOutcome;
use gb_inpaint::run::{run, RunSpec, RunSummary};
use gb_inpaint::InpaintError;

/// The grid's file in its folder.
pub const GRID_FILE: &str = "grid.toml";
/// A failed cell's error, in its run folder (read by [`merge`]).
pub const CELL_ERROR_FILE: &str = "cell-error.txt";
/// A finished cell's wall time, in its run folder.
pub const CELL_TIME_FILE: &str = "cell-time.json";

/// What every cell shares. Paths are absolute, so a cell runs from any folder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GridSettings {
    /// The scene folder.
    pub scene: PathBuf,
    /// The preset (name or absolute `.toml` path).
    pub preset: String,
    /// The prior of the guided methods (`tiny`, a folder, a hub id).
    pub prior: String,
    /// The LoRA file of the methods with `use_lora = true` (default: the prior's own).
    pub lora: Option<PathBuf>,
    /// Overrides the preset's steps.
    pub steps: Option<usize>,
    /// Overrides the preset's training seed.
    pub seed: Option<u64>,
    /// Overrides the preset's depth supervision.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth: Option<gb_nerf::train::DepthSupervision>,
    /// The backend's name.
    pub device: String,
    /// Folder of metric weights (the plan's default: `$GB_TEST_DATA/weights` when it
    /// exists, made absolute).
    pub weights: Option<PathBuf>,
    /// Frames of each run's orbit animation.
    pub orbit_frames: usize,
    /// Whether each run writes the nerfstudio export (absent in grids from before the
    /// setting, when runs exported by default: full).
    #[serde(default = "full_export", skip_serializing_if = "is_full_export")]
    pub export: gb_inpaint::export::ExportMode,
    /// Whether each run writes `probe/` ([`gb_inpaint::run::probe`]; absent: no).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub probe: bool,
}

fn full_export() -> gb_inpaint::export::ExportMode {
    gb_inpaint::export::ExportMode::Full
}

fn is_full_export(m: &gb_inpaint::export::ExportMode) -> bool {
    *m == gb_inpaint::export::ExportMode::Full
}

/// One run of the grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GridCell {
    /// The method: a built-in name, or a `.toml` file name in the grid folder (the sweep).
    pub method: String,
    /// The run folder, relative to the grid folder.
    pub dir: String,
    /// Whether the grid's LoRA applies (the method has `use_lora = true`).
    pub use_lora: bool,
}

/// One point of the CSD w3 sweep: its w3 and the run folder that holds it (the `csd` cell
/// itself when its w3 is that value).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SweepPoint {
    /// The unconditional weight w3, on RGB and normal maps.
    pub w3: f64,
    /// The run folder, relative to the grid folder.
    pub dir: String,
}

/// A method grid: its settings, its cells in run order (`none` first: every report's
/// baseline) and the w3 sweep.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Grid {
    /// Shared settings.
    pub settings: GridSettings,
    /// The cells, by index.
    pub cells: Vec<GridCell>,
    /// The w3 sweep (empty: not run).
    pub sweep: Vec<SweepPoint>,
}

impl Grid {
    /// Writes `dir/grid.toml` (and nothing else; [`Grid::plan`] wrote the sweep's method
    /// files).
    pub fn write(&self, dir: &Path) -> Result<PathBuf, InpaintError> {
        let path = dir.join(GRID_FILE);
        let text =
            toml::to_string(self).map_err(|e| InpaintError::io(&path, std::io::Error::other(e)))?;
        let text = format!(
            "# A method grid: run cell I with `gb-nerf ablate --grid {} --cell I`, merge the \
             tables with `--merge`.\n{text}",
            dir.display()
        );
        std::fs::create_dir_all(dir).map_err(|e| InpaintError::io(dir, e))?;
        gb_core::write_atomic(&path, text.as_bytes()).map_err(|e| InpaintError::io(&path, e))?;
        Ok(path)
    }

    /// Reads `dir/grid.toml`.
    pub fn read(dir: &Path) -> Result<Self, InpaintError> {
        let path = dir.join(GRID_FILE);
        let text = std::fs::read_to_string(&path).map_err(|e| InpaintError::io(&path, e))?;
        toml::from_str(&text).map_err(|e| InpaintError::Spec {
            field: path.display().to_string(),
            reason: format!("not a grid file: {}", e.message()),
        })
    }

    /// The [`RunSpec`] of cell `index`, run into `grid_dir/<dir>` (resumable). Its report's
    /// baseline is the `none` cell when that one has finished.
    pub fn cell_spec(&self, grid_dir: &Path, index: usize) -> Result<RunSpec, InpaintError> {
        let cell = self.cells.get(index).ok_or_else(|| InpaintError::Spec {
            field: format!("--cell {index}"),
            reason: format!(
                "the grid {} has {} cell(s), indices 0 to {}",
                grid_dir.display(),
                self.cells.len(),
                self.cells.len().saturating_sub(1)
            ),
        })?;
        let s = &self.settings;
        let method = if cell.method.ends_with(".toml") {
            grid_dir.join(&cell.method).display().to_string()
        } else {
            cell.method.clone()
        };
        let baseline = self
            .cells
            .iter()
            .find(|c| c.method == "none")
            .map(|c| grid_dir.join(&c.dir))
            .filter(|d| cell.method != "none" && d.join("metrics.json").is_file());
        Ok(RunSpec {
            scene: Some(s.scene.clone()),
            method: Some(method),
            preset: s.preset.clone(),
            prior: Some(s.prior.clone()),
            lora: s.lora.clone().filter(|_| cell.use_lora),
            device: s.device.parse().map_err(|e| InpaintError::Spec {
                field: grid_dir.join(GRID_FILE).display().to_string(),
                reason: format!("settings.device: {e}"),
            })?,
            seed: s.seed,
            steps: s.steps,
            depth: s.depth,
            out: grid_dir.join(&cell.dir),
            resume: true,
            baseline,
            weights: s.weights.clone(),
            orbit_frames: s.orbit_frames,
            export: s.export,
            probe: s.probe,
            ..RunSpec::default()
        })
    }
}

/// Runs cell `index` of the grid in `grid_dir` into its own folder, resuming a checkpoint
/// left there. A failure is written to the cell's `cell-error.txt` (for [`merge`]) and
/// returned in the outcome; a bad index is an error.
pub fn run_cell(grid_dir: &Path, index: usize) -> Result<RunOutcome, InpaintError> {
    let grid = Grid::read(grid_dir)?;
    let spec = grid.cell_spec(grid_dir, index)?;
    let cell = &grid.cells[index];
    tracing::info!(cell = index, method = %cell.method, out = %spec.out.display(), "grid: running");
    let start = Instant::now();
    let error_file = spec.out.join(CELL_ERROR_FILE);
    let result = run(&spec).map_err(|e| e.to_string());
    let seconds = start.elapsed().as_secs_f64();
    match &result {
        Ok(_) => {
            let _ = std::fs::remove_file(&error_file);
            let time = serde_json::json!({ "seconds": seconds }).to_string();
            let path = spec.out.join(CELL_TIME_FILE);
            gb_core::write_atomic(&path, time.as_bytes())
                .map_err(|e| InpaintError::io(&path, e))?;
        }
        Err(e) => {
            tracing::error!(cell = index, method = %cell.method, "grid: the run failed: {e}");
            std::fs::create_dir_all(&spec.out).map_err(|e| InpaintError::io(&spec.out, e))?;
            gb_core::write_atomic(&error_file, e.as_bytes())
                .map_err(|e| InpaintError::io(&error_file, e))?;
        }
    }
    Ok(RunOutcome {
        label: cell.dir.clone(),
        method: cell.dir.clone(),
        dir: cell.dir.clone(),
        result,
        seconds,
    })
}

/// Runs every cell of the grid in `grid_dir`, one after the other in this process, then
/// [`merge`]s: the single-process `cargo xtask ablate`.
pub fn run_all(grid_dir: &Path) -> Result<MergeReport, InpaintError> {
    let cells = Grid::read(grid_dir)?.cells.len();
    for i in 0..cells {
        run_cell(grid_dir, i)?;
    }
    merge(grid_dir)
}

/// Whether the run in the cell folder `dir` finished: its summary and wall time are written
/// and no error is recorded.
pub fn cell_finished(dir: &Path) -> bool {
    !dir.join(CELL_ERROR_FILE).is_file()
        && dir.join("metrics.json").is_file()
        && dir.join(CELL_TIME_FILE).is_file()
}

/// Reads a cell's outcome from its folder: the summary, the recorded error, or missing.
pub(crate) fn read_outcome(grid_dir: &Path, index: usize, cell: &GridCell) -> (RunOutcome, bool) {
    let dir = grid_dir.join(&cell.dir);
    let seconds = std::fs::read_to_string(dir.join(CELL_TIME_FILE))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|v| v["seconds"].as_f64())
        .unwrap_or(f64::NAN);
    let metrics = dir.join("metrics.json");
    let (result, missing) = if let Ok(err) = std::fs::read_to_string(dir.join(CELL_ERROR_FILE)) {
        (Err(err), false)
    } else if cell_finished(&dir) {
        (RunSummary::read(&metrics).map_err(|e| e.to_string()), false)
    } else {
        (Err(format!("cell {index} has not finished")), true)
    };
    let outcome = RunOutcome {
        label: cell.dir.clone(),
        method: cell.dir.clone(),
        dir: cell.dir.clone(),
        result,
        seconds,
    };
    (outcome, missing)
}
