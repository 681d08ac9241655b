//! Undistortion of a capture fitted with a radial lens (`--camera radial`): COLMAP's
//! `image_undistorter` writes the images and the model of an ideal `PINHOLE` camera (one focal
//! length, the principal point at the new image's centre), which is what the LLFF layout
//! holds; the object masks go through the same mapping here ([`undistort_mask`]), nearest
//! pixel, so they stay binary.

use std::path::{Path, PathBuf};

use gb_nerf::scene::colmap::{Camera, Model};

use crate::CaptureError;

/// What `image_undistorter` wrote: the undistorted images' folder and model.
pub struct Undistorted {
    /// `OUT/images/NAME` for each registered image.
    pub images: PathBuf,
    /// The model of the undistorted images (`PINHOLE` cameras).
    pub model: Model,
    /// Its folder.
    pub sparse: PathBuf,
}

/// Runs `colmap image_undistorter` on the model in `sparse` (its images in `images`) into
/// `work/undistorted`, and reads the result back.
pub fn undistort(
    program: &Path,
    images: &Path,
    sparse: &Path,
    work: &Path,
) -> Result<Undistorted, CaptureError> {
    let out = work.join("undistorted");
    if out.exists() {
        std::fs::remove_dir_all(&out).map_err(|e| CaptureError::io(&out, e))?;
    }
    let s = |p: &Path| p.display().to_string();
    crate::colmap::run(
        program,
        "image_undistorter",
        &[
            "--image_path",
            &s(images),
            "--input_path",
            &s(sparse),
            "--output_path",
            &s(&out),
            "--output_type",
            "COLMAP",
        ],
        work,
    )?;
    let sparse = out.join("sparse");
    let model = Model::read(&sparse)?;
    Ok(Undistorted {
        images: out.join("images"),
        model,
        sparse,
    })
}

/// The map from the undistorted `PINHOLE` camera's pixels to the distorted photo's (a
/// `RADIAL`, `SIMPLE_RADIAL` or pinhole camera), its parameters read once.
struct Mapping {
    /// `fx, fy, cx, cy` of the undistorted camera.
    to: (f64, f64, f64, f64),
    /// `f, cx, cy, k1, k2` of the photo's camera.
    from: (f64, f64, f64, f64, f64),
    /// The photo's size.
    size: (f64, f64),
}

impl Mapping {
    /// `None` when either camera is not of the models above.
    fn new(from: &Camera, to: &Camera) -> Option<Self> {
        Some(Self {
            to: pinhole(to)?,
            from: radial(from)?,
            size: (from.width as f64, from.height as f64),
        })
    }

    /// The photo's pixel that the centre of pixel `(x, y)` sees; `None` outside the photo.
    fn source(&self, x: usize, y: usize) -> Option<(usize, usize)> {
        let (fx, fy, cx, cy) = self.to;
        let (f, pcx, pcy, k1, k2) = self.from;
        let u = (x as f64 + 0.5 - cx) / fx;
        let v = (y as f64 + 0.5 - cy) / fy;
        let r2 = u * u + v * v;
        let d = 1.0 + k1 * r2 + k2 * r2 * r2;
        let (px, py) = (f * u * d + pcx, f * v * d + pcy);
        let inside = px >= 0.0 && py >= 0.0 && px < self.size.0 && py < self.size.1;
        inside.then_some((px as usize, py as usize))
    }
}

/// The pixel of the distorted image `from` (a `RADIAL`, `SIMPLE_RADIAL` or pinhole camera)
/// that the centre of pixel `(x, y)` of the undistorted `PINHOLE` camera `to` sees; `None`
/// outside `from`'s image. COLMAP's convention: pixel `(i, j)` covers `[i, i + 1) x [j, j + 1)`.
pub fn source_pixel(from: &Camera, to: &Camera, x: usize, y: usize) -> Option<(usize, usize)> {
    Mapping::new(from, to)?.source(x, y)
}

/// `(fx, fy, cx, cy)` of a `PINHOLE` camera.
fn pinhole(c: &Camera) -> Option<(f64, f64, f64, f64)> {
    match (c.model.as_str(), c.params.as_slice()) {
        ("PINHOLE", [fx, fy, cx, cy]) => Some((*fx, *fy, *cx, *cy)),
        ("SIMPLE_PINHOLE", [f, cx, cy]) => Some((*f, *f, *cx, *cy)),
        _ => None,
    }
}

