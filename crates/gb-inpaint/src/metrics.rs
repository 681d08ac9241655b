//! Every metric of `gb_eval` that applies to a run's test views, as one
//! [`gb_eval::report::EvalReport`] (the same keys and JSON as `cargo xtask eval`):
//!
//! - `psnr`, `ssim` over the whole image, the mask's bounding box (`_bbox`) and the mask
//!   (`_mask`);
//! - `lpips` (ST-LPIPS, AlexNet, shift tolerant) over the whole image and the bounding box,
//!   when the weights folder holds `stlpips_alex_shift_tolerant.safetensors`;
//! - `d_psnr` (PSNR of the 8-bit max-normalised disparity, `gb_eval::disparity`) over the
//!   three regions, where the scene has ground-truth depth;
//! - `fid` and `d_fid` when there are at least [`FID_MIN_IMAGES`] test views and the
//!   Inception weights are in the weights folder;
//! - `brisque` (no reference) with OpenCV's LIVE model, and `nima` with its weights, when the
//!   weights folder holds them.
//!
//! A metric that cannot be computed is recorded as unavailable with its reason, never as a
//! number (`report.values[key] = Outcome::Unavailable(reason)`).

use std::path::PathBuf;

use gb_core::{BackendKind, RgbImage};
use gb_eval::disparity::{d_psnr, disparity_to_rgb8, ScalarMap};
use gb_eval::fid::FidExtractor;
use gb_eval::report::{EvalReport, RegionKind};
use gb_eval::stlpips::StLpips;
use gb_eval::{psnr, ssim, MetricError, Region};

/// FID and D-FID need at least this many test views. `gb_eval::fid::check_counts` accepts 2,
/// but the Frechet distance of a handful of 2048-dimensional features is dominated by the
/// covariance estimate's noise; below this count the metric is reported unavailable.
pub const FID_MIN_IMAGES: usize = 8;

/// One evaluated test view.
#[derive(Debug, Clone)]
pub struct ViewPair {
    /// View name (file stem).
    pub name: String,
    /// The render.
    pub pred: RgbImage,
    /// The ground truth.
    pub gt: RgbImage,
    /// The object mask (row-major, `true` inside), when the view has one.
    pub mask: Option<Vec<bool>>,
    /// Rendered and ground-truth disparity, when the scene has ground-truth depth.
    pub disparity: Option<(ScalarMap, ScalarMap)>,
}

/// Where the network metrics find their weights and run.
#[derive(Debug, Clone)]
pub struct MetricOptions {
    /// The weights folder (`$GB_TEST_DATA/weights` layout), if any.
    pub weights: Option<PathBuf>,
    /// Backend of the network metrics.
    pub device: BackendKind,
    /// Minimum number of views for FID / D-FID (default [`FID_MIN_IMAGES`]).
    pub fid_min_images: usize,
}

impl MetricOptions {
    /// `weights`, or `$GB_TEST_DATA/weights` when it exists.
    pub fn new(weights: Option<PathBuf>, device: BackendKind) -> Self {
        let weights = weights.or_else(|| {
            let dir = PathBuf::from(std::env::var_os("GB_TEST_DATA")?).join("weights");
            dir.is_dir().then_some(dir)
        });
        Self {
            weights,
            device,
            fid_min_images: FID_MIN_IMAGES,
        }
    }

    /// The weights file `name`, or why it is not there.
    fn file(&self, name: &str, flag: &str) -> Result<PathBuf, String> {
        match &self.weights {
            Some(dir) if dir.join(name).is_file() => Ok(dir.join(name)),
            Some(dir) => Err(format!(
                "weights file {} not found",
                dir.join(name).display()
            )),
            None => Err(format!(
                "no weights folder (pass {flag} DIR holding {name}, or set GB_TEST_DATA)"
            )),
        }
    }
}

/// Per-image values of one key, or the first error.
struct Values {
    key: String,
    values: Vec<f64>,
    error: Option<String>,
}

impl Values {
    fn new(key: String) -> Self {
        Self {
            key,
            values: Vec::new(),
            error: None,
        }
    }

    fn push(&mut self, name: &str, v: Result<f64, String>) {
        match v {
            Ok(v) => self.values.push(v),
            Err(e) => {
                if self.error.is_none() {
                    self.error = Some(format!("{name}: {e}"));
                }
            }
        }
    }

    fn store(self, report: &mut EvalReport) {
        match self.error {
            Some(e) => report.set_unavailable(self.key, e),
            None if self.values.is_empty() => {
                report.set_unavailable(self.key, "no view has the inputs this metric needs")
            }
            None => report.set_per_image(&self.key, &self.values),
        }
    }
}

/// The regions of one view: full image, and with a mask its bounding box and its pixels.
fn regions(v: &ViewPair) -> Vec<(RegionKind, Result<Region, String>)> {
    let mut out = vec![(RegionKind::Full, Ok(Region::Full))];
    if let Some(mask) = &v.mask {
        let bbox = Region::bbox_of_mask(mask, v.gt.width)
            .ok_or_else(|| MetricError::EmptyMask.to_string());
        out.push((RegionKind::BBox, bbox));
        out.push((RegionKind::Mask, Ok(Region::Mask(mask.clone()))));
    }
    out
}

