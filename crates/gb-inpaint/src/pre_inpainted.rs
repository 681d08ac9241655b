//! The SPIn-NeRF + LaMa baseline's inputs: 2D-inpainted training images (and depths) that
//! replace the masked training views, which are then trained on every pixel (no mask).
//!
//! Where: `RGB_inpainted/` and `Depth_inpainted/`, in the scene folder or inside its image
//! folder `images_F/` (gb-nerf's `spin_extras`).
//!
//! Pairing: a training view `NAME` takes `RGB_inpainted/NAME.{png,jpg,jpeg}`; when no file
//! matches any training view by name, the sorted inpainted files are paired with the sorted
//! masked training views if their counts agree (with a warning). An inpainted image must
//! have its view's size.
//!
//! Depth (optional), per view:
//! - `Depth_inpainted/NAME.npy`: float32 z-depth `[H, W]` in scene units (the inpaint command
//!   loads LLFF scenes unnormalised, so these are the units of `poses_bounds.npy`);
//! - `Depth_inpainted/NAME.png` (8 or 16 bit grey): near-scaled disparity `near / z` in
//!   `[0, 1]` (the quantity gb-nerf's disparity loss compares; 0 = no depth). SPIn-NeRF's own
//!   PNGs are normalised disparities of a first NeRF, which this reading matches up to that
//!   NeRF's scale.
//!
//! Without a depth file, the view's existing depth (if any) is kept outside the mask and
//! dropped inside it, where it shows the removed object.

use std::path::{Path, PathBuf};

use gb_nerf::scene::llff::spin_extras;
use gb_nerf::scene::npy::read_float_array;
use gb_nerf::scene::{Scene, Split};

use crate::error::InpaintError;

/// What [`apply`] replaced.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct PreInpaintedReport {
    /// `RGB_inpainted/` folder used.
    pub rgb_dir: PathBuf,
    /// `Depth_inpainted/` folder used, if any.
    pub depth_dir: Option<PathBuf>,
    /// Training views whose image was replaced.
    pub images: usize,
    /// Training views whose depth was replaced.
    pub depths: usize,
    /// Non-fatal notes (pairing by order, ...).
    pub warnings: Vec<String>,
}

fn err(path: &Path, reason: impl Into<String>) -> InpaintError {
    InpaintError::PreInpainted {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

fn list_files(dir: &Path, exts: &[&str]) -> Result<Vec<PathBuf>, InpaintError> {
    let rd = std::fs::read_dir(dir).map_err(|e| InpaintError::io(dir, e))?;
    let mut out: Vec<PathBuf> = rd
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.is_file()
                && p.extension()
                    .and_then(|e| e.to_str())
                    .is_some_and(|e| exts.contains(&e.to_ascii_lowercase().as_str()))
        })
        .collect();
    out.sort();
    Ok(out)
}

