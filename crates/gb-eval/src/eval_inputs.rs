//! The inputs of an evaluation run: folders of predictions, ground truths, masks and
//! depth/disparity maps, paired by sorted file name.
//!
//! Pairing is positional after sorting each folder's file names (byte order): the i-th
//! prediction goes with the i-th ground truth, mask and depth map. Different counts, or a
//! prediction whose size differs from its ground truth (or mask), are errors naming the files.
//! Masks: any non-zero pixel is inside the mask (0/1 and 0/255 masks both work).

use std::path::{Path, PathBuf};

use gb_core::{read_gray, read_rgb, ImageIoError, RgbImage};

use crate::disparity::{read_disparity, DepthKind, DisparityReadError, ScalarMap};

/// Image files the evaluation reads.
const IMAGE_EXTENSIONS: [&str; 3] = ["png", "jpg", "jpeg"];
/// Depth files the evaluation reads.
const DEPTH_EXTENSIONS: [&str; 4] = ["npy", "png", "jpg", "jpeg"];

/// The evaluation's inputs could not be paired or read.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    /// A folder could not be listed.
    #[error("{path}: cannot list the folder: {reason}")]
    ListDir {
        /// The folder.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// A folder holds no file of the expected kinds.
    #[error("{path}: no {what} files (expected extensions {extensions})")]
    Empty {
        /// The folder.
        path: PathBuf,
        /// "image", "mask", "depth".
        what: &'static str,
        /// The accepted extensions.
        extensions: String,
    },
    /// Two folders hold different numbers of files.
    #[error("{what}: {a_dir} holds {a} files but {b_dir} holds {b}; files pair by sorted name")]
    CountMismatch {
        /// The pairing ("prediction/ground truth", ...).
        what: &'static str,
        /// First folder.
        a_dir: PathBuf,
        /// Its count.
        a: usize,
        /// Second folder.
        b_dir: PathBuf,
        /// Its count.
        b: usize,
    },
    /// Two paired files have different sizes.
    #[error("size mismatch: {a} is {aw}x{ah} but {b} is {bw}x{bh}")]
    SizeMismatch {
        /// First file.
        a: PathBuf,
        /// Its width.
        aw: usize,
        /// Its height.
        ah: usize,
        /// Second file.
        b: PathBuf,
        /// Its width.
        bw: usize,
        /// Its height.
        bh: usize,
    },
    /// An image could not be read.
    #[error(transparent)]
    Image(#[from] ImageIoError),
    /// A depth or disparity map could not be read.
    #[error(transparent)]
    Depth(#[from] DisparityReadError),
}

/// Paired input files of one evaluation run.
#[derive(Debug, Clone)]
pub struct EvalInputs {
    /// Prediction folder.
    pub pred_dir: PathBuf,
    /// Ground-truth folder.
    pub gt_dir: PathBuf,
    /// Display name of each pair (the prediction's file name).
    pub names: Vec<String>,
    /// Prediction files.
    pub pred: Vec<PathBuf>,
    /// Ground-truth files.
    pub gt: Vec<PathBuf>,
    /// Mask files, when a mask folder was given.
    pub masks: Option<Vec<PathBuf>>,
    /// Predicted and ground-truth depth/disparity files, when both folders were given.
    pub depth: Option<(Vec<PathBuf>, Vec<PathBuf>)>,
    /// What the depth files hold.
    pub depth_kind: DepthKind,
}

impl EvalInputs {
    /// Lists and pairs the folders; checks counts, and that every prediction has the size of
    /// its ground truth and mask (reading only the file headers).
    pub fn from_dirs(
        pred_dir: &Path,
        gt_dir: &Path,
        mask_dir: Option<&Path>,
        depth_dirs: Option<(&Path, &Path)>,
        depth_kind: DepthKind,
    ) -> Result<Self, InputError> {
        let pred = list_files(pred_dir, "image", &IMAGE_EXTENSIONS)?;
        let gt = list_files(gt_dir, "image", &IMAGE_EXTENSIONS)?;
        check_count(
            "prediction/ground truth",
            pred_dir,
            pred.len(),
            gt_dir,
            gt.len(),
        )?;
        for (p, g) in pred.iter().zip(&gt) {
            check_same_size(p, g)?;
        }
        let masks = match mask_dir {
            Some(dir) => {
                let masks = list_files(dir, "mask", &IMAGE_EXTENSIONS)?;
                check_count("prediction/mask", pred_dir, pred.len(), dir, masks.len())?;
                for (p, m) in pred.iter().zip(&masks) {
                    check_same_size(p, m)?;
                }
                Some(masks)
            }
            None => None,
        };
        let depth = match depth_dirs {
            Some((pd, gd)) => {
                let pdep = list_files(pd, "depth", &DEPTH_EXTENSIONS)?;
                let gdep = list_files(gd, "depth", &DEPTH_EXTENSIONS)?;
                check_count(
                    "predicted/ground-truth depth",
                    pd,
                    pdep.len(),
                    gd,
                    gdep.len(),
                )?;
                check_count("prediction/depth", pred_dir, pred.len(), pd, pdep.len())?;
                Some((pdep, gdep))
            }
            None => None,
        };
        let names = pred
            .iter()
            .map(|p| {
                p.file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default()
            })
            .collect();
        Ok(Self {
            pred_dir: pred_dir.to_path_buf(),
            gt_dir: gt_dir.to_path_buf(),
            names,
            pred,
            gt,
            masks,
            depth,
            depth_kind,
        })
    }

    /// Number of pairs.
    pub fn len(&self) -> usize {
        self.pred.len()
    }

    /// Whether there is no pair (never true for inputs built by [`EvalInputs::from_dirs`]).
    pub fn is_empty(&self) -> bool {
        self.pred.is_empty()
    }

    /// Reads pair `i` as `(prediction, ground truth)`; an alpha channel is dropped (the metrics
    /// see the RGB channels, as scikit-image would on `img[..., :3]`).
    pub fn load_pair(&self, i: usize) -> Result<(RgbImage, RgbImage), InputError> {
        let p = read_rgb(&self.pred[i], None)?;
        let g = read_rgb(&self.gt[i], None)?;
        if (p.width, p.height) != (g.width, g.height) {
            return Err(size_mismatch(
                &self.pred[i],
                (p.width, p.height),
                &self.gt[i],
                (g.width, g.height),
            ));
        }
        Ok((p, g))
    }

    /// Reads mask `i` (non-zero = inside), if a mask folder was given.
    pub fn load_mask(&self, i: usize) -> Result<Option<Vec<bool>>, InputError> {
        let Some(masks) = &self.masks else {
            return Ok(None);
        };
        let (_, _, values) = read_gray(&masks[i])?;
        Ok(Some(values.into_iter().map(|v| v > 0.0).collect()))
    }

    /// Reads depth pair `i` as disparity `(prediction, ground truth)`, if depth folders were
    /// given; the two maps must have the same size.
    pub fn load_disparity_pair(
        &self,
        i: usize,
    ) -> Result<Option<(ScalarMap, ScalarMap)>, InputError> {
        let Some((pd, gd)) = &self.depth else {
            return Ok(None);
        };
        let p = read_disparity(&pd[i], self.depth_kind)?;
        let g = read_disparity(&gd[i], self.depth_kind)?;
        if (p.width, p.height) != (g.width, g.height) {
            return Err(size_mismatch(
                &pd[i],
                (p.width, p.height),
                &gd[i],
                (g.width, g.height),
            ));
        }
        Ok(Some((p, g)))
    }
}

fn size_mismatch(
    a: &Path,
    (aw, ah): (usize, usize),
    b: &Path,
    (bw, bh): (usize, usize),
) -> InputError {
    InputError::SizeMismatch {
        a: a.to_path_buf(),
        aw,
        ah,
        b: b.to_path_buf(),
        bw,
        bh,
    }
}

/// The folder's files with one of `extensions` (case-insensitive), sorted by name.
fn list_files(
    dir: &Path,
    what: &'static str,
    extensions: &[&str],
) -> Result<Vec<PathBuf>, InputError> {
    let list_err = |e: std::io::Error| InputError::ListDir {
        path: dir.to_path_buf(),
        reason: e.to_string(),
    };
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(list_err)? {
        let path = entry.map_err(list_err)?.path();
        let ext_ok = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| extensions.iter().any(|x| x.eq_ignore_ascii_case(e)));
        if path.is_file() && ext_ok {
            files.push(path);
        }
    }
    files.sort();
    if files.is_empty() {
        return Err(InputError::Empty {
            path: dir.to_path_buf(),
            what,
            extensions: extensions.join(", "),
        });
    }
    Ok(files)
}

fn check_count(
    what: &'static str,
    a_dir: &Path,
    a: usize,
    b_dir: &Path,
    b: usize,
) -> Result<(), InputError> {
    if a != b {
        return Err(InputError::CountMismatch {
            what,
            a_dir: a_dir.to_path_buf(),
            a,
            b_dir: b_dir.to_path_buf(),
            b,
        });
    }
    Ok(())
}

fn check_same_size(a: &Path, b: &Path) -> Result<(), InputError> {
    let dims = |p: &Path| gb_core::image_size(p).map_err(InputError::Image);
    let (da, db) = (dims(a)?, dims(b)?);
    if da != db {
        return Err(size_mismatch(a, da, b, db));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use gb_core::write_rgb_png;

    fn write(dir: &Path, name: &str, w: usize, h: usize) {
        write_rgb_png(&dir.join(name), &RgbImage::filled(w, h, [0.5; 3])).unwrap();
    }

    #[test]
    fn pairs_by_sorted_name_and_rejects_mismatches() {
        let tmp = tempfile::tempdir().unwrap();
        let (p, g) = (tmp.path().join("p"), tmp.path().join("g"));
        std::fs::create_dir_all(&p).unwrap();
        std::fs::create_dir_all(&g).unwrap();
        write(&p, "b.png", 4, 3);
        write(&p, "a.png", 4, 3);
        write(&g, "x.png", 4, 3);
        std::fs::write(g.join("notes.txt"), "ignored").unwrap();
        let err = EvalInputs::from_dirs(&p, &g, None, None, DepthKind::Disparity).unwrap_err();
        assert!(
            matches!(err, InputError::CountMismatch { a: 2, b: 1, .. }),
            "{err}"
        );
        write(&g, "y.png", 5, 3);
        let err = EvalInputs::from_dirs(&p, &g, None, None, DepthKind::Disparity).unwrap_err();
        assert!(
            err.to_string().contains("y.png") && err.to_string().contains("5x3"),
            "{err}"
        );
        write(&g, "y.png", 4, 3);
        let inputs = EvalInputs::from_dirs(&p, &g, None, None, DepthKind::Disparity).unwrap();
        assert_eq!(inputs.names, vec!["a.png", "b.png"]);
        assert!(inputs.gt[1].ends_with("y.png"));
    }
}
