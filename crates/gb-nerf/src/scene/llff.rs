//! Loader for the LLFF / SPIn-NeRF layout (and the procedural benchmark, which writes it).
//!
//! ```text
//! DIR/poses_bounds.npy        N x 17 float64: row-major 3x5 [R|t|hwf] (LLFF "down, right,
//!                             back" axes, hwf at full resolution) + near, far; rows follow
//!                             the sorted image names
//! DIR/images_F/*.png|jpg      the images, downscaled by F (images/ means F = 1)
//! DIR/images_F/label/         object masks of training views (0/1 or 0/255), same names
//! DIR/images_F/test_label/    masks of the test views (SPIn-NeRF), named after the images,
//!                             or out_00001.png, ... in the sorted order of the test views
//! DIR/depth_F/NAME.npy        optional z-depth, H x W float32 (procedural scenes); 0 where
//!                             there is no depth (NaN and infinity are refused)
//! DIR/normal_F/NAME.npy       optional unit world normals, H x W x 3 float32 (finite)
//! DIR/scene.json              optional; `aabb_min`/`aabb_max` make the scene Bounded
//! DIR/sparse/0/               optional COLMAP model (.bin or .txt): every view must be one
//!                             of its registered images (by file stem); its points become
//!                             the scene's per-view sparse depth
//! ```
//!
//! **Splits.** When `test_label/` exists, the views with a test mask are test views (the
//! SPIn-NeRF convention: in a 100-view scene they are the first 40 sorted views, captured
//! without the object); a warning is recorded when they are not the first K sorted views.
//! Full SPIn-NeRF scenes name their test masks `out_00001.png`, `out_00002.png`, ... rather
//! than after the images: when the masks do not name images but are as many as the views
//! without a training mask, they pair with those views in sorted order, with a warning.
//! Otherwise every view is a training view, unless [`LlffOptions::holdout_every`] is `Some(n)`:
//! then views `0, n, 2n, ...` are test views (the NeRF "llffhold = 8" convention for fern).
//!
//! **Intrinsics.** `fx = fy = f / F` and the principal point is the image centre. When an
//! image's size is not `hwf / F`, the focal length is scaled by `image_width / w` instead and
//! a warning is recorded.
//!
//! **Bounds.** `near = 0.9 * min(near bounds)`, `far = max(far bounds)` (nerf-pytorch's
//! non-NDC choice), over the training views' rows only (all rows when no view is a test
//! view): removing the test views does not change them.
//!
//! **Normalisation** (off by default): [`LlffOptions::normalize`] applies NeRF's LLFF
//! convention, see [`Normalization::nerf_llff`]: the average camera becomes the identity
//! and the scene is scaled by `1 / (0.75 * min near)`, so the smallest near bound becomes
//! 4/3 and the scene's `near` about 1.2. Depth maps are scaled and normals rotated with it.
// Component loops over xyz / matrix entries read clearer with indices than with zips.
#![allow(clippy::needless_range_loop)]

use super::colmap::{self, SparseDepth};
use super::files::{list_images, stem};
use super::llff_poses::{read_poses_bounds, LlffPose, Normalization};
use super::masks::read_mask;
use super::npy::read_float_array;
use super::{Camera, Mask, Scene, SceneError, SceneKind, Split, View};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Options of the LLFF loader.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LlffOptions {
    /// Use `images_F/` (`images/` for 1). `None`: the smallest `F` present.
    pub factor: Option<u32>,
    /// For scenes without test masks: make every n-th view (0, n, 2n, ...) a test view.
    pub holdout_every: Option<usize>,
    /// Apply NeRF's LLFF recentring and scaling (see the module docs).
    pub normalize: bool,
}

/// Paths of SPIn-NeRF's optional precomputed inpaintings (needed by later stages).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SpinExtras {
    /// `RGB_inpainted/` (2D-inpainted images), if present.
    pub rgb_inpainted: Option<PathBuf>,
    /// `Depth_inpainted/` (2D-inpainted depth), if present.
    pub depth_inpainted: Option<PathBuf>,
}