/// Runs `f` over every view and region in `kinds` as key `base` (+ region suffix).
fn per_region(
    report: &mut EvalReport,
    views: &[ViewPair],
    base: &str,
    kinds: &[RegionKind],
    f: impl Fn(&ViewPair, &Region) -> Result<f64, String>,
) {
    let any_mask = views.iter().any(|v| v.mask.is_some());
    for &kind in kinds {
        if kind != RegionKind::Full && !any_mask {
            continue;
        }
        let mut vals = Values::new(kind.key(base));
        for v in views {
            if let Some((_, region)) = regions(v).into_iter().find(|(k, _)| *k == kind) {
                vals.push(&v.name, region.and_then(|r| f(v, &r)));
            }
        }
        vals.store(report);
    }
}

/// Evaluates the views (see the module docs). Never fails: every problem becomes an
/// unavailable metric with its reason.
pub fn evaluate(views: &[ViewPair], opts: &MetricOptions) -> EvalReport {
    let names: Vec<String> = views.iter().map(|v| v.name.clone()).collect();
    let mut report = EvalReport::new(&names);
    report
        .context
        .insert("device".into(), opts.device.name().to_string());
    if let Some(w) = &opts.weights {
        report
            .context
            .insert("weights".into(), w.display().to_string());
    }
    if views.is_empty() {
        for key in ["psnr", "ssim", "lpips", "d_psnr", "fid", "d_fid"] {
            report.set_unavailable(key, "the scene has no test view with ground truth");
        }
        return report;
    }
    let e = |r: Result<f64, MetricError>| r.map_err(|e| e.to_string());
    per_region(&mut report, views, "psnr", &RegionKind::ALL, |v, r| {
        e(psnr(&v.pred, &v.gt, r))
    });
    per_region(&mut report, views, "ssim", &RegionKind::ALL, |v, r| {
        e(ssim(&v.pred, &v.gt, r))
    });

    // ST-LPIPS
    let lpips_kinds = [RegionKind::Full, RegionKind::BBox];
    let any_mask = views.iter().any(|v| v.mask.is_some());
    let lpips_keys: Vec<String> = lpips_kinds
        .iter()
        .filter(|k| **k == RegionKind::Full || any_mask)
        .map(|k| k.key("lpips"))
        .collect();
    let lpips = opts
        .file(StLpips::WEIGHTS_FILE, "--weights")
        .and_then(|p| StLpips::load(&p, &opts.device.device()).map_err(|e| e.to_string()));
    match lpips {
        Ok(model) => per_region(&mut report, views, "lpips", &lpips_kinds, |v, r| match r {
            Region::Full => e(model.distance(&v.pred, &v.gt)),
            Region::BBox { x0, y0, x1, y1 } => {
                e(model.distance_bbox(&v.pred, &v.gt, (*x0, *y0, *x1, *y1)))
            }
            Region::Mask(_) => Err("ST-LPIPS has no per-pixel mask variant".into()),
        }),
        Err(reason) => {
            for k in &lpips_keys {
                report.set_unavailable(k.clone(), format!("ST-LPIPS: {reason}"));
            }
        }
    }

    // D-PSNR
    let with_depth: Vec<&ViewPair> = views.iter().filter(|v| v.disparity.is_some()).collect();
    if with_depth.is_empty() {
        report.set_unavailable("d_psnr", "the scene has no ground-truth depth");
    } else {
        per_region(
            &mut report,
            views,
            "d_psnr",
            &RegionKind::ALL,
            |v, r| match &v.disparity {
                Some((p, g)) => e(d_psnr(p, g, r)),
                None => Err("no ground-truth depth".into()),
            },
        );
    }

    // FID and D-FID
    fid_metrics(&mut report, views, opts, !with_depth.is_empty());

    // no-reference metrics of the renders
    brisque(&mut report, views, opts);
    nima(&mut report, views, opts);
    report
}

