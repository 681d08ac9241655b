//! `cargo xtask ablate`: the paper's method grid on one scene, and its tables
//! (`gb_grid`).
//!
//! ```text
//! cargo xtask ablate --scene DIR [--methods LIST] [--preset P] [--prior P] [--lora FILE]
//!     [--steps N] [--seed N] [--out DIR] [--w3 LIST] [--device D] [--weights DIR]
//!     [--orbit-frames N] [--emit slurm,kubernetes [--image I] [--cpus N] [--gpus N]]
//! cargo xtask ablate --grid GRID --cell I
//! cargo xtask ablate --grid GRID --merge
//! ```
//!
//! Plans the grid into `OUT/grid.toml` (every method file, prior and LoRA checked first),
//! runs its cells one after the other in this process, each into `OUT/METHOD/` (a complete
//! inpaint run: renders, metrics.json, config.toml, report.html; resumable), then writes
//! the tables:
//!
//! - `OUT/baselines.md` / `.json`: none, spin-nerf-sds, mvip-nerf, csd, gb-nerf;
//! - `OUT/ablation.md` / `.json`: origin = mvip-nerf (SDS on RGB and normals, no LoRA),
//!   +LoRA = sds-lora, +BSD = bsd, +LoRA+BSD = gb-nerf;
//! - `OUT/w3_sweep.md` / `.json` and `OUT/w3_sweep.svg`, `OUT/w3_sweep_psnr.svg`: csd with w3
//!   set to each value of `--w3` (default -1,-0.5,0,0.5,1) on both modalities, each into
//!   `OUT/csd-w3=X/` (the csd run itself is reused for the value of its config). The sweep
//!   runs when csd is in the grid or `--w3` is given.
//!
//! With `--emit slurm,kubernetes` it only plans the grid and writes `OUT/slurm.sh` (a Slurm
//! array job) and `OUT/job.yaml` (a Kubernetes Indexed Job), whose tasks run
//! `--grid OUT --cell I`; `--merge` then writes the tables and lists the missing cells.
//! Columns: masked-box SSIM, ST-LPIPS (when the weights exist), D-PSNR, PSNR, and time. A
//! run that fails is reported in the tables and makes the command exit with an error after
//! writing them. The no-prior run goes first and is every other run's `--baseline`.

use std::path::PathBuf;

use anyhow::bail;
use gb_grid::emit::{write_jobs, Engine};
use gb_grid::{self as grid, Grid, GridSettings, MergeReport};

use super::job_resources::JobResources;

/// Arguments of `cargo xtask ablate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene folder (LLFF / SPIn-NeRF or Blender layout, with masks).
    #[arg(long, required_unless_present = "grid_dir")]
    pub scene: Option<PathBuf>,
    /// The grid: methods, preset, prior, steps, device.
    #[command(flatten)]
    pub grid: gb_bench::GridArgs,
    /// LoRA file for the methods with `use_lora = true` (default: the prior's own).
    #[arg(long)]
    pub lora: Option<PathBuf>,
    /// Override the preset's training seed in every run.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Output folder.
    #[arg(long, default_value = "out/ablate")]
    pub out: PathBuf,
    /// Comma-separated w3 values of the CSD sweep (e.g. `--w3 -1,0,1`; default -1,-0.5,0,0.5,1).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub w3: Option<Vec<f64>>,
    /// Folder of metric weights (default `$GB_TEST_DATA/weights` when it exists).
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Frames of each run's orbit animation (0: none).
    #[arg(long, default_value_t = 0)]
    pub orbit_frames: usize,
    /// Only plan the grid into OUT and write its job files: slurm, kubernetes (comma-separated).
    #[arg(long, value_delimiter = ',')]
    pub emit: Option<Vec<Engine>>,
    /// The emitted jobs' image, cores and GPUs.
    #[command(flatten)]
    pub jobs: JobResources,
    /// A planned grid's folder: with --cell, run one cell; with --merge, write the tables.
    #[arg(long = "grid", value_name = "GRID", conflicts_with = "scene")]
    pub grid_dir: Option<PathBuf>,
    /// The index of the cell to run (with --grid).
    #[arg(long, requires = "grid_dir", conflicts_with = "merge")]
    pub cell: Option<usize>,
    /// Write the tables from the finished cells (with --grid).
    #[arg(long, requires = "grid_dir")]
    pub merge: bool,
}

/// Plans the grid of `scene` into `out`: the settings of `grid`, the training seed, LoRA,
/// weights, orbit frames and w3 sweep.
pub fn plan(args: &Args, scene: PathBuf) -> anyhow::Result<Grid> {
    let settings = GridSettings {
        lora: args.lora.clone(),
        weights: args.weights.clone(),
        orbit_frames: args.orbit_frames,
        ..args.grid.settings(scene, args.seed)
    };
    let grid = Grid::plan(
        settings,
        args.grid.methods.as_deref(),
        args.w3.as_deref(),
        &args.out,
    )?;
    grid.write(&args.out)?;
    Ok(grid)
}

/// Prints the tables and fails when a cell failed or is missing.
fn report(report: &MergeReport, grid_dir: &std::path::Path) -> anyhow::Result<()> {
    println!("{}", report.markdown);
    if !report.missing.is_empty() {
        bail!(
            "{} cell(s) have not finished: {:?} (run them with --grid {} --cell I)",
            report.missing.len(),
            report.missing,
            grid_dir.display()
        );
    }
    if !report.failed.is_empty() {
        let names: Vec<&str> = report.failed.iter().map(|(d, _)| d.as_str()).collect();
        bail!(
            "{} run(s) failed: {} (see the tables in {})",
            names.len(),
            names.join(", "),
            grid_dir.display()
        );
    }
    Ok(())
}

/// Runs the command.
pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(dir) = &args.grid_dir {
        if let Some(i) = args.cell {
            let outcome = grid::run_cell(dir, i)?;
            if let Err(e) = outcome.result {
                bail!("cell {i} ({}) failed: {e}", outcome.dir);
            }
            println!(
                "cell {i} ({}) finished in {:.1} s",
                outcome.dir, outcome.seconds
            );
            return Ok(());
        }
        if args.merge {
            return report(&grid::merge(dir)?, dir);
        }
        bail!("--grid {}: give --cell I or --merge", dir.display());
    }
    let Some(scene) = args.scene.clone() else {
        bail!("--scene is required (or --grid)");
    };
    let grid = plan(&args, scene)?;
    if let Some(engines) = &args.emit {
        let opts = args.jobs.emit_options();
        for path in write_jobs(&args.out, grid.cells.len(), engines, &opts)? {
            println!("wrote {}", path.display());
        }
        println!(
            "{} cell(s) in {}; merge with --grid {} --merge",
            grid.cells.len(),
            args.out.join(grid::GRID_FILE).display(),
            args.out.display()
        );
        return Ok(());
    }
    let start = std::time::Instant::now();
    let merged = grid::run_all(&args.out)?;
    println!(
        "ablate: {} run(s) in {:.1} s; tables in {}",
        grid.cells.len(),
        start.elapsed().as_secs_f64(),
        args.out.display()
    );
    report(&merged, &args.out)
}