/// Finds SPIn-NeRF's `RGB_inpainted/` and `Depth_inpainted/` folders, in the scene folder
/// or inside its image folder `images_F/`.
pub fn spin_extras(dir: &Path, factor: Option<u32>) -> SpinExtras {
    let mut roots = vec![dir.to_path_buf()];
    if let Ok((images_dir, _)) = image_folder(dir, factor) {
        roots.push(images_dir);
    }
    let find = |name: &str| roots.iter().map(|r| r.join(name)).find(|p| p.is_dir());
    SpinExtras {
        rgb_inpainted: find("RGB_inpainted"),
        depth_inpainted: find("Depth_inpainted"),
    }
}

/// The image folder to use and its downscale factor.
pub fn image_folder(dir: &Path, factor: Option<u32>) -> Result<(PathBuf, u32), SceneError> {
    let folder_for = |f: u32| {
        if f == 1 {
            dir.join("images")
        } else {
            dir.join(format!("images_{f}"))
        }
    };
    if let Some(f) = factor {
        let p = folder_for(f);
        // the procedural benchmark writes images_1/
        if f == 1 && !p.is_dir() && dir.join("images_1").is_dir() {
            return Ok((dir.join("images_1"), 1));
        }
        return if p.is_dir() {
            Ok((p, f))
        } else {
            Err(SceneError::Missing {
                path: p,
                what: format!("image folder for factor {f}"),
            })
        };
    }
    let mut found: Vec<(u32, PathBuf)> = Vec::new();
    let rd = std::fs::read_dir(dir).map_err(|e| SceneError::io(dir, e))?;
    for entry in rd.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if !entry.path().is_dir() {
            continue;
        }
        if name == "images" {
            found.push((1, entry.path()));
        } else if let Some(f) = name
            .strip_prefix("images_")
            .and_then(|s| s.parse::<u32>().ok())
        {
            if f >= 1 {
                found.push((f, entry.path()));
            }
        }
    }
    found.sort();
    found
        .into_iter()
        .next()
        .map(|(f, p)| (p, f))
        .ok_or_else(|| SceneError::Missing {
            path: dir.join("images_N"),
            what: "image folder (images/ or images_N/)".into(),
        })
}

/// Reads mask files of one folder into `name -> path`; every mask must have an image.
fn mask_files(
    dir: &Path,
    images_dir: &Path,
    names: &BTreeMap<String, usize>,
) -> Result<BTreeMap<String, PathBuf>, SceneError> {
    let mut out = BTreeMap::new();
    if !dir.is_dir() {
        return Ok(out);
    }
    for p in list_images(dir)? {
        let s = stem(&p);
        if !names.contains_key(&s) {
            return Err(SceneError::OrphanMask {
                path: p,
                images_dir: images_dir.to_path_buf(),
            });
        }
        out.insert(s, p);
    }
    Ok(out)
}

/// Reads the test masks of `images_dir/test_label/` into `view name -> path`.
///
/// Masks named after their images pair by name. Full SPIn-NeRF scenes name them
/// `out_00001.png`, `out_00002.png`, ... in the sorted order of the test views instead: when
/// some mask names no image but there are as many masks as views without a training mask,
/// the i-th sorted mask goes with the i-th such view, and a warning says so. Otherwise a mask
/// that names no image is an error naming it.
fn test_mask_files(
    images_dir: &Path,
    names: &BTreeMap<String, usize>,
    train_masks: &BTreeMap<String, PathBuf>,
    warnings: &mut Vec<String>,
) -> Result<BTreeMap<String, PathBuf>, SceneError> {
    let dir = images_dir.join("test_label");
    if !dir.is_dir() {
        return Ok(BTreeMap::new());
    }
    let files = list_images(&dir)?;
    let Some(orphan) = files.iter().find(|p| !names.contains_key(&stem(p))) else {
        return Ok(files.into_iter().map(|p| (stem(&p), p)).collect());
    };
    // views in image order (`names` maps each stem to its sorted position)
    let mut unmasked: Vec<(&String, usize)> = names
        .iter()
        .filter(|(n, _)| !train_masks.contains_key(*n))
        .map(|(n, &i)| (n, i))
        .collect();
    unmasked.sort_by_key(|&(_, i)| i);
    if unmasked.len() != files.len() {
        return Err(SceneError::OrphanMask {
            path: orphan.clone(),
            images_dir: images_dir.to_path_buf(),
        });
    }
    let pairs: BTreeMap<String, PathBuf> = unmasked
        .iter()
        .zip(&files)
        .map(|(&(n, _), p)| (n.clone(), p.clone()))
        .collect();
    let (first, last) = (unmasked[0].0, unmasked[unmasked.len() - 1].0);
    warnings.push(format!(
        "{}: the {} test masks are not named after the images (SPIn-NeRF's out_NNNNN.png); \
         paired in sorted order with the {} views that have no training mask ({first} .. {last})",
        dir.display(),
        files.len(),
        unmasked.len(),
    ));
    Ok(pairs)
}