/// `(f, cx, cy, k1, k2)` of a `RADIAL`, `SIMPLE_RADIAL` or `SIMPLE_PINHOLE` camera.
fn radial(c: &Camera) -> Option<(f64, f64, f64, f64, f64)> {
    match (c.model.as_str(), c.params.as_slice()) {
        ("RADIAL", [f, cx, cy, k1, k2]) => Some((*f, *cx, *cy, *k1, *k2)),
        ("SIMPLE_RADIAL", [f, cx, cy, k]) => Some((*f, *cx, *cy, *k, 0.0)),
        ("SIMPLE_PINHOLE", [f, cx, cy]) => Some((*f, *cx, *cy, 0.0, 0.0)),
        _ => None,
    }
}

/// The mask `bits` (`from`'s size, row-major, 1 on the object) as the undistorted camera `to`
/// sees it; `None` when either camera is not of the models above or `bits` is not `from`'s
/// size.
pub fn undistort_mask(from: &Camera, to: &Camera, bits: &[f32]) -> Option<Vec<f32>> {
    let map = Mapping::new(from, to)?;
    let from_w = from.width as usize;
    if bits.len() != from_w * from.height as usize {
        return None;
    }
    let (w, h) = (to.width as usize, to.height as usize);
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            if let Some((i, j)) = map.source(x, y) {
                out[y * w + x] = bits[j * from_w + i];
            }
        }
    }
    Some(out)
}

/// The undistorted camera's shape for the LLFF layout (one focal length, the principal point
/// at the centre): an error naming the model when it is not. COLMAP 3.8's undistortion of a
/// `RADIAL` camera keeps its one focal length and scales the principal point with the image,
/// so it stays at the centre as long as the mapper does not refine it (its default, which
/// [`crate::colmap::reconstruct`] keeps) and no `max_image_size` rescales the output.
pub fn check_centred(camera: &Camera, id: i32) -> Result<f64, String> {
    let (fx, fy, cx, cy) =
        pinhole(camera).ok_or_else(|| format!("camera {id} is {}, not PINHOLE", camera.model))?;
    let (w, h) = (camera.width as f64, camera.height as f64);
    if (fx - fy).abs() > 1e-6 * fx || (cx - w / 2.0).abs() > 0.5 || (cy - h / 2.0).abs() > 0.5 {
        return Err(format!(
            "camera {id} (fx {fx}, fy {fy}, cx {cx}, cy {cy}, {w}x{h}) has not one focal length \
             and its principal point at the centre, which the LLFF layout assumes"
        ));
    }
    Ok(fx)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(model: &str, width: u64, height: u64, params: &[f64]) -> Camera {
        Camera {
            model: model.into(),
            width,
            height,
            params: params.to_vec(),
        }
    }

    #[test]
    fn without_distortion_the_mask_maps_onto_itself() {
        let from = camera("SIMPLE_RADIAL", 8, 6, &[10.0, 4.0, 3.0, 0.0]);
        let to = camera("PINHOLE", 8, 6, &[10.0, 10.0, 4.0, 3.0]);
        let bits: Vec<f32> = (0..48).map(|i| (i % 3 == 0) as u8 as f32).collect();
        assert_eq!(undistort_mask(&from, &to, &bits).unwrap(), bits);
    }

    #[test]
    fn barrel_distortion_pulls_the_edges_in() {
        // k1 < 0: a point far from the centre is seen nearer to it in the photo
        let from = camera("RADIAL", 101, 101, &[50.0, 50.5, 50.5, -0.2, 0.0]);
        let to = camera("PINHOLE", 101, 101, &[50.0, 50.0, 50.5, 50.5]);
        assert_eq!(source_pixel(&from, &to, 50, 50), Some((50, 50)));
        // pixel 100's centre: u = 50 / 50 = 1, r2 = 1, d = 0.8 -> 40 px from the centre
        assert_eq!(source_pixel(&from, &to, 100, 50), Some((90, 50)));
        let far = camera("RADIAL", 101, 101, &[50.0, 50.5, 50.5, 0.5, 0.0]);
        // pincushion: the same pixel lies outside the photo
        assert_eq!(source_pixel(&far, &to, 100, 50), None);
        assert!(undistort_mask(&camera("OPENCV", 1, 1, &[0.0; 8]), &to, &[]).is_none());
    }

    #[test]
    fn only_a_centred_single_focal_camera_is_accepted() {
        let ok = camera("PINHOLE", 200, 150, &[160.0, 160.0, 100.0, 75.0]);
        assert_eq!(check_centred(&ok, 1), Ok(160.0));
        let off = camera("PINHOLE", 200, 150, &[160.0, 160.0, 103.0, 75.0]);
        assert!(check_centred(&off, 1)
            .unwrap_err()
            .contains("principal point"));
        let two = camera("PINHOLE", 200, 150, &[160.0, 170.0, 100.0, 75.0]);
        assert!(check_centred(&two, 1).is_err());
    }
}