fn stem(p: &Path) -> String {
    p.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Replaces the masked training views of `scene` (loaded from `scene_dir`) by their
/// inpainted images and depths, and drops their masks (see the module docs).
pub fn apply(scene: &mut Scene, scene_dir: &Path) -> Result<PreInpaintedReport, InpaintError> {
    let extras = spin_extras(scene_dir, None);
    let rgb_dir = extras.rgb_inpainted.ok_or_else(|| {
        err(
            scene_dir,
            "method pre-inpainted needs 2D-inpainted training images in RGB_inpainted/ (in the \
             scene folder or in its images_F/ folder, as in SPIn-NeRF); none found",
        )
    })?;
    let mut report = PreInpaintedReport {
        rgb_dir: rgb_dir.clone(),
        depth_dir: extras.depth_inpainted.clone(),
        ..Default::default()
    };
    let files = list_files(&rgb_dir, &["png", "jpg", "jpeg"])?;
    if files.is_empty() {
        return Err(err(&rgb_dir, "contains no PNG or JPEG image"));
    }
    let targets: Vec<usize> = scene
        .views
        .iter()
        .enumerate()
        .filter(|(_, v)| v.split == Split::Train && v.mask.is_some())
        .map(|(i, _)| i)
        .collect();
    let by_name = |name: &str| files.iter().find(|p| stem(p) == name).cloned();
    let any_named = targets
        .iter()
        .any(|&i| by_name(&scene.views[i].name).is_some());
    let pairs: Vec<(usize, PathBuf)> = if any_named {
        targets
            .iter()
            .map(|&i| {
                let name = &scene.views[i].name;
                by_name(name).map(|p| (i, p)).ok_or_else(|| {
                    err(
                        &rgb_dir.join(format!("{name}.png")),
                        format!("missing: training view {name} has a mask but no inpainted image"),
                    )
                })
            })
            .collect::<Result<_, _>>()?
    } else if files.len() == targets.len() {
        report.warnings.push(format!(
            "{}: no file is named after a training view; paired {} files with the masked \
             training views in sorted order",
            rgb_dir.display(),
            files.len()
        ));
        targets.iter().copied().zip(files.iter().cloned()).collect()
    } else {
        return Err(err(
            &rgb_dir,
            format!(
                "{} images, none named after a training view, and {} masked training views: \
                 cannot pair them",
                files.len(),
                targets.len()
            ),
        ));
    };
    let near = scene.near;
    for (i, path) in pairs {
        let view = &mut scene.views[i];
        let (w, h) = (view.image.width, view.image.height);
        let image = gb_core::read_rgb(&path, None).map_err(|e| err(&path, e.to_string()))?;
        if (image.width, image.height) != (w, h) {
            return Err(err(
                &path,
                format!(
                    "is {}x{} but training view {} is {w}x{h}",
                    image.width, image.height, view.name
                ),
            ));
        }
        view.image = image;
        report.images += 1;
        let depth = match &extras.depth_inpainted {
            Some(dir) => read_depth(dir, &view.name, w, h, near)?,
            None => None,
        };
        match depth {
            Some(d) => {
                view.depth = Some(d);
                report.depths += 1;
            }
            None => {
                if let (Some(d), Some(m)) = (view.depth.as_mut(), view.mask.as_ref()) {
                    for (v, masked) in d.iter_mut().zip(&m.data) {
                        if *masked {
                            *v = 0.0;
                        }
                    }
                }
            }
        }
        // the object's sparse points would pull the inpainted region back onto it
        if let (Some(m), Some(points)) = (view.mask.take(), scene.sparse_depth.get_mut(&view.name))
        {
            points.retain(|p| {
                let (x, y) = (p.x.max(0.0) as usize, p.y.max(0.0) as usize);
                x >= m.width || y >= m.height || !m.data[y * m.width + x]
            });
        }
    }
    if report.depth_dir.is_some() && report.depths == 0 {
        report.warnings.push(format!(
            "{}: no NAME.npy or NAME.png matched a training view; depths not replaced",
            report
                .depth_dir
                .as_ref()
                .map(|d| d.display().to_string())
                .unwrap_or_default()
        ));
    }
    for w in &report.warnings {
        tracing::warn!("{w}");
    }
    Ok(report)
}

/// Reads `dir/NAME.npy` (z-depth) or `dir/NAME.png` (near-scaled disparity); `None` when
/// neither exists.
fn read_depth(
    dir: &Path,
    name: &str,
    w: usize,
    h: usize,
    near: f32,
) -> Result<Option<Vec<f32>>, InpaintError> {
    let npy = dir.join(format!("{name}.npy"));
    if npy.is_file() {
        let arr = read_float_array(&npy).map_err(|e| err(&npy, e.to_string()))?;
        if arr.shape != [h as u64, w as u64] {
            return Err(err(
                &npy,
                format!("shape {:?} is not the view's [{h}, {w}]", arr.shape),
            ));
        }
        return Ok(Some(arr.data.into_iter().map(|v| v as f32).collect()));
    }
    let png = dir.join(format!("{name}.png"));
    if png.is_file() {
        let (pw, ph, values) = gb_core::read_gray(&png).map_err(|e| err(&png, e.to_string()))?;
        if (pw, ph) != (w, h) {
            return Err(err(&png, format!("is {pw}x{ph} but the view is {w}x{h}")));
        }
        return Ok(Some(
            values
                .into_iter()
                .map(|d| if d > 0.0 { near / d } else { 0.0 })
                .collect(),
        ));
    }
    Ok(None)
}
