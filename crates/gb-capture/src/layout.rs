//! Writing the scene folder (module docs of the crate): the LLFF layout.

use std::path::{Path, PathBuf};

use gb_nerf::scene::colmap::{rotation, write_binary, Image, Model};
use gb_nerf::scene::llff_poses::{encode_row, LlffPose};
use gb_nerf::scene::npy::encode_f64;

use crate::{CaptureError, CaptureReport};

/// The `q`-quantile (0..1) of sorted values, linearly interpolated (NumPy's default).
fn quantile(sorted: &[f64], q: f64) -> f64 {
    let pos = q * (sorted.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64)
}

/// The OpenGL camera-to-world pose (x right, y up, z back) of a registered COLMAP image
/// (world to camera, x right, y down, z forward).
pub fn opengl_c2w(image: &Image) -> [[f64; 4]; 3] {
    let r = rotation(image.qvec);
    let t = image.tvec;
    let centre: [f64; 3] = [0, 1, 2].map(|i| -(0..3).map(|k| r[k][i] * t[k]).sum::<f64>());
    [0, 1, 2].map(|i| [r[0][i], -r[1][i], -r[2][i], centre[i]])
}

/// Near and far of `image`: the 0.1 and 99.9 percentiles of its points' z-depth (LLFF's
/// `imgs2poses.py`); `None` when it sees no point.
fn bounds(model: &Model, image: &Image) -> Option<(f64, f64)> {
    let mut z: Vec<f64> = model
        .sparse_depth(image)
        .iter()
        .map(|d| d.depth as f64)
        .collect();
    if z.is_empty() {
        return None;
    }
    z.sort_by(f64::total_cmp);
    Some((quantile(&z, 0.001), quantile(&z, 0.999)))
}

/// A radial capture's undistortion, for [`write_scene`]: the photos' (distorted) model, and
/// the folder of the undistorted images that `model` describes.
pub struct Undistortion<'a> {
    /// The mapper's model of the photos.
    pub photos: &'a Model,
    /// `image_undistorter`'s images.
    pub images: &'a Path,
}

/// A mask file as bits (1 on the object).
fn mask_bits(path: &Path) -> Result<(usize, usize, Vec<f32>), CaptureError> {
    let (w, h, values) = gb_core::read_gray(path)?;
    let bits = values
        .iter()
        .map(|&v| if v > 0.0 { 1.0 } else { 0.0 })
        .collect();
    Ok((w, h, bits))
}

