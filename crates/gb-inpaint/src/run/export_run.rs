//! The nerfstudio export of a finished run, from its checkpoint, without training
//! (`cargo xtask export --run OUT`): the files `inpaint --export full` writes at the end of a
//! run ([`crate::export`]), for any run made with `--export none` (the default).

use std::path::{Path, PathBuf};

use gb_core::BackendKind;

use crate::error::InpaintError;
use crate::export::{write_export, ExportInfo};
use crate::trainer::GuidedTrainer;

/// Writes the export of the run folder `run` (its `config.toml` and `checkpoint.bin`) into
/// `to` (default `RUN/export`), with `orbit_frames` cameras in `camera_path.json` (0: none),
/// rendering on `device` (default: the run's, `[run] device`, so that the renders are the
/// run's own). The scene is the run's (`[run] scene`), with its pre-inpainted images when the
/// run's method used them, so that the checkpoint's training data matches. A checkpoint
/// short of the run's step count is exported with a warning.
pub fn export_run(
    run: &Path,
    to: Option<&Path>,
    orbit_frames: usize,
    device: Option<BackendKind>,
) -> Result<ExportInfo, InpaintError> {
    let config = run.join("config.toml");
    let ckpt = run.join("checkpoint.bin");
    for file in [&config, &ckpt] {
        if !file.is_file() {
            return Err(InpaintError::Spec {
                field: format!("--run {}", run.display()),
                reason: format!(
                    "{} is missing: give the output folder of a finished `inpaint` run",
                    file.display()
                ),
            });
        }
    }
    let recorded = RunTable::read(&config)?;
    let scene_dir = recorded.scene;
    let device = device.unwrap_or(recorded.device);
    let method = super::load_method(&config.display().to_string())?;
    let mut scene = super::setup::load_scene(&scene_dir)?;
    if method.pre_inpainted {
        crate::pre_inpainted::apply(&mut scene, &scene_dir)?;
    }
    let trainer = GuidedTrainer::for_rendering(&scene, &ckpt, device)?;
    if trainer.step < trainer.config.train.steps {
        tracing::warn!(
            step = trainer.step,
            steps = trainer.config.train.steps,
            "the checkpoint is not at the run's last step: exporting the field as it is"
        );
    }
    let dir = to.map_or_else(|| run.join("export"), Path::to_path_buf);
    write_export(&dir, &scene, &trainer, orbit_frames)
}

/// What `export_run` reads of a run's `config.toml`'s `[run]` table.
#[derive(serde::Deserialize)]
struct RunTable {
    /// The scene folder (absolute since 2026-12-05; an older run's may be relative to the
    /// folder it was started from).
    scene: PathBuf,
    /// The backend the run trained on.
    device: BackendKind,
}

impl RunTable {
    fn read(config: &Path) -> Result<Self, InpaintError> {
        let bad = |reason: String| InpaintError::Spec {
            field: config.display().to_string(),
            reason,
        };
        let table = super::setup::table_of(config, "run")?
            .ok_or_else(|| bad("no [run] table: not the config.toml of an `inpaint` run".into()))?;
        toml::from_str(&table).map_err(|e| bad(format!("[run]: {}", e.message())))
    }
}