/// Loads an LLFF / SPIn-NeRF scene (see the module docs for the layout and conventions).
pub fn load(dir: &Path, opts: &LlffOptions) -> Result<Scene, SceneError> {
    if !dir.is_dir() {
        return Err(SceneError::NotAFolder {
            path: dir.to_path_buf(),
        });
    }
    let poses_path = dir.join("poses_bounds.npy");
    let (images_dir, factor) = image_folder(dir, opts.factor)?;
    let poses = read_poses_bounds(&poses_path)?;
    let image_paths = list_images(&images_dir)?;
    if image_paths.len() != poses.len() {
        return Err(SceneError::CountMismatch {
            images_dir: images_dir.clone(),
            images: image_paths.len(),
            poses_path,
            poses: poses.len(),
        });
    }
    let names: BTreeMap<String, usize> = image_paths
        .iter()
        .enumerate()
        .map(|(i, p)| (stem(p), i))
        .collect();
    let mut warnings = Vec::new();
    let train_masks = mask_files(&images_dir.join("label"), &images_dir, &names)?;
    let test_masks = test_mask_files(&images_dir, &names, &train_masks, &mut warnings)?;

    let norm = if opts.normalize {
        Normalization::nerf_llff(&poses)
    } else {
        Normalization::identity()
    };
    let suffix = images_dir
        .file_name()
        .and_then(|n| n.to_str())
        .and_then(|n| n.strip_prefix("images"))
        .unwrap_or("");
    let depth_dir = dir.join(format!("depth{suffix}"));
    let normal_dir = dir.join(format!("normal{suffix}"));

    let mut size: Option<(usize, usize)> = None;
    let mut views = Vec::with_capacity(image_paths.len());
    let mut focal_warned = false;
    for (i, (path, pose)) in image_paths.iter().zip(&poses).enumerate() {
        let name = stem(path);
        let image = gb_core::read_rgb(path, None)?;
        let (w, h) = (image.width, image.height);
        match size {
            None => size = Some((w, h)),
            Some((ww, wh)) if (ww, wh) != (w, h) => {
                return Err(SceneError::ImageSize {
                    path: path.clone(),
                    got_w: w,
                    got_h: h,
                    want_w: ww,
                    want_h: wh,
                })
            }
            _ => {}
        }
        let camera = camera_for(
            pose,
            factor,
            w,
            h,
            &norm,
            &mut focal_warned,
            path,
            &mut warnings,
        );
        let split = if !test_masks.is_empty() {
            if test_masks.contains_key(&name) {
                Split::Test
            } else {
                Split::Train
            }
        } else {
            match opts.holdout_every {
                Some(n) if n > 0 && i % n == 0 => Split::Test,
                _ => Split::Train,
            }
        };
        let mask_path = match split {
            Split::Test => test_masks.get(&name).or_else(|| train_masks.get(&name)),
            Split::Train => train_masks.get(&name),
        };
        let mask: Option<Mask> = match mask_path {
            Some(p) => Some(read_mask(p, w, h, &mut warnings)?),
            None => None,
        };
        let depth = read_depth(&depth_dir.join(format!("{name}.npy")), w, h, norm.scale)?;
        let normal = read_normals(&normal_dir.join(format!("{name}.npy")), w, h, &norm)?;
        views.push(View {
            name,
            camera,
            image,
            mask,
            depth,
            normal,
            split,
        });
    }
    let k = test_masks.len();
    if k > 0 && views.iter().take(k).any(|v| v.split != Split::Test) {
        warnings.push(format!(
            "{}: the {k} test masks are not the first {k} sorted views (SPIn-NeRF convention)",
            images_dir.join("test_label").display()
        ));
    }
    if !train_masks.is_empty() {
        let missing = views
            .iter()
            .filter(|v| v.split == Split::Train && v.mask.is_none())
            .count();
        if missing > 0 {
            warnings.push(format!(
                "{}: {missing} training views have no mask",
                images_dir.join("label").display()
            ));
        }
    }
    let sparse_depth = match colmap::model_dir(dir) {
        Some(model_dir) => sparse_depth_of(&model_dir, &views, norm.scale)?,
        None => BTreeMap::new(),
    };
    // bounds from the training views only: a test view's row must not widen them
    let has_train = views.iter().any(|v| v.split == Split::Train);
    let bounded = || {
        poses
            .iter()
            .zip(&views)
            .filter(move |(_, v)| !has_train || v.split == Split::Train)
            .map(|(p, _)| p)
    };
    let near = 0.9 * bounded().map(|p| p.near).fold(f64::INFINITY, f64::min) * norm.scale;
    let far = bounded().map(|p| p.far).fold(0.0f64, f64::max) * norm.scale;
    let kind = match read_aabb(&dir.join("scene.json"))? {
        Some((lo, hi)) => {
            let (lo, hi) = transform_aabb(lo, hi, &norm);
            SceneKind::Bounded {
                aabb_min: lo,
                aabb_max: hi,
            }
        }
        None => SceneKind::ForwardFacing,
    };
    Ok(Scene {
        name: dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        kind,
        views,
        near: near as f32,
        far: far as f32,
        background: [0.0; 3],
        warnings,
        sparse_depth,
    })
}

