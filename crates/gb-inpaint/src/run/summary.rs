//! [`RunSummary`]: the typed record of one run, written as its `metrics.json` and read back
//! by the grid's tables.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::InpaintError;
use crate::export::ExportInfo;

/// The metrics of one test view (`null` in JSON where a value is absent or not finite).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewMetrics {
    /// The view's name.
    pub view: String,
    /// PSNR over the whole image, dB.
    pub psnr: Option<f64>,
    /// SSIM over the whole image.
    pub ssim: Option<f64>,
    /// PSNR over the mask's bounding box (views with a mask).
    pub psnr_bbox: Option<f64>,
    /// SSIM over the mask's bounding box (`null` when the box is under 11 pixels).
    pub ssim_bbox: Option<f64>,
    /// PSNR of the 8-bit max-normalised disparity (scenes with ground-truth depth).
    pub d_psnr: Option<f64>,
    /// Mean field evaluations per ray of the render.
    pub evaluations_per_ray: f32,
}

/// Means over the test views of [`ViewMetrics`] (finite values only).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MeanMetrics {
    /// Mean PSNR.
    pub psnr: Option<f64>,
    /// Mean SSIM.
    pub ssim: Option<f64>,
    /// Mean mask-box PSNR.
    pub psnr_bbox: Option<f64>,
    /// Mean mask-box SSIM.
    pub ssim_bbox: Option<f64>,
    /// Mean disparity PSNR.
    pub d_psnr: Option<f64>,
}

impl MeanMetrics {
    /// The finite means of `views`' values.
    pub fn of(views: &[ViewMetrics]) -> Self {
        let mean = |f: fn(&ViewMetrics) -> Option<f64>| {
            let v: Vec<f64> = views
                .iter()
                .filter_map(f)
                .filter(|v| v.is_finite())
                .collect();
            (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
        };
        Self {
            psnr: mean(|v| v.psnr),
            ssim: mean(|v| v.ssim),
            psnr_bbox: mean(|v| v.psnr_bbox),
            ssim_bbox: mean(|v| v.ssim_bbox),
            d_psnr: mean(|v| v.d_psnr),
        }
    }
}

/// Counts and timings of the guidance over the whole run.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GuidanceSummary {
    /// Steps with at least one guidance term.
    pub guided_steps: usize,
    /// Steps without guidance.
    pub unguided_steps: usize,
    /// Steps skipped for a non-finite loss.
    pub skipped_steps: usize,
    /// Mean wall time of a guided step, s.
    pub seconds_per_guided_step: Option<f64>,
    /// Mean wall time of an unguided step, s.
    pub seconds_per_unguided_step: Option<f64>,
    /// U-Net calls.
    pub unet_calls: usize,
    /// The step the normal-map guidance starts at.
    pub normal_start: usize,
    /// The prior's square resolution (guided runs).
    pub resolution: Option<usize>,
}

/// The orbit animation `orbit.gif`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OrbitSummary {
    /// The file, relative to the run folder.
    pub file: String,
    /// Frames.
    pub frames: usize,
    /// Frame width.
    pub width: usize,
    /// Frame height.
    pub height: usize,
    /// Wall time of the renders and the write, s.
    pub seconds: f64,
}

