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
//!   weights folder holds them, over the whole render and (`brisque_bbox`, `nima_bbox`) over
//!   the crop of the mask's bounding box, which holds the filled region.
//!
//! A scene without ground truth (a real capture such as SPIn-NeRF's `statue` without its
//! test views) is scored by [`evaluate_without_reference`]: the no-reference metrics of the
//! renders of its masked training views, where the object was removed; every full-reference
//! metric is unavailable, with that reason.
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

/// A render scored without a reference: a masked training view of a scene that has no test
/// view with ground truth.
#[derive(Debug, Clone)]
pub struct RenderOnly {
    /// View name (file stem).
    pub name: String,
    /// The render.
    pub pred: RgbImage,
    /// The object mask (row-major, the render's size), whose bounding box is the `_bbox` crop.
    pub mask: Option<Vec<bool>>,
}

/// The input of the no-reference metrics: name, render, mask.
type Scored<'a> = (&'a str, &'a RgbImage, Option<&'a [bool]>);

/// Smallest side of a mask-box crop scored by BRISQUE / NIMA: below it the local statistics
/// (7x7 windows at two scales) describe the crop's border more than its content.
pub const NO_REFERENCE_MIN_CROP: usize = 32;

/// The crop of `img` to its mask's bounding box, or why there is none.
fn bbox_crop(img: &RgbImage, mask: Option<&[bool]>) -> Result<RgbImage, String> {
    let mask = mask.ok_or("no mask")?;
    let Some(Region::BBox { x0, y0, x1, y1 }) = Region::bbox_of_mask(mask, img.width) else {
        return Err(MetricError::EmptyMask.to_string());
    };
    let (w, h) = (x1 - x0, y1 - y0);
    if w < NO_REFERENCE_MIN_CROP || h < NO_REFERENCE_MIN_CROP {
        return Err(format!(
            "the mask box is {w}x{h}, under the {NO_REFERENCE_MIN_CROP}-pixel minimum"
        ));
    }
    let mut out = RgbImage::filled(w, h, [0.0; 3]);
    for y in 0..h {
        for x in 0..w {
            out.set(x, y, img.get(x0 + x, y0 + y));
        }
    }
    Ok(out)
}

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
        Self {
            weights: weights.or_else(gb_eval::default_weights_dir),
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

/// An empty report of the named views, with the device and weights folder as context.
fn new_report(names: Vec<String>, opts: &MetricOptions) -> EvalReport {
    let mut report = EvalReport::new(&names);
    report
        .context
        .insert("device".into(), opts.device.name().to_string());
    if let Some(w) = &opts.weights {
        report
            .context
            .insert("weights".into(), w.display().to_string());
    }
    report
}

/// Marks every full-reference metric unavailable: the scene has no ground truth.
fn set_no_ground_truth(report: &mut EvalReport) {
    for key in ["psnr", "ssim", "lpips", "d_psnr", "fid", "d_fid"] {
        report.set_unavailable(key, "the scene has no test view with ground truth");
    }
}

/// Evaluates the views (see the module docs). Never fails: every problem becomes an
/// unavailable metric with its reason.
pub fn evaluate(views: &[ViewPair], opts: &MetricOptions) -> EvalReport {
    let mut report = new_report(views.iter().map(|v| v.name.clone()).collect(), opts);
    if views.is_empty() {
        set_no_ground_truth(&mut report);
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
    let scored: Vec<Scored> = views
        .iter()
        .map(|v| (v.name.as_str(), &v.pred, v.mask.as_deref()))
        .collect();
    no_reference(&mut report, &scored, opts);
    report
}

/// Evaluates renders without ground truth (see the module docs): `brisque` / `nima` over the
/// whole render and `_bbox` over the mask box; the full-reference metrics are unavailable.
/// Never fails, like [`evaluate`].
pub fn evaluate_without_reference(views: &[RenderOnly], opts: &MetricOptions) -> EvalReport {
    let mut report = new_report(views.iter().map(|v| v.name.clone()).collect(), opts);
    report.context.insert(
        "views".into(),
        "masked training views (the scene has no test view with ground truth)".into(),
    );
    set_no_ground_truth(&mut report);
    let scored: Vec<Scored> = views
        .iter()
        .map(|v| (v.name.as_str(), &v.pred, v.mask.as_deref()))
        .collect();
    if scored.is_empty() {
        for key in ["brisque", "brisque_bbox", "nima", "nima_bbox"] {
            report.set_unavailable(key, "no render to score");
        }
    } else {
        no_reference(&mut report, &scored, opts);
    }
    report
}

/// BRISQUE and NIMA of the renders, whole and in the mask box.
fn no_reference(report: &mut EvalReport, views: &[Scored], opts: &MetricOptions) {
    brisque(report, views, opts);
    nima(report, views, opts);
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

/// Scores every render (`key`) and its mask-box crop (`key_bbox`, when a view has a mask).
fn score_renders(
    report: &mut EvalReport,
    views: &[Scored],
    key: &str,
    score: impl Fn(&RgbImage) -> Result<f64, String>,
) {
    let mut full = Values::new(key.into());
    let mut bbox = Values::new(format!("{key}_bbox"));
    for (name, pred, mask) in views {
        full.push(name, score(pred));
        // every view, so that the values stay aligned with the views: one without a mask
        // makes the key unavailable, naming it
        bbox.push(name, bbox_crop(pred, *mask).and_then(|c| score(&c)));
    }
    full.store(report);
    if views.iter().any(|(_, _, m)| m.is_some()) {
        bbox.store(report);
    }
}

fn brisque(report: &mut EvalReport, views: &[Scored], opts: &MetricOptions) {
    use gb_eval::brisque::{Brisque, OPENCV_MODEL_FILE, OPENCV_RANGE_FILE};
    let model = opts
        .file(OPENCV_MODEL_FILE, "--weights")
        .and_then(|m| Ok((m, opts.file(OPENCV_RANGE_FILE, "--weights")?)))
        .and_then(|(m, r)| Brisque::load_opencv(&m, &r).map_err(|e| e.to_string()));
    match model {
        Ok(model) => score_renders(report, views, "brisque", |img| {
            model.score(img).map_err(|e| e.to_string())
        }),
        Err(reason) => {
            report.set_unavailable("brisque", reason.clone());
            report.set_unavailable("brisque_bbox", reason);
        }
    }
}

fn nima(report: &mut EvalReport, views: &[Scored], opts: &MetricOptions) {
    use gb_eval::nima::{nima_score, Nima, WEIGHTS_FILE};
    let model = opts
        .file(WEIGHTS_FILE, "--weights")
        .and_then(|p| Nima::load(&p, &opts.device.device()).map_err(|e| e.to_string()));
    match model {
        Ok(model) => score_renders(report, views, "nima", |img| {
            nima_score(&model, img).map_err(|e| e.to_string())
        }),
        Err(reason) => {
            let why = format!("{reason} (no NIMA weights ship with the project)");
            report.set_unavailable("nima", why.clone());
            report.set_unavailable("nima_bbox", why);
        }
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

    // fails when the shared data appeared after this crate was built without it
    gb_core::shared_data_guard!();

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

    /// Box blur of radius `r` inside `[x0, x1) x [y0, y1)`, repeated `times`.
    fn blur_box(
        img: &RgbImage,
        (x0, y0, x1, y1): (usize, usize, usize, usize),
        r: usize,
        times: usize,
    ) -> RgbImage {
        let mut out = img.clone();
        for _ in 0..times {
            let src = out.clone();
            for y in y0..y1 {
                for x in x0..x1 {
                    let mut acc = [0.0f32; 3];
                    let mut n = 0.0;
                    for yy in y.saturating_sub(r)..(y + r + 1).min(img.height) {
                        for xx in x.saturating_sub(r)..(x + r + 1).min(img.width) {
                            let p = src.get(xx, yy);
                            (0..3).for_each(|c| acc[c] += p[c]);
                            n += 1.0;
                        }
                    }
                    out.set(x, y, acc.map(|v| v / n));
                }
            }
        }
        out
    }

    #[test]
    #[cfg_attr(
        gb_no_shared_data,
        ignore = "needs the shared test data (../shared or GB_TEST_DATA): weights/ and data/rgb_normal_sample"
    )]
    fn renders_without_reference_get_brisque_whole_and_in_the_mask_box() {
        let data = gb_core::test_data_dir();
        let weights = data.join("weights");
        let photo = data.join("data/rgb_normal_sample/000000_img.png");
        let photo = gb_core::read_rgb(&photo, None).unwrap();
        let (w, h) = (photo.width, photo.height);
        let (x0, y0, x1, y1) = (w / 3, h / 3, w / 3 + 160, h / 3 + 120);
        let mut mask = vec![false; w * h];
        for y in y0..y1 {
            for x in x0..x1 {
                mask[y * w + x] = true;
            }
        }
        // the "filled" box of a render: the photo, blurred inside the mask box as a weak
        // fill is
        let pred = blur_box(&photo, (x0, y0, x1, y1), 3, 3);
        let mut tiny = vec![false; w * h];
        tiny[10 * w + 10] = true;
        let opts = MetricOptions {
            weights: Some(weights.clone()),
            device: BackendKind::Flex,
            fid_min_images: FID_MIN_IMAGES,
        };
        let view = |name: &str, mask: Vec<bool>| RenderOnly {
            name: name.into(),
            pred: pred.clone(),
            mask: Some(mask),
        };
        let r = evaluate_without_reference(&[view("a", mask.clone())], &opts);
        use gb_eval::brisque::{Brisque, OPENCV_MODEL_FILE, OPENCV_RANGE_FILE};
        let model = Brisque::load_opencv(
            &weights.join(OPENCV_MODEL_FILE),
            &weights.join(OPENCV_RANGE_FILE),
        )
        .unwrap();
        let crop = bbox_crop(&pred, Some(&mask)).unwrap();
        assert_eq!((crop.width, crop.height), (160, 120));
        assert_eq!(crop.get(0, 0), pred.get(x0, y0));
        assert_eq!(crop.get(159, 119), pred.get(x1 - 1, y1 - 1));
        let val = |r: &EvalReport, k: &str| match r.values.get(k) {
            Some(gb_eval::report::Outcome::Value(v)) => *v,
            other => panic!("{k}: {other:?}"),
        };
        assert_eq!(val(&r, "brisque"), model.score(&pred).unwrap());
        assert_eq!(val(&r, "brisque_bbox"), model.score(&crop).unwrap());
        // the blurred fill scores worse (higher) in the box than the photo's own crop
        let sharp = model
            .score(&bbox_crop(&photo, Some(&mask)).unwrap())
            .unwrap();
        assert!(
            val(&r, "brisque_bbox") > sharp + 10.0,
            "{} vs {sharp}",
            val(&r, "brisque_bbox")
        );
        for k in ["psnr", "ssim", "lpips", "d_psnr", "fid"] {
            match r.values.get(k) {
                Some(gb_eval::report::Outcome::Unavailable(why)) => {
                    assert!(why.contains("no test view with ground truth"), "{k}: {why}")
                }
                other => panic!("{k}: {other:?}"),
            }
        }
        // a 1-pixel mask box is too small to score, and says so with the view's name
        let r = evaluate_without_reference(&[view("a", mask), view("b", tiny)], &opts);
        assert!(matches!(
            r.values.get("brisque"),
            Some(gb_eval::report::Outcome::Value(_))
        ));
        match r.values.get("brisque_bbox") {
            Some(gb_eval::report::Outcome::Unavailable(why)) => {
                assert!(why.starts_with("b: the mask box is 1x1"), "{why}")
            }
            other => panic!("{other:?}"),
        }
        let none = evaluate_without_reference(&[], &opts);
        assert!(matches!(
            none.values.get("brisque"),
            Some(gb_eval::report::Outcome::Unavailable(_))
        ));
    }
}