fn fid_metrics(report: &mut EvalReport, views: &[ViewPair], opts: &MetricOptions, depth: bool) {
    let n = views.len();
    let too_few = (n < opts.fid_min_images).then(|| {
        format!(
            "{n} test view(s): FID needs at least {} images for a meaningful covariance",
            opts.fid_min_images
        )
    });
    let extractor = match too_few {
        Some(r) => Err(r),
        None => opts
            .file(gb_eval::fid::WEIGHTS_FILE, "--weights")
            .and_then(|p| FidExtractor::load(&p, &opts.device.device()).map_err(|e| e.to_string())),
    };
    let extractor = match extractor {
        Ok(x) => x,
        Err(reason) => {
            report.set_unavailable("fid", reason.clone());
            if depth {
                report.set_unavailable("d_fid", reason);
            } else {
                report.set_unavailable("d_fid", "the scene has no ground-truth depth");
            }
            return;
        }
    };
    let pred: Vec<RgbImage> = views.iter().map(|v| v.pred.clone()).collect();
    let gt: Vec<RgbImage> = views.iter().map(|v| v.gt.clone()).collect();
    match extractor.fid(&pred, &gt) {
        Ok(v) => report.set("fid", v),
        Err(e) => report.set_unavailable("fid", e.to_string()),
    }
    if !depth {
        report.set_unavailable("d_fid", "the scene has no ground-truth depth");
        return;
    }
    let render = |which: usize| -> Result<Vec<RgbImage>, String> {
        views
            .iter()
            .map(|v| {
                let (p, g) = v
                    .disparity
                    .as_ref()
                    .ok_or("a view has no ground-truth depth")?;
                disparity_to_rgb8(if which == 0 { p } else { g }).map_err(|e| e.to_string())
            })
            .collect()
    };
    match render(0).and_then(|p| Ok((p, render(1)?))) {
        Ok((p, g)) => match extractor.fid(&p, &g) {
            Ok(v) => report.set("d_fid", v),
            Err(e) => report.set_unavailable("d_fid", e.to_string()),
        },
        Err(e) => report.set_unavailable("d_fid", e),
    }
}

fn brisque(report: &mut EvalReport, views: &[ViewPair], opts: &MetricOptions) {
    use gb_eval::brisque::{Brisque, OPENCV_MODEL_FILE, OPENCV_RANGE_FILE};
    let model = opts
        .file(OPENCV_MODEL_FILE, "--weights")
        .and_then(|m| Ok((m, opts.file(OPENCV_RANGE_FILE, "--weights")?)))
        .and_then(|(m, r)| Brisque::load_opencv(&m, &r).map_err(|e| e.to_string()));
    let mut vals = Values::new("brisque".into());
    match model {
        Ok(model) => {
            for v in views {
                vals.push(&v.name, model.score(&v.pred).map_err(|e| e.to_string()));
            }
            vals.store(report);
        }
        Err(reason) => report.set_unavailable("brisque", reason),
    }
}

fn nima(report: &mut EvalReport, views: &[ViewPair], opts: &MetricOptions) {
    use gb_eval::nima::{nima_score, Nima, WEIGHTS_FILE};
    let model = opts
        .file(WEIGHTS_FILE, "--weights")
        .and_then(|p| Nima::load(&p, &opts.device.device()).map_err(|e| e.to_string()));
    match model {
        Ok(model) => {
            let mut vals = Values::new("nima".into());
            for v in views {
                vals.push(
                    &v.name,
                    nima_score(&model, &v.pred).map_err(|e| e.to_string()),
                );
            }
            vals.store(report);
        }
        Err(reason) => report.set_unavailable(
            "nima",
            format!("{reason} (no NIMA weights ship with the project)"),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(w: usize, h: usize, f: impl Fn(usize, usize) -> f32) -> RgbImage {
        let mut im = RgbImage::filled(w, h, [0.0; 3]);
        for y in 0..h {
            for x in 0..w {
                let v = f(x, y);
                im.set(x, y, [v, v * 0.5, 1.0 - v]);
            }
        }
        im
    }

    #[test]
    fn psnr_ssim_regions_and_unavailable_reasons() {
        let (w, h) = (32, 24);
        let gt = img(w, h, |x, y| ((x * 7 + y * 3) % 17) as f32 / 17.0);
        let mut pred = gt.clone();
        let mut mask = vec![false; w * h];
        // a triangle: its bounding box also holds correct pixels
        for y in 4..20 {
            for x in 8..24 {
                if x - 8 <= y - 4 {
                    mask[y * w + x] = true;
                    pred.set(x, y, [0.5; 3]);
                }
            }
        }
        let views = vec![ViewPair {
            name: "v".into(),
            pred,
            gt,
            mask: Some(mask),
            disparity: None,
        }];
        let opts = MetricOptions {
            weights: None,
            device: BackendKind::Ndarray,
            fid_min_images: FID_MIN_IMAGES,
        };
        let r = evaluate(&views, &opts);
        use gb_eval::report::Outcome;
        let val = |k: &str| match r.values.get(k) {
            Some(Outcome::Value(v)) => *v,
            other => panic!("{k}: {other:?}"),
        };
        // the error is only inside the mask: full > bbox > mask PSNR
        assert!(val("psnr") > val("psnr_bbox") && val("psnr_bbox") > val("psnr_mask"));
        assert!(val("ssim") > val("ssim_bbox"));
        for k in ["lpips", "lpips_bbox", "fid", "d_psnr", "nima", "brisque"] {
            assert!(
                matches!(r.values.get(k), Some(Outcome::Unavailable(_))),
                "{k}: {:?}",
                r.values.get(k)
            );
        }
        let Some(Outcome::Unavailable(why)) = r.values.get("fid") else {
            unreachable!()
        };
        assert!(why.contains("1 test view"), "{why}");
    }
}
