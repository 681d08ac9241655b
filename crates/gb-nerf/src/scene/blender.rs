//! Loader for Blender (NeRF-synthetic) and nerfstudio `transforms*.json` scenes.
//!
//! - Splits: `transforms_train.json` (train) and `transforms_test.json` (test). A single
//!   `transforms.json` (nerfstudio) gives training views, of which every n-th can be held out
//!   with [`BlenderOptions::holdout_every`]. `transforms_val.json` is not read.
//! - Intrinsics: `fl_x`, `fl_y`, `cx`, `cy` (top level, or per frame overriding the top level);
//!   otherwise `camera_angle_x` (and `camera_angle_y` if present): `f = 0.5 * W / tan(angle/2)`,
//!   principal point at the image centre. When the JSON gives `w`/`h` and the image has
//!   another size, `fl_x, cx` and `fl_y, cy` are scaled by the width and height ratios.
//! - Poses: `transform_matrix` (4x4 or 3x4) is camera-to-world with OpenGL camera axes
//!   already, as both Blender and nerfstudio use.
//! - Images: `file_path` relative to the JSON file; `.png` is appended when it has no
//!   extension. RGBA is composited on [`BlenderOptions::background`].
//! - The 8-bit `*_depth_0001.png` / `*_normal_0001.png` passes of the NeRF-synthetic test
//!   set are NOT loaded into [`View::depth`] / [`View::normal`]: they are display-only
//!   (8-bit, unknown depth mapping, negative normal components clipped to 0).
//! - Space: [`SceneKind::Bounded`] with the box `[-1.5, 1.5]^3`, near 2 and far 6 (the
//!   NeRF-synthetic convention), unless the JSON has `aabb_min`/`aabb_max`, `near`/`far`.

use super::{Camera, Scene, SceneError, SceneKind, Split, View};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// Options of the Blender / nerfstudio loader.
#[derive(Debug, Clone, PartialEq)]
pub struct BlenderOptions {
    /// Colour that RGBA images are composited on, in [0, 1].
    pub background: [f32; 3],
    /// For a single `transforms.json`: make every n-th frame (0, n, 2n, ...) a test view.
    pub holdout_every: Option<usize>,
}

impl Default for BlenderOptions {
    fn default() -> Self {
        Self {
            background: [1.0, 1.0, 1.0],
            holdout_every: None,
        }
    }
}

/// Whether `dir` looks like a Blender / nerfstudio scene.
pub fn is_blender(dir: &Path) -> bool {
    dir.join("transforms_train.json").is_file() || dir.join("transforms.json").is_file()
}

/// Loads a Blender / nerfstudio scene (see the module docs).
pub fn load(dir: &Path, opts: &BlenderOptions) -> Result<Scene, SceneError> {
    if !dir.is_dir() {
        return Err(SceneError::NotAFolder {
            path: dir.to_path_buf(),
        });
    }
    let mut files: Vec<(PathBuf, Option<Split>)> = Vec::new();
    if dir.join("transforms_train.json").is_file() {
        files.push((dir.join("transforms_train.json"), Some(Split::Train)));
        if dir.join("transforms_test.json").is_file() {
            files.push((dir.join("transforms_test.json"), Some(Split::Test)));
        }
    } else if dir.join("transforms.json").is_file() {
        files.push((dir.join("transforms.json"), None));
    } else {
        return Err(SceneError::Missing {
            path: dir.join("transforms_train.json"),
            what: "Blender transforms".into(),
        });
    }
    let mut views = Vec::new();
    let mut bounds: Option<(f32, f32)> = None;
    let mut aabb: Option<([f32; 3], [f32; 3])> = None;
    for (path, split) in &files {
        let json = read_json(path)?;
        if let (Some(n), Some(f)) = (
            json.get("near").and_then(Value::as_f64),
            json.get("far").and_then(Value::as_f64),
        ) {
            bounds = Some((n as f32, f as f32));
        }
        if let (Some(lo), Some(hi)) = (vec3(json.get("aabb_min")), vec3(json.get("aabb_max"))) {
            aabb = Some((lo, hi));
        }
        let frames = json
            .get("frames")
            .and_then(Value::as_array)
            .ok_or_else(|| SceneError::Json {
                path: path.clone(),
                reason: "no \"frames\" array".into(),
            })?;
        for (i, frame) in frames.iter().enumerate() {
            let split = match split {
                Some(s) => *s,
                None => match opts.holdout_every {
                    Some(n) if n > 0 && i % n == 0 => Split::Test,
                    _ => Split::Train,
                },
            };
            views.push(load_frame(path, &json, frame, i, split, opts.background)?);
        }
    }
    if views.is_empty() {
        return Err(SceneError::Json {
            path: files[0].0.clone(),
            reason: "no frames".into(),
        });
    }
    let (near, far) = bounds.unwrap_or((2.0, 6.0));
    let (aabb_min, aabb_max) = aabb.unwrap_or(([-1.5; 3], [1.5; 3]));
    Ok(Scene {
        name: dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        kind: SceneKind::Bounded { aabb_min, aabb_max },
        views,
        near,
        far,
        background: opts.background,
        warnings: Vec::new(),
        sparse_depth: Default::default(),
    })
}

