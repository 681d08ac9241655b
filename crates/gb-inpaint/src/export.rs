//! The export of a run (`OUT/export/`): the inpainted scene as a nerfstudio dataset, for the
//! tools one trains next (nerfstudio, its gsplat-based splatfacto):
//!
//! ```text
//! export/transforms.json     nerfstudio format (see transforms): OPENCV pinhole cameras,
//!                            OpenGL camera-to-world, depth_unit_scale_factor
//! export/images/NAME.png     the trained field's render of every training view (8-bit RGB),
//!                            at the training resolution (the preset's image_downscale)
//! export/depth/NAME.png      its z-depth, 16-bit PNG: value * depth_unit_scale_factor (see
//!                            depth_png), 0 = none
//! export/camera_path.json    the orbit of orbit.gif (gif::orbit_path) in nerfstudio's
//!                            camera-path format (see camera_path); only with orbit frames
//! ```
//!
//! **Cameras.** The run loads its scene without normalisation (`gb_nerf::scene::load` with
//! default options: no LLFF recentring or rescaling, LLFF axes converted to OpenGL), and the
//! trainer keeps the cameras as loaded, so the exported poses are the scene's own world frame
//! and units; nothing is undone and nothing needs recording. Intrinsics are the training
//! views' at the training resolution. Reading the folder with `gb_nerf::scene::load` gives
//! back exactly these cameras, names and sizes, with `near`, `far` and (bounded scenes) the
//! box of the run; a forward-facing scene reads back as bounded, since `transforms.json`
//! has no forward-facing flag.
//!
//! **nerfstudio.** `ns-train nerfacto --data OUT/export` (or `depth-nerfacto`, `splatfacto`)
//! reads it; nerfstudio recentres and rescales poses itself (and scales the depths with
//! them). The depth PNGs are in millimetres (nerfstudio's default
//! `--depth-unit-scale-factor 1e-3`) unless the scene is deeper than 65.535 units; then pass
//! the file's `depth_unit_scale_factor`. `camera_path.json` is in the export's world frame:
//! for `ns-render camera-path` train with `--orientation-method none --center-method none
//! --auto-scale-poses False`, or apply the run's `dataparser_transforms.json` to it.

mod camera_path;
mod depth_png;
mod transforms;

pub use camera_path::{camera_path_json, flattened_c2w, vertical_fov_degrees};
pub use depth_png::{depth_unit_for, quantise_depth, read_depth_png, write_depth_png, MILLIMETRE};
pub use transforms::{depth_path, homogeneous, image_path, transforms_json};

use std::path::{Path, PathBuf};
use std::time::Instant;

use gb_nerf::scene::{Camera, Scene, Split};
use gb_nerf::train::data::downscale_camera;
use serde::{Deserialize, Serialize};

use crate::error::InpaintError;
use crate::gif::{orbit_path, ORBIT_FPS};
use crate::GuidedTrainer;

/// Whether a run writes the nerfstudio export (`--export`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ExportMode {
    /// `OUT/export/`: every training view rendered, its depth, the cameras and the orbit.
    Full,
    /// No export (the default: it renders every training view, which on a real capture costs
    /// as much as the training on a CPU; `cargo xtask export --run OUT` writes it later from
    /// the run's checkpoint, [`crate::run::export_run`]).
    #[default]
    None,
}

impl std::str::FromStr for ExportMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "full" => Ok(Self::Full),
            "none" => Ok(Self::None),
            _ => Err(format!("'{s}': expected full or none")),
        }
    }
}

impl ExportMode {
    /// True for [`ExportMode::Full`].
    pub fn enabled(self) -> bool {
        self == ExportMode::Full
    }
}

/// What [`write_export`] wrote.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ExportInfo {
    /// The export folder.
    pub folder: PathBuf,
    /// Number of exported training views.
    pub views: usize,
    /// Width of the exported images (the first view's).
    pub width: usize,
    /// Height of the exported images (the first view's).
    pub height: usize,
    /// Scene units per step of the depth PNGs.
    pub depth_unit_scale_factor: f64,
    /// Frames of `camera_path.json` (0: not written).
    pub camera_path_frames: usize,
    /// Wall time of the renders and the writes.
    pub seconds: f64,
}

fn write_text(path: &Path, text: serde_json::Result<String>) -> Result<(), InpaintError> {
    let text = text.map_err(|e| InpaintError::io(path, std::io::Error::other(e)))?;
    gb_core::write_atomic(path, text.as_bytes()).map_err(|e| InpaintError::io(path, e))
}

fn create_dir(dir: &Path) -> Result<(), InpaintError> {
    std::fs::create_dir_all(dir).map_err(|e| InpaintError::io(dir, e))
}

/// Writes the export of a trained run into `dir` (see the module docs): every training view
/// of `scene` rendered by `trainer` at the training resolution, `transforms.json`, and the
/// `orbit_frames` cameras of the run's orbit as `camera_path.json` (none when 0).
pub fn write_export(
    dir: &Path,
    scene: &Scene,
    trainer: &GuidedTrainer,
    orbit_frames: usize,
) -> Result<ExportInfo, InpaintError> {
    let start = Instant::now();
    let (images, depths) = (dir.join("images"), dir.join("depth"));
    create_dir(&images)?;
    create_dir(&depths)?;
    let downscale = trainer.config.train.image_downscale.max(1);
    let mut views: Vec<(String, Camera)> = Vec::new();
    let mut depth_maps: Vec<Vec<f32>> = Vec::new();
    for view in scene.split(Split::Train) {
        let camera = downscale_camera(&view.camera, downscale);
        let render = trainer.render(&camera)?;
        let path = dir.join(image_path(&view.name));
        gb_core::write_rgb_png(&path, &render.rgb)
            .map_err(|e| InpaintError::io(&path, std::io::Error::other(e.to_string())))?;
        depth_maps.push(render.depth);
        views.push((view.name.clone(), camera));
    }
    let max_depth = depth_maps
        .iter()
        .flatten()
        .copied()
        .filter(|d| d.is_finite())
        .fold(0.0f32, f32::max);
    let unit = depth_unit_for(max_depth);
    for ((name, camera), depth) in views.iter().zip(&depth_maps) {
        let path = dir.join(depth_path(name));
        write_depth_png(&path, camera.width, camera.height, depth, unit)?;
    }
    write_text(
        &dir.join("transforms.json"),
        transforms_json(&views, unit, scene),
    )?;
    let orbit = orbit_path(scene, trainer, orbit_frames);
    let path_file = dir.join("camera_path.json");
    match camera_path_json(&orbit, ORBIT_FPS) {
        Some(text) => write_text(&path_file, text)?,
        // no orbit: no path, also none left from an earlier run into the same folder
        None => match std::fs::remove_file(&path_file) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(InpaintError::io(&path_file, e))
            }
            _ => {}
        },
    }
    let info = ExportInfo {
        folder: dir.to_path_buf(),
        views: views.len(),
        width: views.first().map_or(0, |(_, c)| c.width),
        height: views.first().map_or(0, |(_, c)| c.height),
        depth_unit_scale_factor: unit,
        camera_path_frames: orbit.len(),
        seconds: start.elapsed().as_secs_f64(),
    };
    tracing::info!(
        folder = %dir.display(), views = info.views, depth_unit = unit,
        camera_path_frames = info.camera_path_frames, "wrote the nerfstudio export"
    );
    Ok(info)
}
