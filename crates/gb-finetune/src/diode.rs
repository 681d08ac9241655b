//! The DIODE dataset (Vasiljevic et al. 2019, <https://diode-dataset.org>) as a
//! [`PairSource`] of RGB images and normal maps.
//!
//! **Layout** (the DIODE Depth release `train.tar.gz` / `val.tar.gz` with the DIODE Normal
//! release `train_normals.tar.gz` / `val_normals.tar.gz` extracted over the same tree):
//!
//! ```text
//! ROOT/
//!   train/ | val/                          the split (DiodeSplit)
//!     indoors/ | outdoor/                  scene type; at least one of them
//!       scene_XXXXX/
//!         scan_YYYYY/
//!           XXXXX_YYYYY_indoors_AAA_BBB.png             RGB, 1024 x 768
//!           XXXXX_YYYYY_indoors_AAA_BBB_depth.npy       float32 (H, W, 1): depth in metres
//!           XXXXX_YYYYY_indoors_AAA_BBB_depth_mask.npy  (H, W): 1 = valid sensor return
//!           XXXXX_YYYYY_indoors_AAA_BBB_normal.npy      float32 (H, W, 3): unit normal,
//!                                                       (0, 0, 0) where invalid
//! ```
//!
//! [`DiodeDataset::open`] scans the tree once, in sorted order (scene type, scene, scan,
//! file name), and checks that every image has its `_normal.npy` and `_depth_mask.npy`;
//! [`PairSource::load`] reads one sample lazily. A normal is valid where the depth mask is
//! 1 and the stored normal is non-zero; the axis conversion and the orientation towards the
//! camera (with DIODE's intrinsics [`DIODE_INTRINSICS`], scaled to the image size) are
//! [`crate::normal_map::diode_to_camera_gl`], whose docs give the source of DIODE's
//! convention. The depth is not needed for training pairs; [`DiodeDataset::load_depth`]
//! reads it (it is checked only then).
//!
//! The npy files may be float32/float64, bool or integer (the mask), C or Fortran order.

use crate::captions::CaptionFile;
use crate::normal_map::{diode_to_camera_gl, normals_to_map, pixel_ray_gl};
use crate::sample::{PairSample, PairSource};
use crate::FinetuneError;
use std::path::{Path, PathBuf};

/// DIODE's camera `[fx, fy, cx, cy]` for its 1024 x 768 images (diode-devkit
/// `intrinsics.txt`).
pub const DIODE_INTRINSICS: [f32; 4] = [886.81, 927.06, 512.0, 384.0];
/// The image size [`DIODE_INTRINSICS`] refer to.
pub const DIODE_SIZE: (usize, usize) = (1024, 768);
/// The scene-type folders, in scan order.
pub const SCENE_TYPES: [&str; 2] = ["indoors", "outdoor"];

/// Which companion file of an entry a check looks at.
type PathOf = fn(&DiodeEntry) -> &PathBuf;

/// The layout, for error messages.
const LAYOUT: &str = "ROOT/{train,val}/{indoors,outdoor}/scene_*/scan_*/NAME.png";

/// DIODE's intrinsics `[fx, fy, cx, cy]` scaled to an image of `width x height` (a
/// resized DIODE image).
pub fn diode_intrinsics(width: usize, height: usize) -> [f32; 4] {
    let sx = width as f32 / DIODE_SIZE.0 as f32;
    let sy = height as f32 / DIODE_SIZE.1 as f32;
    [
        DIODE_INTRINSICS[0] * sx,
        DIODE_INTRINSICS[1] * sy,
        DIODE_INTRINSICS[2] * sx,
        DIODE_INTRINSICS[3] * sy,
    ]
}

/// Which DIODE split.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DiodeSplit {
    /// `train/`.
    Train,
    /// `val/`.
    Val,
}

impl DiodeSplit {
    /// The folder name: `train` or `val`.
    pub fn as_str(&self) -> &'static str {
        match self {
            DiodeSplit::Train => "train",
            DiodeSplit::Val => "val",
        }
    }
}

