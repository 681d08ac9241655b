//! The geometry term's unguided field ([`crate::geometry`]): the field of the run's
//! configuration trained without any hidden-region term, whose depth through the hidden pixels
//! the term holds. It is the `none` run of the same preset, seed, scene and device, so a
//! finished `--baseline` run of `--method none` that matches all of these is that field
//! already: its checkpoint is read instead of training it again (about 45 s of a `fast` run on
//! 2 CPU cores, a whole `none` run at `balanced`). Anything that does not match, to the exact
//! configuration, is said in one line and the field is trained as before.
//!
//! The same baseline is the whole field of a run that trains exactly as `none`: an `auto`
//! choice of zero weights ([`baseline_field`]), which then only renders and scores.

use std::path::{Path, PathBuf};
use std::time::Instant;

use gb_core::Devices;
use gb_nerf::scene::Scene;
use gb_nerf::train::checkpoint::load;
use gb_nerf::train::{NerfConfig, Trainer};

use crate::error::InpaintError;
use crate::geometry::HiddenDepth;
use crate::resume::{identity, identity_difference, preset_difference, GuidedState, RunTotals};
use crate::trainer::{FitOptions, GuidedTrainer};
use crate::MethodConfig;

/// The geometry term's targets, how long they took, and the baseline checkpoint they were
/// read from (`None`: trained in this run).
pub(super) struct UnguidedDepth {
    pub targets: HiddenDepth,
    pub seconds: f64,
    pub from: Option<PathBuf>,
}

/// The geometry term's targets: the unguided field's depth through the pixels `method`
/// holds. The field is `baseline`'s checkpoint when [`baseline_field`] accepts it, else
/// trained here from the run's `config` with the built-in `none` (the same seed, so the same
/// initialisation and rays as `--method none`).
pub(super) fn unguided_depth(
    scene: &Scene,
    config: &NerfConfig,
    method: &MethodConfig,
    devices: &Devices,
    baseline: Option<&Path>,
    progress: bool,
) -> Result<UnguidedDepth, InpaintError> {
    let start = Instant::now();
    let reused = match baseline {
        Some(dir) => match baseline_field(dir, scene, config, devices) {
            Ok((field, _, path)) => Some((field, path)),
            Err(reason) => {
                tracing::info!(
                    "geometry: --baseline {} is not this run's unguided field ({reason}), so it \
                     is trained",
                    dir.display()
                );
                None
            }
        },
        None => None,
    };
    let (field, from) = match reused {
        Some((field, path)) => (field, Some(path)),
        None => {
            let none = MethodConfig::builtin("none")?;
            let mut field = GuidedTrainer::new(scene, config.clone(), none, None, devices)?;
            field.fit(&FitOptions {
                checkpoint: None,
                log: None,
                append_log: false,
                progress,
            })?;
            (field.nerf, None)
        }
    };
    let targets = HiddenDepth::from_field(&field, method.geometry.clone(), method.crop_margin)?;
    let seconds = start.elapsed().as_secs_f64();
    let source = from
        .as_deref()
        .map_or_else(|| "trained".to_string(), |p| p.display().to_string());
    tracing::info!(
        pixels = targets.pixels.len(),
        region = ?method.geometry.region,
        seconds,
        from = %source,
        "geometry: the unguided field's depth through the held pixels"
    );
    Ok(UnguidedDepth {
        targets,
        seconds,
        from,
    })
}

/// The field of `dir` (a run folder, or its `renders/`) when it holds a finished checkpoint
/// of the built-in `none` with no reference, with `config` (any cadence of checkpoints; the
/// step count is the run's), trained on the same backend (its `metrics.json`'s `device`) on
/// the same scene and training data (checked as the field is restored): the restored
/// reconstruction trainer, the baseline's counters and its checkpoint's path. Otherwise the
/// first thing that differs, in words. The unguided pass renders its depth; a run that trains
/// exactly as `none` (an `auto` choice of zero weights) wraps it in its own method.
pub(super) fn baseline_field(
    dir: &Path,
    scene: &Scene,
    config: &NerfConfig,
    devices: &Devices,
) -> Result<(Trainer, RunTotals, PathBuf), String> {
    let run = if dir.file_name().is_some_and(|n| n == "renders") {
        dir.parent().unwrap_or(dir)
    } else {
        dir
    };
    let path = run.join("checkpoint.bin");
    if !path.is_file() {
        return Err(format!("no {}", path.display()));
    }
    let metrics = run.join("metrics.json");
    let device = std::fs::read_to_string(&metrics)
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|v| v.get("device").and_then(|d| d.as_str()).map(str::to_owned))
        .ok_or_else(|| format!("no device in {}", metrics.display()))?;
    if device != devices.name() {
        return Err(format!(
            "trained on {device}, this run on {}",
            devices.name()
        ));
    }
    let mut parts = load(&path).map_err(|e| e.to_string())?;
    if parts.meta.step != config.train.steps {
        return Err(format!(
            "its checkpoint is at step {} of this run's {}",
            parts.meta.step, config.train.steps
        ));
    }
    let stored = parts.meta.config(&path).map_err(|e| e.to_string())?;
    if let Some(d) = preset_difference(&stored, config).map_err(|e| format!("its preset: {e}"))? {
        return Err(format!("its preset differs: {d}"));
    }
    let state: GuidedState = serde_json::from_value(parts.meta.extra.take())
        .map_err(|_| "it was not written by a run of `inpaint`".to_string())?;
    let none = MethodConfig::builtin("none").map_err(|e| e.to_string())?;
    let id = identity(&none, None)?;
    if let Some(d) = identity_difference(&state.identity_toml, &id, true)
        .map_err(|e| format!("its run identity: {e}"))?
    {
        return Err(format!("it is not the built-in none: {d}"));
    }
    let nerf = Trainer::resume_from(scene, &path, parts, config.clone(), devices)
        .map_err(|e| e.to_string())?;
    Ok((nerf, state.totals, path))
}