/// The sparse depth of every view from the scene's COLMAP model in `model_dir`: each view
/// must be a registered image (matched by file stem); keypoints are scaled from the
/// camera's resolution to the loaded one, depths by the normalisation's scale.
fn sparse_depth_of(
    model_dir: &Path,
    views: &[View],
    scale: f64,
) -> Result<BTreeMap<String, Vec<SparseDepth>>, SceneError> {
    let model = colmap::Model::read(model_dir)?;
    let images = model.match_stems(model_dir, views.iter().map(|v| v.name.as_str()))?;
    let mut out = BTreeMap::new();
    for (view, image) in views.iter().zip(images) {
        let camera = &model.cameras[&image.camera_id];
        let sx = view.image.width as f64 / camera.width.max(1) as f64;
        let sy = view.image.height as f64 / camera.height.max(1) as f64;
        let points = model
            .sparse_depth(image)
            .into_iter()
            .map(|p| SparseDepth {
                x: (p.x as f64 * sx) as f32,
                y: (p.y as f64 * sy) as f32,
                depth: (p.depth as f64 * scale) as f32,
                error: (p.error as f64 * sx) as f32,
            })
            .collect();
        out.insert(view.name.clone(), points);
    }
    Ok(out)
}

#[allow(clippy::too_many_arguments)]
fn camera_for(
    pose: &LlffPose,
    factor: u32,
    w: usize,
    h: usize,
    norm: &Normalization,
    warned: &mut bool,
    path: &Path,
    warnings: &mut Vec<String>,
) -> Camera {
    let f = factor as f64;
    let expect = ((pose.width / f).round(), (pose.height / f).round());
    let focal = if (expect.0 - w as f64).abs() <= 1.0 && (expect.1 - h as f64).abs() <= 1.0 {
        pose.focal / f
    } else {
        if !*warned {
            warnings.push(format!(
                "{}: image is {w}x{h} but hwf / {factor} gives {}x{}; focal scaled by the width ratio",
                path.display(),
                expect.0,
                expect.1
            ));
            *warned = true;
        }
        pose.focal * w as f64 / pose.width
    };
    let c2w = norm.pose(&pose.c2w);
    let mut c = [[0.0f32; 4]; 3];
    for i in 0..3 {
        for j in 0..4 {
            c[i][j] = c2w[i][j] as f32;
        }
    }
    Camera {
        width: w,
        height: h,
        fx: focal as f32,
        fy: focal as f32,
        cx: w as f32 / 2.0,
        cy: h as f32 / 2.0,
        c2w: c,
    }
}