impl std::fmt::Display for DiodeSplit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for DiodeSplit {
    type Err = FinetuneError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "train" => Ok(DiodeSplit::Train),
            "val" | "validation" => Ok(DiodeSplit::Val),
            other => Err(FinetuneError::Config {
                field: "split".into(),
                message: format!("unknown DIODE split '{other}' (expected train or val)"),
            }),
        }
    }
}

/// The files of one DIODE image.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DiodeEntry {
    /// Path of the RGB image relative to the root, with `/` separators
    /// (`val/indoors/scene_00019/scan_00183/NAME.png`): the caption key.
    pub relative: String,
    /// The RGB image `NAME.png`.
    pub rgb: PathBuf,
    /// `NAME_depth.npy`.
    pub depth: PathBuf,
    /// `NAME_depth_mask.npy`.
    pub depth_mask: PathBuf,
    /// `NAME_normal.npy`.
    pub normal: PathBuf,
    /// Its caption (empty when the caption file has none or none was given).
    pub caption: String,
}

/// A DIODE split as a [`PairSource`] (see the module docs).
#[derive(Debug, Clone)]
pub struct DiodeDataset {
    root: PathBuf,
    split: DiodeSplit,
    entries: Vec<DiodeEntry>,
}

/// A depth map and its validity mask, `[h * w]` each.
#[derive(Debug, Clone, PartialEq)]
pub struct DiodeDepth {
    /// Width.
    pub width: usize,
    /// Height.
    pub height: usize,
    /// Depth in metres (z-depth).
    pub depth: Vec<f32>,
    /// 1 where the sensor returned a valid depth, else 0.
    pub mask: Vec<f32>,
}

fn sorted_subdirs(dir: &Path, prefix: &str) -> Result<Vec<PathBuf>, FinetuneError> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).map_err(|e| FinetuneError::io(dir, e))? {
        let e = e.map_err(|e| FinetuneError::io(dir, e))?;
        let p = e.path();
        let name = e.file_name().to_string_lossy().to_string();
        if name.starts_with(prefix) && p.is_dir() {
            out.push(p);
        }
    }
    out.sort();
    Ok(out)
}

fn companion(rgb: &Path, suffix: &str) -> PathBuf {
    let stem = rgb
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_default();
    rgb.with_file_name(format!("{stem}{suffix}"))
}

fn file_name(p: &Path) -> String {
    p.file_name()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_default()
}

