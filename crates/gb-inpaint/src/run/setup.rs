//! Everything a run resolves before it trains: the method and preset (names or `.toml`
//! files), the prior spec, the scene (loaded, or the procedural `stairs` generated), and the
//! checks a user can fail (masks, output folder, baseline folder).

use std::path::{Path, PathBuf};

use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};
use gb_nerf::scene::{LoadOptions, Scene, Split};
use gb_nerf::train::NerfConfig;

use super::RunSpec;
use crate::error::InpaintError;
use crate::method::MethodConfig;
use crate::method::DEFAULT_METHOD;

/// The method name and prior spec of a run: by default [`DEFAULT_METHOD`] with the built-in
/// tiny prior; `prior = "none"` implies the method `none` unless one is given.
pub fn method_and_prior(spec: &RunSpec) -> (String, Option<String>) {
    match (&spec.method, &spec.prior) {
        (m, Some(p)) if p == "none" => (m.clone().unwrap_or_else(|| "none".into()), None),
        (m, Some(p)) => (
            m.clone().unwrap_or_else(|| DEFAULT_METHOD.into()),
            Some(p.clone()),
        ),
        (Some(m), None) => (m.clone(), Some("tiny".into())),
        (None, None) => (DEFAULT_METHOD.into(), Some("tiny".into())),
    }
}

/// The `[table]` of a run's `config.toml` (or of any TOML file that has it) as TOML text;
/// `None` when the file has no such table.
pub(crate) fn table_of(path: &Path, table: &str) -> Result<Option<String>, InpaintError> {
    let text = std::fs::read_to_string(path).map_err(|e| InpaintError::io(path, e))?;
    let Ok(v) = text.parse::<toml::Table>() else {
        return Ok(None);
    };
    match v.get(table).and_then(|p| p.as_table()) {
        Some(t) => toml::to_string(t)
            .map(Some)
            .map_err(|e| InpaintError::io(path, std::io::Error::other(e))),
        None => Ok(None),
    }
}

/// A preset name or `.toml` file; a run's `config.toml` contributes its `[preset]` table.
pub fn load_preset(spec: &str) -> Result<NerfConfig, InpaintError> {
    if spec.ends_with(".toml") {
        let path = Path::new(spec);
        if let Some(text) = table_of(path, "preset")? {
            return Ok(NerfConfig::from_toml(&text, path)?);
        }
    }
    Ok(NerfConfig::preset(spec)?)
}

/// A method name or `.toml` file; a run's `config.toml` contributes its `[method]` table.
pub fn load_method(spec: &str) -> Result<MethodConfig, InpaintError> {
    if spec.ends_with(".toml") {
        let path = Path::new(spec);
        if let Some(text) = table_of(path, "method")? {
            return MethodConfig::from_toml(&text, path);
        }
    }
    MethodConfig::load(spec)
}

/// The scene folder and the loaded scene: `spec.scene`, or the procedural `stairs` scene
/// generated into `OUT/scene` (once).
pub fn load_or_generate(spec: &RunSpec) -> Result<(PathBuf, Scene), InpaintError> {
    let dir = match &spec.scene {
        Some(d) => d.clone(),
        None => {
            let dir = spec.out.join("scene");
            if !dir.join("poses_bounds.npy").is_file() {
                let opts = ProceduralOptions {
                    name: SceneName::Stairs,
                    ..Default::default()
                };
                tracing::info!(dir = %dir.display(), "generating the procedural stairs scene");
                procedural::write(&opts, &dir).map_err(|source| InpaintError::Scene {
                    what: "generating scene",
                    path: dir.clone(),
                    source: Box::new(source),
                })?;
            }
            dir
        }
    };
    let scene = load_scene(&dir)?;
    Ok((dir, scene))
}

/// Loads the scene folder `dir` as a run does (no normalisation), its warnings logged.
pub(crate) fn load_scene(dir: &Path) -> Result<Scene, InpaintError> {
    let (_, scene) = gb_nerf::scene::load(dir, &LoadOptions::default()).map_err(|source| {
        InpaintError::Scene {
            what: "loading scene",
            path: dir.to_path_buf(),
            source: Box::new(source),
        }
    })?;
    for w in &scene.warnings {
        tracing::warn!("{w}");
    }
    Ok(scene)
}

/// Errors when no training view has a non-empty mask, or when a training view's mask covers
/// the whole image (no pixel of that view is left to supervise the NeRF: an inverted mask).
pub fn require_masks(scene: &Scene) -> Result<(), InpaintError> {
    let masked = scene
        .split(Split::Train)
        .filter(|v| v.mask.as_ref().is_some_and(|m| m.bbox().is_some()))
        .count();
    if masked == 0 {
        return Err(InpaintError::NoMasks {
            scene: scene.name.clone(),
        });
    }
    for view in scene.split(Split::Train) {
        if let Some(m) = view.mask.as_ref().filter(|m| m.data.iter().all(|&b| b)) {
            return Err(InpaintError::Spec {
                field: format!("scene '{}'", scene.name),
                reason: format!(
                    "the mask of training view '{}' covers the whole {}x{} image, so no pixel \
                     of it is left to supervise the NeRF (an inverted mask? masks are non-zero \
                     on the object only)",
                    view.name, m.width, m.height
                ),
            });
        }
    }
    Ok(())
}

/// Fails when `out` cannot be a folder: it, or the first of its ancestors that exists, is
/// not a folder; and when `baseline` is given but is not a folder. Checked before anything
/// is loaded; creating the output folder comes later.
pub fn check_paths(spec: &RunSpec) -> Result<(), InpaintError> {
    if let Some(existing) = spec.out.ancestors().find(|p| p.exists()) {
        if !existing.is_dir() {
            return Err(InpaintError::Spec {
                field: format!("--out {}", spec.out.display()),
                reason: format!(
                    "{} is a file, not a folder, so the output folder cannot be created",
                    existing.display()
                ),
            });
        }
    }
    if let Some(b) = spec.baseline.as_ref().filter(|b| !b.is_dir()) {
        return Err(InpaintError::Spec {
            field: format!("--baseline {}", b.display()),
            reason: "not a folder (expected another run's output folder)".into(),
        });
    }
    Ok(())
}
