//! Running COLMAP's command-line stages (module docs of the crate).

use std::path::{Path, PathBuf};
use std::process::Command;

use gb_nerf::scene::colmap::Model;

use crate::{CaptureError, CaptureOptions, Matcher};

/// Checks that `program` runs (`colmap help`).
pub fn check_program(program: &Path) -> Result<(), CaptureError> {
    let missing = |reason: String| CaptureError::ColmapMissing {
        program: program.display().to_string(),
        reason,
    };
    let out = Command::new(program)
        .arg("help")
        .output()
        .map_err(|e| missing(e.to_string()))?;
    if !out.status.success() {
        return Err(missing(format!("`help` exited with {}", out.status)));
    }
    Ok(())
}

/// Writes COLMAP's feature masks into `dir`: for image `NAME.EXT`, `NAME.EXT.png`, black
/// where the object's mask is set (COLMAP extracts no feature there), white elsewhere.
fn write_feature_masks(
    images: &[PathBuf],
    masks: &[Option<PathBuf>],
    dir: &Path,
) -> Result<usize, CaptureError> {
    std::fs::create_dir_all(dir).map_err(|e| CaptureError::io(dir, e))?;
    let mut written = 0;
    for (image, mask) in images.iter().zip(masks) {
        let Some(mask) = mask else { continue };
        let (iw, ih) = image_size(image)?;
        let (w, h, values) = gb_core::read_gray(mask)?;
        if (w, h) != (iw, ih) {
            return Err(CaptureError::MaskSize {
                path: mask.clone(),
                mask_w: w,
                mask_h: h,
                image_w: iw,
                image_h: ih,
            });
        }
        let keep: Vec<f32> = values
            .iter()
            .map(|&v| if v > 0.0 { 0.0 } else { 1.0 })
            .collect();
        let name = format!("{}.png", crate::file_name(image));
        gb_core::write_gray_png(&dir.join(name), w, h, &keep)?;
        written += 1;
    }
    Ok(written)
}

/// The size of an image file, from its header.
pub(crate) fn image_size(path: &Path) -> Result<(usize, usize), CaptureError> {
    Ok(gb_core::image_size(path)?)
}

/// Runs `colmap STAGE ARGS`, its output to `work/STAGE.log`.
pub(crate) fn run(
    program: &Path,
    stage: &'static str,
    args: &[&str],
    work: &Path,
) -> Result<(), CaptureError> {
    let log = work.join(format!("{stage}.log"));
    let file = std::fs::File::create(&log).map_err(|e| CaptureError::io(&log, e))?;
    let err = file.try_clone().map_err(|e| CaptureError::io(&log, e))?;
    tracing::info!(stage, log = %log.display(), "COLMAP");
    let status = Command::new(program)
        .arg(stage)
        .args(args)
        .stdout(file)
        .stderr(err)
        .status()
        .map_err(|e| CaptureError::ColmapMissing {
            program: program.display().to_string(),
            reason: e.to_string(),
        })?;
    if !status.success() {
        return Err(CaptureError::Colmap {
            stage,
            status: status.to_string(),
            log,
        });
    }
    Ok(())
}

/// Feature extraction (the object masked out), matching and mapping in `work`; returns the
/// largest model the mapper made, with its folder.
pub fn reconstruct(
    opts: &CaptureOptions,
    images: &[PathBuf],
    masks: &[Option<PathBuf>],
    work: &Path,
    progress: &mut impl FnMut(&str),
) -> Result<(Model, PathBuf), CaptureError> {
    let db = work.join("database.db");
    // a fresh database: COLMAP adds to an existing one
    if db.exists() {
        std::fs::remove_file(&db).map_err(|e| CaptureError::io(&db, e))?;
    }
    let s = |p: &Path| p.display().to_string();
    let (db_s, images_s) = (s(&db), s(&opts.images));
    let feature_masks = work.join("feature_masks");
    let masked = write_feature_masks(images, masks, &feature_masks)?;
    let fm = s(&feature_masks);
    progress("COLMAP feature extraction");
    let mut args = vec![
        "--database_path",
        &db_s,
        "--image_path",
        &images_s,
        "--ImageReader.single_camera",
        "1",
        "--ImageReader.camera_model",
        opts.lens.colmap_model(),
        "--SiftExtraction.use_gpu",
        "0",
    ];
    if masked > 0 {
        args.extend(["--ImageReader.mask_path", &fm]);
    }
    // a known focal length: f, cx, cy with the centre of the first image (and no distortion
    // to start from, for a radial lens)
    let params = match opts.focal {
        Some(f) => {
            let (w, h) = image_size(&images[0])?;
            let radial = match opts.lens {
                crate::Lens::Pinhole => "",
                crate::Lens::Radial => ",0,0",
            };
            Some(format!("{f},{},{}{radial}", w as f64 / 2.0, h as f64 / 2.0))
        }
        None => None,
    };
    if let Some(p) = &params {
        args.extend(["--ImageReader.camera_params", p]);
    }
    run(&opts.colmap, "feature_extractor", &args, work)?;
    progress("COLMAP matching");
    let matcher = match opts.matcher {
        Matcher::Exhaustive => "exhaustive_matcher",
        Matcher::Sequential => "sequential_matcher",
    };
    run(
        &opts.colmap,
        matcher,
        &["--database_path", &db_s, "--SiftMatching.use_gpu", "0"],
        work,
    )?;
    progress("COLMAP mapping");
    let sparse = work.join("sparse");
    if sparse.exists() {
        std::fs::remove_dir_all(&sparse).map_err(|e| CaptureError::io(&sparse, e))?;
    }
    std::fs::create_dir_all(&sparse).map_err(|e| CaptureError::io(&sparse, e))?;
    let sparse_s = s(&sparse);
    run(
        &opts.colmap,
        "mapper",
        &[
            "--database_path",
            &db_s,
            "--image_path",
            &images_s,
            "--output_path",
            &sparse_s,
            "--Mapper.ba_refine_focal_length",
            if opts.focal.is_some() { "0" } else { "1" },
        ],
        work,
    )?;
    // the mapper writes one model per connected component: 0, 1, ...
    let mut best: Option<(Model, PathBuf)> = None;
    let entries = std::fs::read_dir(&sparse).map_err(|e| CaptureError::io(&sparse, e))?;
    for entry in entries {
        let path = entry.map_err(|e| CaptureError::io(&sparse, e))?.path();
        if path.is_dir() {
            let model = Model::read(&path)?;
            if best
                .as_ref()
                .is_none_or(|b| model.images.len() > b.0.images.len())
            {
                best = Some((model, path));
            }
        }
    }
    // no model at all: nothing registered, which the check below reports
    let (model, model_dir) = best.unwrap_or_else(|| (Model::default(), sparse.join("0")));
    let names: Vec<String> = model.images.values().map(|i| i.name.clone()).collect();
    let total = images.len();
    let unregistered: Vec<String> = images
        .iter()
        .map(|p| crate::file_name(p))
        .filter(|n| !names.contains(n))
        .collect();
    let registered = total - unregistered.len();
    if registered < 3 || 2 * registered < total {
        return Err(CaptureError::TooFewRegistered {
            registered,
            total,
            unregistered: unregistered.into_iter().take(8).collect(),
        });
    }
    if !unregistered.is_empty() {
        tracing::warn!(
            registered,
            total,
            left_out = %unregistered.join(", "),
            "COLMAP did not register every image: those are left out of the scene"
        );
    }
    Ok((model, model_dir))
}