impl DiodeDataset {
    /// Scans `root/{split}/` (see the module docs for the layout), with captions from a
    /// JSONL caption file keyed by the image path relative to `root` (or its name or stem;
    /// see [`crate::captions`]). Images without a caption get an empty one (a warning gives
    /// their count).
    ///
    /// Errors name what was expected where: a missing root or split folder, a split with no
    /// `indoors/` or `outdoor/` folder or no image, an image without its `_normal.npy` or
    /// `_depth_mask.npy` (the first such file, and how many images lack one).
    pub fn open(
        root: &Path,
        split: DiodeSplit,
        captions: Option<&Path>,
    ) -> Result<Self, FinetuneError> {
        if !root.is_dir() {
            return Err(FinetuneError::Missing {
                what: format!("DIODE root folder (layout {LAYOUT})"),
                path: root.to_path_buf(),
            });
        }
        let split_dir = root.join(split.as_str());
        if !split_dir.is_dir() {
            return Err(FinetuneError::Missing {
                what: format!("DIODE split folder `{}/` (layout {LAYOUT})", split.as_str()),
                path: split_dir,
            });
        }
        let types: Vec<PathBuf> = SCENE_TYPES
            .iter()
            .map(|t| split_dir.join(t))
            .filter(|p| p.is_dir())
            .collect();
        if types.is_empty() {
            return Err(FinetuneError::Missing {
                what: "DIODE scene-type folder `indoors/` or `outdoor/`".into(),
                path: split_dir,
            });
        }
        let mut rgbs = Vec::new();
        for t in &types {
            for scene in sorted_subdirs(t, "scene_")? {
                for scan in sorted_subdirs(&scene, "scan_")? {
                    let mut files = Vec::new();
                    for e in std::fs::read_dir(&scan).map_err(|e| FinetuneError::io(&scan, e))? {
                        let p = e.map_err(|e| FinetuneError::io(&scan, e))?.path();
                        let is_png = p.extension().is_some_and(|x| x.eq_ignore_ascii_case("png"));
                        if is_png && p.is_file() {
                            files.push(p);
                        }
                    }
                    files.sort();
                    rgbs.extend(files);
                }
            }
        }
        if rgbs.is_empty() {
            return Err(FinetuneError::Missing {
                what: format!(
                    "DIODE RGB images `*.png` in {}/{{indoors,outdoor}}/scene_*/scan_*/",
                    split.as_str()
                ),
                path: split_dir,
            });
        }
        let captions = captions.map(CaptionFile::load).transpose()?;
        let mut entries = Vec::with_capacity(rgbs.len());
        for rgb in rgbs {
            let relative = rgb
                .strip_prefix(root)
                .unwrap_or(&rgb)
                .components()
                .map(|c| c.as_os_str().to_string_lossy().to_string())
                .collect::<Vec<_>>()
                .join("/");
            let caption = captions
                .as_ref()
                .and_then(|c| c.get(&relative))
                .unwrap_or("")
                .to_string();
            entries.push(DiodeEntry {
                depth: companion(&rgb, "_depth.npy"),
                depth_mask: companion(&rgb, "_depth_mask.npy"),
                normal: companion(&rgb, "_normal.npy"),
                relative,
                rgb,
                caption,
            });
        }
        let n = entries.len();
        fn normal_of(e: &DiodeEntry) -> &PathBuf {
            &e.normal
        }
        fn mask_of(e: &DiodeEntry) -> &PathBuf {
            &e.depth_mask
        }
        let checks: [(&str, &str, PathOf); 2] = [
            (
                "normal file",
                "normals release `{split}_normals.tar.gz`",
                normal_of,
            ),
            ("depth-mask file", "depth release `{split}.tar.gz`", mask_of),
        ];
        for (what, release, get) in checks {
            let missing: Vec<&DiodeEntry> = entries.iter().filter(|e| !get(e).is_file()).collect();
            if let Some(first) = missing.first() {
                return Err(FinetuneError::Missing {
                    what: format!(
                        "DIODE {what} `{}` for image `{}` (from DIODE's {}, extracted into the \
                         same tree); {} of {n} images lack theirs",
                        file_name(get(first)),
                        file_name(&first.rgb),
                        release.replace("{split}", split.as_str()),
                        missing.len()
                    ),
                    path: get(first).clone(),
                });
            }
        }
        if let Some(c) = &captions {
            let without = entries
                .iter()
                .filter(|e| c.get(&e.relative).is_none())
                .count();
            if without > 0 {
                tracing::warn!(
                    "{}: no caption for {without} of {n} DIODE images; they use the bare \
                     modality identifiers",
                    c.path.display()
                );
            }
        }
        Ok(Self {
            root: root.to_path_buf(),
            split,
            entries,
        })
    }

    /// The dataset root.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The split.
    pub fn split(&self) -> DiodeSplit {
        self.split
    }

    /// The images, in load order.
    pub fn entries(&self) -> &[DiodeEntry] {
        &self.entries
    }

    fn entry(&self, index: usize) -> Result<&DiodeEntry, FinetuneError> {
        self.entries
            .get(index)
            .ok_or_else(|| FinetuneError::Config {
                field: "index".into(),
                message: format!(
                    "sample {index} out of range: DIODE {} under {} has {}",
                    self.split,
                    self.root.display(),
                    self.entries.len()
                ),
            })
    }

    /// The depth map and its mask of image `index` (`_depth.npy` `(H, W, 1)` or `(H, W)`,
    /// `_depth_mask.npy` `(H, W)` or `(H, W, 1)`, of the same size).
    pub fn load_depth(&self, index: usize) -> Result<DiodeDepth, FinetuneError> {
        let e = self.entry(index)?;
        if !e.depth.is_file() {
            return Err(FinetuneError::Missing {
                what: format!(
                    "DIODE depth file `{}` for image `{}`",
                    file_name(&e.depth),
                    file_name(&e.rgb)
                ),
                path: e.depth.clone(),
            });
        }
        let (shape, depth) = read_npy_f32(&e.depth)?;
        let (h, w) = plane_shape(&e.depth, &shape, None)?;
        let mask = read_mask(&e.depth_mask, w, h)?;
        Ok(DiodeDepth {
            width: w,
            height: h,
            depth,
            mask,
        })
    }
}

