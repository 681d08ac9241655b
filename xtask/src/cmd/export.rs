//! `cargo xtask export`: the nerfstudio export of a finished run, from its checkpoint, without
//! training (`gb_inpaint::run::export_run`).
//!
//! ```text
//! cargo xtask export --run OUT [--to DIR] [--orbit-frames N] [--device D]
//! ```
//!
//! Writes `DIR` (default `OUT/export/`): every training view rendered at the training
//! resolution (`images/`, 16-bit `depth/`), `transforms.json` and the orbit's
//! `camera_path.json` (`gb_inpaint::export`). `inpaint --export full` writes the same files at
//! the end of a run.

use std::path::PathBuf;

use gb_core::BackendKind;

/// Arguments of `cargo xtask export`.
#[derive(clap::Args)]
pub struct Args {
    /// A finished run's output folder (`inpaint --out`), with its config.toml and
    /// checkpoint.bin.
    #[arg(long)]
    run: PathBuf,
    /// The export folder (default: RUN/export).
    #[arg(long)]
    to: Option<PathBuf>,
    /// Cameras of camera_path.json along the orbit through the scene's cameras, as
    /// `inpaint --orbit-frames` (0: none).
    #[arg(long, default_value_t = 24)]
    orbit_frames: usize,
    /// Compute backend: ndarray, flex or wgpu (default: the run's).
    #[arg(long, value_enum)]
    device: Option<BackendKind>,
}

/// Writes the export and prints what it wrote.
pub fn run(args: Args) -> anyhow::Result<()> {
    let info = gb_inpaint::run::export_run(
        &args.run,
        args.to.as_deref(),
        args.orbit_frames,
        args.device,
    )?;
    println!(
        "wrote {} views ({}x{}) to {} in {:.1} s",
        info.views,
        info.width,
        info.height,
        info.folder.display(),
        info.seconds
    );
    Ok(())
}
