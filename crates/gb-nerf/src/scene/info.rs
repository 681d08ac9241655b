//! A summary of a loaded scene, as printed by `cargo xtask scene-info`.

use super::{Scene, SceneFormat, SceneKind, Split};
use serde::Serialize;

/// Per-split numbers.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SplitInfo {
    /// Number of views.
    pub views: usize,
    /// Views that have a mask.
    pub with_mask: usize,
    /// Mean mask coverage over the views with a mask, in percent (0 when none).
    pub mask_coverage_mean_pct: f32,
    /// Smallest mask coverage, in percent (0 when none).
    pub mask_coverage_min_pct: f32,
    /// Largest mask coverage, in percent (0 when none).
    pub mask_coverage_max_pct: f32,
    /// Views with ground-truth depth.
    pub with_depth: usize,
    /// Views with ground-truth normals.
    pub with_normal: usize,
}

/// Everything `scene-info` reports.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneInfo {
    /// Scene name.
    pub name: String,
    /// Detected format.
    pub format: SceneFormat,
    /// Parameterisation of space.
    pub kind: SceneKind,
    /// Distinct image resolutions `(width, height)`, sorted.
    pub resolutions: Vec<(usize, usize)>,
    /// Intrinsics `(fx, fy, cx, cy)` of the first view.
    pub intrinsics: (f32, f32, f32, f32),
    /// Near bound.
    pub near: f32,
    /// Far bound.
    pub far: f32,
    /// Training views.
    pub train: SplitInfo,
    /// Test views.
    pub test: SplitInfo,
    /// Every warning raised while loading.
    pub warnings: Vec<String>,
}

impl SceneInfo {
    /// Summarises a scene.
    pub fn new(format: SceneFormat, scene: &Scene) -> Self {
        let mut resolutions: Vec<(usize, usize)> = scene
            .views
            .iter()
            .map(|v| (v.camera.width, v.camera.height))
            .collect();
        resolutions.sort();
        resolutions.dedup();
        let intrinsics = scene
            .views
            .first()
            .map(|v| (v.camera.fx, v.camera.fy, v.camera.cx, v.camera.cy))
            .unwrap_or_default();
        Self {
            name: scene.name.clone(),
            format,
            kind: scene.kind.clone(),
            resolutions,
            intrinsics,
            near: scene.near,
            far: scene.far,
            train: split_info(scene, Split::Train),
            test: split_info(scene, Split::Test),
            warnings: scene.warnings.clone(),
        }
    }

    /// A human-readable multi-line report.
    pub fn to_text(&self) -> String {
        let res: Vec<String> = self
            .resolutions
            .iter()
            .map(|(w, h)| format!("{w}x{h}"))
            .collect();
        let (fx, fy, cx, cy) = self.intrinsics;
        let mut s = format!(
            "scene      {}\nformat     {:?}\nkind       {:?}\nresolution {}\nintrinsics fx {fx:.3} fy {fy:.3} cx {cx:.3} cy {cy:.3}\nnear/far   {:.4} / {:.4}\n",
            self.name,
            self.format,
            self.kind,
            res.join(", "),
            self.near,
            self.far
        );
        for (label, si) in [("train", &self.train), ("test", &self.test)] {
            s += &format!(
                "{label:<10} {} views, {} with mask (coverage mean {:.2}%, min {:.2}%, max {:.2}%), {} with depth, {} with normals\n",
                si.views, si.with_mask, si.mask_coverage_mean_pct, si.mask_coverage_min_pct, si.mask_coverage_max_pct, si.with_depth, si.with_normal
            );
        }
        s += &format!("warnings   {}\n", self.warnings.len());
        for w in &self.warnings {
            s += &format!("  warning: {w}\n");
        }
        s
    }
}

fn split_info(scene: &Scene, split: Split) -> SplitInfo {
    let views: Vec<_> = scene.split(split).collect();
    let cov: Vec<f32> = views
        .iter()
        .filter_map(|v| v.mask.as_ref())
        .map(|m| m.coverage() * 100.0)
        .collect();
    let n = cov.len();
    SplitInfo {
        views: views.len(),
        with_mask: n,
        mask_coverage_mean_pct: if n > 0 {
            cov.iter().sum::<f32>() / n as f32
        } else {
            0.0
        },
        mask_coverage_min_pct: cov
            .iter()
            .copied()
            .fold(None, |a: Option<f32>, c| Some(a.map_or(c, |a| a.min(c))))
            .unwrap_or(0.0),
        mask_coverage_max_pct: cov.iter().copied().fold(0.0, f32::max),
        with_depth: views.iter().filter(|v| v.depth.is_some()).count(),
        with_normal: views.iter().filter(|v| v.normal.is_some()).count(),
    }
}