/// `(H, W)` of an `(H, W)` or `(H, W, 1)` array, checked against `expected` `(h, w)`.
fn plane_shape(
    path: &Path,
    shape: &[u64],
    expected: Option<(usize, usize)>,
) -> Result<(usize, usize), FinetuneError> {
    let ok = matches!(shape, [_, _] | [_, _, 1]);
    let hw = (
        shape.first().copied().unwrap_or(0) as usize,
        shape.get(1).copied().unwrap_or(0) as usize,
    );
    let want = match expected {
        Some((h, w)) => format!("({h}, {w}) or ({h}, {w}, 1)"),
        None => "(H, W) or (H, W, 1)".into(),
    };
    if !ok || expected.is_some_and(|e| e != hw) {
        return Err(FinetuneError::Invalid {
            path: path.to_path_buf(),
            message: format!("array shape {shape:?}, expected {want}"),
        });
    }
    Ok(hw)
}

fn read_mask(path: &Path, w: usize, h: usize) -> Result<Vec<f32>, FinetuneError> {
    let (shape, data) = read_npy_f32(path)?;
    plane_shape(path, &shape, Some((h, w)))?;
    Ok(data
        .into_iter()
        .map(|v| if v > 0.5 { 1.0 } else { 0.0 })
        .collect())
}

impl PairSource for DiodeDataset {
    fn len(&self) -> usize {
        self.entries.len()
    }

    fn load(&self, index: usize) -> Result<PairSample, FinetuneError> {
        let e = self.entry(index)?;
        let img = gb_core::read_rgb(&e.rgb, None).map_err(|err| FinetuneError::Invalid {
            path: e.rgb.clone(),
            message: match err {
                gb_core::ImageIoError::Read { error, .. } => {
                    format!("cannot read image: {error}")
                }
                other => other.to_string(),
            },
        })?;
        let (w, h) = (img.width, img.height);
        let (shape, raw) = read_npy_f32(&e.normal)?;
        if shape != [h as u64, w as u64, 3] {
            return Err(FinetuneError::Invalid {
                path: e.normal.clone(),
                message: format!(
                    "array shape {shape:?}, expected (H, W, 3) = ({h}, {w}, 3) to match `{}`",
                    file_name(&e.rgb)
                ),
            });
        }
        let mask = read_mask(&e.depth_mask, w, h)?;
        let [fx, fy, cx, cy] = diode_intrinsics(w, h);
        let normals: Vec<[f32; 3]> = raw
            .chunks_exact(3)
            .enumerate()
            .map(|(i, n)| {
                let ray = pixel_ray_gl(i % w, i / w, fx, fy, cx, cy);
                diode_to_camera_gl([n[0], n[1], n[2]], ray)
            })
            .collect();
        let (normal, normal_valid) = normals_to_map(&normals, Some(&mask));
        let name = e
            .rgb
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default();
        Ok(PairSample {
            name,
            width: w,
            height: h,
            rgb: img.data,
            normal: Some(normal),
            normal_valid,
            caption: e.caption.clone(),
        })
    }
}

/// Reads a numeric `.npy` array (float, integer or bool; C or Fortran order) as C-order
/// `f32`, with its shape, through the workspace's one reader ([`gb_core::npy`]). Errors name
/// the file.
pub fn read_npy_f32(path: &Path) -> Result<(Vec<u64>, Vec<f32>), FinetuneError> {
    let bytes = std::fs::read(path).map_err(|e| FinetuneError::io(path, e))?;
    let array = gb_core::npy::read_npy(&bytes).map_err(|e| FinetuneError::Invalid {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    Ok((
        array.shape,
        array.data.into_iter().map(|v| v as f32).collect(),
    ))
}