/// Writes the scene: `images/`, `images/label/`, `sparse/0/` and `poses_bounds.npy` for the
/// images that `model` (read from `model_dir`) registered (module docs of the crate). With an
/// [`Undistortion`], `model` is the undistorted one: each image comes from the undistorted
/// folder and its mask is mapped from the photo's camera to it
/// ([`crate::undistort::undistort_mask`]). `out/images` and `out/sparse` are replaced.
pub fn write_scene(
    out: &Path,
    images: &[PathBuf],
    masks: &[Option<PathBuf>],
    model: &Model,
    model_dir: &Path,
    undistortion: Option<&Undistortion>,
) -> Result<CaptureReport, CaptureError> {
    let image_dir = out.join("images");
    let label_dir = image_dir.join("label");
    for dir in [&image_dir, &out.join("sparse")] {
        if dir.exists() {
            std::fs::remove_dir_all(dir).map_err(|e| CaptureError::io(dir, e))?;
        }
    }
    std::fs::create_dir_all(&label_dir).map_err(|e| CaptureError::io(&label_dir, e))?;
    let by_name = |name: &str| model.images.values().find(|i| i.name == name);
    let all_bounds: Vec<(f64, f64)> = model
        .images
        .values()
        .filter_map(|i| bounds(model, i))
        .collect();
    let fallback = (
        all_bounds.iter().map(|b| b.0).fold(f64::INFINITY, f64::min),
        all_bounds.iter().map(|b| b.1).fold(0.0, f64::max),
    );
    let mut rows = Vec::new();
    let mut report = CaptureReport {
        images: images.len(),
        registered: 0,
        masked: 0,
        points: model.points.len(),
        left_out: Vec::new(),
        distortion: None,
    };
    for (path, mask) in images.iter().zip(masks) {
        let name = crate::file_name(path);
        let Some(image) = by_name(&name) else {
            report.left_out.push(name);
            continue;
        };
        let bad_model = |reason: String| gb_nerf::scene::SceneError::Colmap {
            path: model_dir.to_path_buf(),
            reason,
        };
        let camera = model.cameras.get(&image.camera_id).ok_or_else(|| {
            bad_model(format!(
                "image {name} names camera {} which is not in the model",
                image.camera_id
            ))
        })?;
        // SIMPLE_PINHOLE's first parameter is its focal length; an undistorted PINHOLE
        // camera must have one, and its principal point at the centre
        let focal =
            if camera.model == "PINHOLE" {
                crate::undistort::check_centred(camera, image.camera_id).map_err(bad_model)?
            } else {
                camera.params.first().copied().ok_or_else(|| {
                    bad_model(format!("camera {} has no parameters", image.camera_id))
                })?
            };
        let (src, mask) = match undistortion {
            None => (path.clone(), mask.as_deref().map(mask_bits).transpose()?),
            Some(u) => {
                let src = u.images.join(&name);
                if !src.is_file() {
                    return Err(bad_model(format!(
                        "image_undistorter wrote no {} (see colmap/image_undistorter.log)",
                        src.display()
                    ))
                    .into());
                }
                let photo_camera = u
                    .photos
                    .images
                    .values()
                    .find(|i| i.name == name)
                    .and_then(|i| u.photos.cameras.get(&i.camera_id))
                    .ok_or_else(|| {
                        bad_model(format!(
                            "{name} is undistorted but not in the photos' model"
                        ))
                    })?;
                // each mask's size was checked against its photo's before COLMAP ran
                let mask = match mask {
                    Some(m) => {
                        let (w, h, bits) = mask_bits(m)?;
                        let mapped = crate::undistort::undistort_mask(photo_camera, camera, &bits)
                            .ok_or_else(|| {
                                bad_model(format!(
                                    "cannot map the {w}x{h} mask {} from a {} camera ({}x{}) \
                                     to a {} one",
                                    m.display(),
                                    photo_camera.model,
                                    photo_camera.width,
                                    photo_camera.height,
                                    camera.model
                                ))
                            })?;
                        Some((camera.width as usize, camera.height as usize, mapped))
                    }
                    None => None,
                };
                (src, mask)
            }
        };
        let dst = image_dir.join(&name);
        std::fs::copy(&src, &dst).map_err(|e| CaptureError::io(&dst, e))?;
        if let Some((w, h, bits)) = &mask {
            let dst = label_dir.join(format!("{}.png", gb_nerf::scene::files::stem(path)));
            gb_core::write_gray_png(&dst, *w, *h, bits)?;
            report.masked += 1;
        }
        let (near, far) = bounds(model, image).unwrap_or(fallback);
        rows.extend(encode_row(&LlffPose {
            c2w: opengl_c2w(image),
            height: camera.height as f64,
            width: camera.width as f64,
            focal,
            near,
            far,
        }));
        report.registered += 1;
    }
    let n = report.registered as u64;
    let npy = out.join("poses_bounds.npy");
    let bytes = encode_f64(&[n, 17], &rows).map_err(|e| CaptureError::io(&npy, e))?;
    gb_core::write_atomic(&npy, &bytes).map_err(|e| CaptureError::io(&npy, e))?;
    write_binary(model, &out.join("sparse/0"))?;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_interpolate_like_numpy() {
        let v: Vec<f64> = (0..=10).map(f64::from).collect();
        assert_eq!(quantile(&v, 0.0), 0.0);
        assert_eq!(quantile(&v, 1.0), 10.0);
        assert!((quantile(&v, 0.25) - 2.5).abs() < 1e-12);
        assert!((quantile(&v, 0.999) - 9.99).abs() < 1e-9);
    }

    /// A camera at (1, 2, 3) looking down world -z with COLMAP's y down: its OpenGL pose
    /// has the identity rotation and its centre as translation.
    #[test]
    fn colmap_poses_become_opengl_camera_to_world() {
        // world to camera: x_cam = R (X - C) with R = diag(1, -1, -1)
        let image = Image {
            qvec: [0.0, 1.0, 0.0, 0.0],
            tvec: [-1.0, 2.0, 3.0],
            camera_id: 1,
            name: "a.png".into(),
            points2d: Vec::new(),
        };
        let c2w = opengl_c2w(&image);
        let want = [
            [1.0, 0.0, 0.0, 1.0],
            [0.0, 1.0, 0.0, 2.0],
            [0.0, 0.0, 1.0, 3.0],
        ];
        for i in 0..3 {
            for j in 0..4 {
                assert!((c2w[i][j] - want[i][j]).abs() < 1e-12, "{c2w:?}");
            }
        }
    }
}
