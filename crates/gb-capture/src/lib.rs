//! `cargo xtask capture`: your own photos to a scene this project loads, in one command.
//!
//! 1. **Inputs.** `--images DIR` (png, jpg) and, optionally, `--masks DIR`: one mask per
//!    image that shows the object, named after its image (`IMG_0001.jpg` -> `IMG_0001.png`),
//!    white (non-zero) on the object. A mask that names no image is an error; an image
//!    without a mask is a view without the object's mask.
//! 2. **COLMAP** ([`colmap`]), on the CPU, each stage logged to `OUT/colmap/STAGE.log`:
//!    feature extraction with one shared camera and the object masked out (COLMAP's
//!    `mask_path`, black where the object is), so the object's features do not drive the
//!    poses; exhaustive or sequential matching; the mapper. The camera ([`Lens`]) is
//!    `SIMPLE_PINHOLE` by default (one focal length, the principal point at the image centre:
//!    the intrinsics of the LLFF layout, for photos without visible distortion, as phones'
//!    processed JPEGs are), or `RADIAL` (two radial distortion terms, for wide or uncorrected
//!    lenses), whose images, model and masks are then undistorted to an ideal `PINHOLE`
//!    camera ([`undistort`]: COLMAP's `image_undistorter`, the masks by the same mapping).
//! 3. **The scene** ([`layout`]), the LLFF layout of `gb_nerf::scene::llff`: `images/` (the
//!    registered images), `images/label/` (their masks, 0/255), `sparse/0/` (the model, whose
//!    points become sparse depth) and `poses_bounds.npy` (camera-to-world poses in LLFF's
//!    axes, `hwf`, and per image the 0.1 and 99.9 percentiles of its points' z-depth as near
//!    and far, as LLFF's `imgs2poses.py` does).
//!
//! Images that COLMAP does not register are left out with a warning; fewer than half (or
//! fewer than 3) registered is an error that says what to try.

pub mod colmap;
pub mod error;
pub mod layout;
pub mod undistort;

use std::path::{Path, PathBuf};

pub use error::CaptureError;
use gb_nerf::scene::files::{list_images, stem};

/// How COLMAP matches features between images.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Matcher {
    /// Every pair (a few hundred images at most).
    #[default]
    Exhaustive,
    /// Neighbours in name order (a video's frames).
    Sequential,
}

/// The lens model COLMAP fits (`--camera`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Lens {
    /// `SIMPLE_PINHOLE`: no distortion (the default).
    #[default]
    Pinhole,
    /// `RADIAL` (k1, k2), then undistortion to `PINHOLE`.
    Radial,
}

impl Lens {
    /// COLMAP's name of the camera model.
    pub fn colmap_model(self) -> &'static str {
        match self {
            Lens::Pinhole => "SIMPLE_PINHOLE",
            Lens::Radial => "RADIAL",
        }
    }
}

/// What [`capture`] needs.
#[derive(Debug, Clone)]
pub struct CaptureOptions {
    /// The photos.
    pub images: PathBuf,
    /// The object masks, named after the images; `None`: no masks.
    pub masks: Option<PathBuf>,
    /// The scene folder to write.
    pub out: PathBuf,
    /// The matcher.
    pub matcher: Matcher,
    /// The COLMAP program.
    pub colmap: PathBuf,
    /// The focal length in pixels when it is known (a calibrated camera): COLMAP then keeps it
    /// fixed instead of estimating it, which also steadies the poses of small captures.
    pub focal: Option<f64>,
    /// The lens model.
    pub lens: Lens,
}

/// What [`capture`] made.
#[derive(Debug, Clone, PartialEq)]
pub struct CaptureReport {
    /// Images given.
    pub images: usize,
    /// Images registered (the scene's views).
    pub registered: usize,
    /// Views with a mask.
    pub masked: usize,
    /// 3D points of the model.
    pub points: usize,
    /// Images left out (not registered).
    pub left_out: Vec<String>,
    /// The fitted distortion `(k1, k2)` of a radial lens, undistorted away.
    pub distortion: Option<(f64, f64)>,
}

/// The file name of `path` (lossy), for messages and COLMAP's image names. Every path here
/// comes from [`list_images`], which lists files only, so each has a name.
pub(crate) fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

/// For each image, its mask in `masks` (same stem, any image extension); an error lists the
/// masks that match no image.
pub fn pair_masks(images: &[PathBuf], masks: &Path) -> Result<Vec<Option<PathBuf>>, CaptureError> {
    let files = list_images(masks)?;
    let stems: Vec<String> = images.iter().map(|p| stem(p)).collect();
    let unmatched: Vec<String> = files
        .iter()
        .filter(|m| !stems.contains(&stem(m)))
        .map(|m| file_name(m))
        .take(8)
        .collect();
    if !unmatched.is_empty() {
        return Err(CaptureError::MaskNames {
            dir: masks.to_path_buf(),
            names: unmatched,
        });
    }
    Ok(stems
        .iter()
        .map(|s| files.iter().find(|m| stem(m) == *s).cloned())
        .collect())
}

/// Runs the capture (module docs); `progress` is told each stage as it starts.
pub fn capture(
    opts: &CaptureOptions,
    mut progress: impl FnMut(&str),
) -> Result<CaptureReport, CaptureError> {
    let images = list_images(&opts.images)?;
    if images.len() < 3 {
        return Err(CaptureError::TooFewImages {
            dir: opts.images.clone(),
            found: images.len(),
        });
    }
    let masks = match &opts.masks {
        Some(dir) => pair_masks(&images, dir)?,
        None => vec![None; images.len()],
    };
    colmap::check_program(&opts.colmap)?;
    let work = opts.out.join("colmap");
    std::fs::create_dir_all(&work).map_err(|e| CaptureError::io(&work, e))?;
    let (model, model_dir) = colmap::reconstruct(opts, &images, &masks, &work, &mut progress)?;
    match opts.lens {
        Lens::Pinhole => {
            progress("writing the scene");
            layout::write_scene(&opts.out, &images, &masks, &model, &model_dir, None)
        }
        Lens::Radial => {
            progress("COLMAP undistortion");
            let und = undistort::undistort(&opts.colmap, &opts.images, &model_dir, &work)?;
            progress("writing the scene");
            let mut report = layout::write_scene(
                &opts.out,
                &images,
                &masks,
                &und.model,
                &und.sparse,
                Some(&layout::Undistortion {
                    photos: &model,
                    images: &und.images,
                }),
            )?;
            // one shared camera (single_camera): its k1, k2
            report.distortion =
                model
                    .cameras
                    .values()
                    .next()
                    .and_then(|c| match c.params.as_slice() {
                        [_, _, _, k1, k2] => Some((*k1, *k2)),
                        _ => None,
                    });
            Ok(report)
        }
    }
}
