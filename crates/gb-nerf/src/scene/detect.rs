//! Scene format auto-detection: one entry point for every loader.

use super::blender::{self, BlenderOptions};
use super::llff::{self, LlffOptions};
use super::{Scene, SceneError};
use std::path::Path;

/// The on-disk layout of a scene folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SceneFormat {
    /// `poses_bounds.npy` + `images_N/` (LLFF, SPIn-NeRF, the procedural benchmark).
    Llff,
    /// `transforms_{train,test}.json` or `transforms.json` (Blender, nerfstudio).
    Blender,
}

/// Options for [`load`]; each loader uses its own part.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LoadOptions {
    /// LLFF options.
    pub llff: LlffOptions,
    /// Blender options.
    pub blender: BlenderOptions,
}

/// Detects the layout of `dir`: `transforms*.json` means Blender; `poses_bounds.npy` or an
/// `images*/` folder means LLFF (a missing `poses_bounds.npy` is then reported by the
/// loader). Errors: not a folder, an empty folder, or an unknown layout.
pub fn detect(dir: &Path) -> Result<SceneFormat, SceneError> {
    if !dir.is_dir() {
        return Err(SceneError::NotAFolder {
            path: dir.to_path_buf(),
        });
    }
    let mut entries = std::fs::read_dir(dir).map_err(|e| SceneError::io(dir, e))?;
    if entries.next().is_none() {
        return Err(SceneError::EmptyFolder {
            path: dir.to_path_buf(),
        });
    }
    if blender::is_blender(dir) {
        return Ok(SceneFormat::Blender);
    }
    if dir.join("poses_bounds.npy").exists() || llff::image_folder(dir, None).is_ok() {
        return Ok(SceneFormat::Llff);
    }
    Err(SceneError::UnknownLayout {
        path: dir.to_path_buf(),
    })
}

/// Detects the format of `dir` and loads it.
pub fn load(dir: &Path, opts: &LoadOptions) -> Result<(SceneFormat, Scene), SceneError> {
    let format = detect(dir)?;
    let scene = match format {
        SceneFormat::Llff => llff::load(dir, &opts.llff)?,
        SceneFormat::Blender => blender::load(dir, &opts.blender)?,
    };
    Ok((format, scene))
}