fn read_json(path: &Path) -> Result<Value, SceneError> {
    let text = std::fs::read_to_string(path).map_err(|e| SceneError::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| SceneError::Json {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })
}

fn vec3(v: Option<&Value>) -> Option<[f32; 3]> {
    let a = v?.as_array()?;
    if a.len() != 3 {
        return None;
    }
    Some([
        a[0].as_f64()? as f32,
        a[1].as_f64()? as f32,
        a[2].as_f64()? as f32,
    ])
}

/// A number from the frame, else from the file's top level.
fn field(frame: &Value, top: &Value, key: &str) -> Option<f64> {
    frame
        .get(key)
        .and_then(Value::as_f64)
        .or_else(|| top.get(key).and_then(Value::as_f64))
}

fn load_frame(
    json_path: &Path,
    top: &Value,
    frame: &Value,
    index: usize,
    split: Split,
    bg: [f32; 3],
) -> Result<View, SceneError> {
    let bad = |reason: String| SceneError::Json {
        path: json_path.to_path_buf(),
        reason: format!("frame {index}: {reason}"),
    };
    let rel = frame
        .get("file_path")
        .and_then(Value::as_str)
        .ok_or_else(|| bad("no \"file_path\"".into()))?;
    let base = json_path.parent().unwrap_or(Path::new("."));
    let mut img_path = base.join(rel.trim_start_matches("./"));
    if img_path.extension().is_none() {
        img_path.set_extension("png");
    }
    if !img_path.is_file() {
        return Err(bad(format!(
            "file_path \"{rel}\" names {}, which does not exist",
            img_path.display()
        )));
    }
    let image = gb_core::read_rgb(&img_path, Some(bg))?;
    let (w, h) = (image.width, image.height);
    let m = frame
        .get("transform_matrix")
        .and_then(Value::as_array)
        .ok_or_else(|| bad("no \"transform_matrix\"".into()))?;
    if m.len() < 3 {
        return Err(bad(format!(
            "transform_matrix has {} rows, expected 3 or 4",
            m.len()
        )));
    }
    let mut c2w = [[0.0f32; 4]; 3];
    for (i, row) in c2w.iter_mut().enumerate() {
        let r = m[i]
            .as_array()
            .filter(|r| r.len() == 4)
            .ok_or_else(|| bad(format!("transform_matrix row {i} is not 4 numbers")))?;
        for (j, v) in r.iter().enumerate() {
            let x = v
                .as_f64()
                .filter(|x| x.is_finite())
                .ok_or_else(|| bad(format!("transform_matrix[{i}][{j}] is not a finite number")))?;
            row[j] = x as f32;
        }
    }
    let (fx, fy) = match (field(frame, top, "fl_x"), field(frame, top, "fl_y")) {
        (Some(fx), fy) => (fx, fy.unwrap_or(fx)),
        (None, _) => {
            let ax = field(frame, top, "camera_angle_x")
                .ok_or_else(|| bad("neither fl_x nor camera_angle_x".into()))?;
            let fx = 0.5 * w as f64 / (0.5 * ax).tan();
            let fy = field(frame, top, "camera_angle_y")
                .map(|ay| 0.5 * h as f64 / (0.5 * ay).tan())
                .unwrap_or(fx);
            (fx, fy)
        }
    };
    if !(fx.is_finite() && fx > 0.0 && fy.is_finite() && fy > 0.0) {
        return Err(bad(format!("focal length {fx}, {fy} is not positive")));
    }
    let cx = field(frame, top, "cx").unwrap_or(w as f64 / 2.0);
    let cy = field(frame, top, "cy").unwrap_or(h as f64 / 2.0);
    // nerfstudio intrinsics are given at the JSON's `w` x `h`; rescale to the image read
    let sx = field(frame, top, "w")
        .filter(|&jw| jw > 0.0)
        .map(|jw| w as f64 / jw)
        .unwrap_or(1.0);
    let sy = field(frame, top, "h")
        .filter(|&jh| jh > 0.0)
        .map(|jh| h as f64 / jh)
        .unwrap_or(1.0);
    let (fx, cx, fy, cy) = if frame.get("fl_x").is_some() || top.get("fl_x").is_some() {
        (fx * sx, cx * sx, fy * sy, cy * sy)
    } else {
        (fx, cx, fy, cy)
    };
    let name = img_path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let camera = Camera {
        width: w,
        height: h,
        fx: fx as f32,
        fy: fy as f32,
        cx: cx as f32,
        cy: cy as f32,
        c2w,
    };
    Ok(View {
        name,
        camera,
        image,
        mask: None,
        depth: None,
        normal: None,
        split,
    })
}