/// What one run measured: its `metrics.json`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RunSummary {
    /// The method's name.
    pub method: String,
    /// The prior folder, or `none`.
    pub prior: String,
    /// The LoRA attached to the prior, if any.
    pub lora: Option<PathBuf>,
    /// The scene's name.
    pub scene: String,
    /// The preset's name.
    pub preset: String,
    /// The backend (`flex`, `ndarray`, `wgpu`).
    pub device: String,
    /// Steps trained (a resumed run's earlier steps included).
    pub steps: usize,
    /// Wall time of this process's training, s.
    pub train_seconds_this_run: f64,
    /// Wall time of the geometry term's unguided pass ([`crate::geometry`]), s; absent when
    /// this run made none (no term, nothing inside the mask to hold, or a finished
    /// checkpoint resumed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unguided_seconds: Option<f64>,
    /// The `--baseline` checkpoint that the unguided pass read instead of training (a
    /// finished `none` run of the same configuration, scene and backend); absent when it
    /// trained or made none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unguided_from: Option<PathBuf>,
    /// The `--baseline` checkpoint that is this run's field: an `auto` choice of zero weights
    /// trains exactly as `none`, so a matching finished `none` run is read instead of trained
    /// (its log is copied, and this run's checkpoint written from it); absent when trained.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub field_from: Option<PathBuf>,
    /// Wall time of the test-view renders, s.
    pub render_seconds: f64,
    /// Wall time of the metrics, s.
    pub eval_seconds: f64,
    /// The nerfstudio export (`export/`; present only with `--export full`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub export: Option<ExportInfo>,
    /// The orbit animation, when one was written.
    pub orbit: Option<OrbitSummary>,
    /// The preset's samples per ray.
    pub samples_per_ray: usize,
    /// Mean field evaluations per ray of the training batches.
    pub mean_train_evaluations_per_ray: f32,
    /// Guidance counts and timings.
    pub guidance: GuidanceSummary,
    /// The per-scene LoRA, when the method personalises the prior.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub personalize: Option<crate::personalize::PersonalizeReport>,
    /// The weights the scene chose (`lambda_rgb` / `lambda_normal = "auto"`): pseudo-hole,
    /// trials, scores and choice ([`crate::auto`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub auto: Option<crate::auto::AutoReport>,
    /// Number of test views.
    pub test_views: usize,
    /// Means over the test views.
    pub mean: MeanMetrics,
    /// Per test view.
    pub views: Vec<ViewMetrics>,
    /// Every gb-eval metric that applies (`gb_eval::report::EvalReport`'s JSON: values,
    /// per image, and `unavailable` reasons).
    pub eval: serde_json::Value,
    /// The report page, relative to the run folder.
    pub report: String,
    /// How to read the numbers.
    pub notes: String,
}

/// The conventions behind [`RunSummary`]'s numbers, written with every run.
pub const NOTES: &str = "PSNR/SSIM: gb_eval (scikit-image conventions) on [0,1] RGB; *_bbox \
    over the test view's mask bounding box; d_psnr: PSNR of 8-bit max-normalised disparity \
    (gb_eval::disparity); d_psnr_true: the same with both maps divided by the true maximum \
    (where the nearest point is rendered does not rescale the region); infinite values are \
    written as null; guidance counts and timings (wall time per step) cover the whole run, a \
    resumed run's steps before its checkpoint included (train_log.jsonl has every step); \
    `eval`: every gb-eval metric that applies (cargo xtask eval's keys and JSON: _bbox, _mask \
    regions, lpips = ST-LPIPS, fid / d_fid, brisque, nima), unavailable ones null with the \
    reason under eval.unavailable; a scene \
    without test views is scored on its first masked training views (renders/train_*) by the \
    no-reference metrics only: brisque / nima of the whole render and, as brisque_bbox / \
    nima_bbox, of the mask's bounding box (the filled region)";

impl RunSummary {
    /// A value of the `eval` block: `Ok(number)` (`"inf"` is infinity), or `Err(reason)`
    /// (the recorded reason it is unavailable).
    pub fn eval_value(&self, key: &str) -> Result<f64, String> {
        match &self.eval[key] {
            serde_json::Value::Number(n) => n.as_f64().ok_or_else(|| "not a number".into()),
            serde_json::Value::String(s) if s == "inf" => Ok(f64::INFINITY),
            _ => Err(self.eval["unavailable"][key]
                .as_str()
                .unwrap_or("not computed")
                .to_string()),
        }
    }

    /// Reads a run's `metrics.json`.
    pub fn read(path: &Path) -> Result<Self, InpaintError> {
        let text = std::fs::read_to_string(path).map_err(|e| InpaintError::io(path, e))?;
        serde_json::from_str(&text).map_err(|e| InpaintError::Spec {
            field: path.display().to_string(),
            reason: format!("not a run's metrics.json: {e}"),
        })
    }

    /// Writes it atomically as pretty JSON.
    pub fn write(&self, path: &Path) -> Result<(), InpaintError> {
        let bytes = serde_json::to_vec_pretty(self)
            .map_err(|e| InpaintError::io(path, std::io::Error::other(e)))?;
        gb_core::write_atomic(path, &bytes).map_err(|e| InpaintError::io(path, e))
    }
}