/// Errors on the first NaN or infinity of an `[h, w, channels]` array, naming its pixel.
fn require_finite(path: &Path, data: &[f64], w: usize, channels: usize) -> Result<(), SceneError> {
    match data.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(SceneError::NonFiniteArray {
            path: path.to_path_buf(),
            x: (i / channels) % w.max(1),
            y: (i / channels) / w.max(1),
            value: data[i],
        }),
        None => Ok(()),
    }
}

/// A z-depth map (0 or less where there is no depth); NaN and infinity are refused.
fn read_depth(path: &Path, w: usize, h: usize, scale: f64) -> Result<Option<Vec<f32>>, SceneError> {
    if !path.is_file() {
        return Ok(None);
    }
    let a = read_float_array(path)?;
    if a.shape != [h as u64, w as u64] {
        return Err(SceneError::ArrayShape {
            path: path.to_path_buf(),
            shape: a.shape,
            expected: format!("[{h}, {w}]"),
        });
    }
    require_finite(path, &a.data, w, 1)?;
    Ok(Some(a.data.iter().map(|&d| (d * scale) as f32).collect()))
}

fn read_normals(
    path: &Path,
    w: usize,
    h: usize,
    norm: &Normalization,
) -> Result<Option<Vec<[f32; 3]>>, SceneError> {
    if !path.is_file() {
        return Ok(None);
    }
    let a = read_float_array(path)?;
    if a.shape != [h as u64, w as u64, 3] {
        return Err(SceneError::ArrayShape {
            path: path.to_path_buf(),
            shape: a.shape,
            expected: format!("[{h}, {w}, 3]"),
        });
    }
    require_finite(path, &a.data, w, 3)?;
    Ok(Some(
        a.data
            .chunks_exact(3)
            .map(|n| {
                let r = norm.direction([n[0], n[1], n[2]]);
                [r[0] as f32, r[1] as f32, r[2] as f32]
            })
            .collect(),
    ))
}

type Aabb = ([f64; 3], [f64; 3]);

fn read_aabb(path: &Path) -> Result<Option<Aabb>, SceneError> {
    if !path.is_file() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(path).map_err(|e| SceneError::io(path, e))?;
    let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| SceneError::Json {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    let get = |k: &str| -> Option<[f64; 3]> {
        let a = v.get(k)?.as_array()?;
        if a.len() != 3 {
            return None;
        }
        Some([a[0].as_f64()?, a[1].as_f64()?, a[2].as_f64()?])
    };
    Ok(match (get("aabb_min"), get("aabb_max")) {
        (Some(lo), Some(hi)) => Some((lo, hi)),
        _ => None,
    })
}

fn transform_aabb(lo: [f64; 3], hi: [f64; 3], norm: &Normalization) -> ([f32; 3], [f32; 3]) {
    let mut mn = [f64::INFINITY; 3];
    let mut mx = [f64::NEG_INFINITY; 3];
    for corner in 0..8 {
        let p = [
            if corner & 1 == 0 { lo[0] } else { hi[0] },
            if corner & 2 == 0 { lo[1] } else { hi[1] },
            if corner & 4 == 0 { lo[2] } else { hi[2] },
        ];
        let q = norm.point(p);
        for i in 0..3 {
            mn[i] = mn[i].min(q[i]);
            mx[i] = mx[i].max(q[i]);
        }
    }
    (
        [mn[0] as f32, mn[1] as f32, mn[2] as f32],
        [mx[0] as f32, mx[1] as f32, mx[2] as f32],
    )
}
