//! How a trial is scored ([`super`] step 3): the withheld pixels' boxes of every training
//! view a pseudo-hole shows in, rendered and compared with the truth the training images
//! hold (mask-box SSIM, ST-LPIPS, D-PSNR), each candidate ranked per metric, the lowest rank
//! sum winning.

use gb_core::RgbImage;
use gb_eval::disparity::disparity_map;
use gb_eval::report::Outcome;
use gb_eval::suite::{evaluate, EvalPair, PairSet, Selection, SuiteOptions};
use gb_nerf::render::rays::crop_camera;
use gb_nerf::scene::{Mask, Scene, Split};
use gb_nerf::train::data::{downscale_mask, prepare_view};

use super::{AutoInputs, HoleScores, Trial};
use crate::error::InpaintError;
use crate::trainer::GuidedTrainer;

/// The metrics a trial is scored on, and whether higher is better.
pub(super) const METRICS: [(&str, bool); 3] = [
    ("ssim_bbox", true),
    ("lpips_bbox", false),
    ("d_psnr_bbox", true),
];

/// The [`METRICS`] means over every pseudo-hole together, and on each alone.
pub(super) type TrialScores = ([Option<f64>; 3], Vec<HoleScores>);

/// One training view's withheld pixels as a trial scores them: the box of the pixels at
/// the training resolution, with its camera, truth and mask, cut once for every trial.
pub(super) struct ScoreTarget {
    pub(super) name: String,
    /// The camera of the box alone (only the box is rendered: the metrics cover nothing else).
    pub(super) camera: gb_nerf::scene::Camera,
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) gt: RgbImage,
    pub(super) mask: Vec<bool>,
    /// The truth's disparity over the box, where the scene has depth maps.
    pub(super) disparity: Option<gb_eval::disparity::ScalarMap>,
}

/// The smallest box side a trial scores, in pixels: ST-LPIPS needs 21, and a pseudo-hole seen
/// edge-on in one view can be narrower; a box that small grows about its centre, inside the
/// image (its mask is still the withheld pixels).
pub const MIN_SCORE_SIDE: usize = 32;

/// `(x0, y0, x1, y1)` grown to at least `min` pixels a side (or the whole image's side),
/// about its centre, inside a `width` x `height` image.
fn grow_box(
    (x0, y0, x1, y1): (usize, usize, usize, usize),
    min: usize,
    width: usize,
    height: usize,
) -> (usize, usize, usize, usize) {
    let grow = |a: usize, b: usize, n: usize| {
        let side = min.min(n);
        if b - a >= side {
            return (a, b);
        }
        let lo = ((a + b) / 2).saturating_sub(side / 2).min(n - side);
        (lo, lo + side)
    };
    let (x0, x1) = grow(x0, x1, width);
    let (y0, y1) = grow(y0, y1, height);
    (x0, y0, x1, y1)
}

/// The [`ScoreTarget`]s of the training views that `holes` (per training view, full
/// resolution) shows in, at downscale `f`.
pub(super) fn score_targets(scene: &Scene, holes: &[Option<Mask>], f: usize) -> Vec<ScoreTarget> {
    let mut targets = Vec::new();
    for (view, hole) in scene.split(Split::Train).zip(holes) {
        let Some(hole) = hole else { continue };
        let mask = downscale_mask(hole, f);
        let Some(bbox) = mask.bbox() else { continue };
        let v = prepare_view(view, f);
        let bbox = grow_box(bbox, MIN_SCORE_SIDE, v.image.width, v.image.height);
        let (x0, y0, x1, y1) = bbox;
        let (w, h) = (x1 - x0, y1 - y0);
        let pixels: Vec<usize> = (y0..y1)
            .flat_map(|y| (x0..x1).map(move |x| y * v.image.width + x))
            .collect();
        targets.push(ScoreTarget {
            name: view.name.clone(),
            camera: crop_camera(&v.camera, bbox, w, h),
            width: w,
            height: h,
            gt: RgbImage {
                width: w,
                height: h,
                data: pixels
                    .iter()
                    .flat_map(|p| v.image.data[p * 3..p * 3 + 3].iter().copied())
                    .collect(),
            },
            mask: pixels.iter().map(|p| mask.data[*p]).collect(),
            disparity: v.depth.as_ref().map(|d| {
                let truth: Vec<f32> = pixels.iter().map(|p| d[*p]).collect();
                disparity_map(&truth, w, h)
            }),
        });
    }
    targets
}

/// The keys the [`METRICS`] are read from in the report of the rendered boxes: the values
/// over the whole of each render, which is the withheld pixels' box itself (grown to
/// [`MIN_SCORE_SIDE`]). The report's `_bbox` values would crop again to the withheld pixels'
/// own box, narrower than ST-LPIPS's 21 pixels where a pseudo-hole is seen edge-on (stairs
/// seed 100, view_021: 20x43), which left ST-LPIPS out of the pooled score of every trial.
const BOX_KEYS: [&str; 3] = ["ssim", "lpips", "d_psnr"];

/// The [`METRICS`] of `t`'s renders of the withheld pixels' boxes: over every pseudo-hole's
/// boxes together, and over each hole's alone (the means of its boxes' per-image values, from
/// the same evaluation).
pub(super) fn score(
    i: &AutoInputs,
    t: &GuidedTrainer,
    scored: &[Vec<ScoreTarget>],
) -> Result<TrialScores, InpaintError> {
    let mut all = Vec::new();
    let mut hole_of = Vec::new();
    for (h, hole) in scored.iter().enumerate() {
        let pairs = render_pairs(t, hole)?;
        hole_of.extend(std::iter::repeat_n(h, pairs.len()));
        all.extend(pairs);
    }
    score_pairs(
        &all,
        &hole_of,
        scored.len(),
        SuiteOptions::new(i.weights.clone(), &i.devices),
    )
}

/// The [`METRICS`] of rendered boxes `pairs` (each pair's image is its box), pooled and per
/// hole (`hole_of[j]` owns pair `j`, of `holes`), with the suite's `opts` (its metrics are
/// set here).
fn score_pairs(
    pairs: &[EvalPair],
    hole_of: &[usize],
    holes: usize,
    opts: SuiteOptions,
) -> Result<TrialScores, InpaintError> {
    let opts = SuiteOptions {
        metrics: Selection::Only(BOX_KEYS.iter().map(|k| k.to_string()).collect()),
        ..opts
    };
    let report = evaluate(&PairSet::new(pairs), &opts)?;
    let pooled = BOX_KEYS.map(|k| match report.values.get(k) {
        Some(Outcome::Value(v)) if v.is_finite() => Some(*v),
        other => {
            tracing::debug!(metric = k, ?other, "auto weights: metric not ranked");
            None
        }
    });
    let hole_mean = |h: usize, k: &str| {
        let values: Vec<f64> = report
            .per_image
            .iter()
            .zip(hole_of)
            .filter(|(_, owner)| **owner == h)
            .filter_map(|((_, m), _)| m.get(k).copied().filter(|v| v.is_finite()))
            .collect();
        (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64)
    };
    let per_hole = (0..holes)
        .map(|h| {
            let m = BOX_KEYS.map(|k| hole_mean(h, k));
            HoleScores {
                ssim_bbox: m[0],
                lpips_bbox: m[1],
                d_psnr_bbox: m[2],
            }
        })
        .collect();
    Ok((pooled, per_hole))
}

/// `t`'s render of each target's box, paired with its truth.
fn render_pairs(t: &GuidedTrainer, targets: &[ScoreTarget]) -> Result<Vec<EvalPair>, InpaintError> {
    let mut pairs = Vec::new();
    for target in targets {
        let r = t.render(&target.camera)?;
        pairs.push(EvalPair {
            name: target.name.clone(),
            gt: Some(target.gt.clone()),
            mask: Some(target.mask.clone()),
            disparity: target
                .disparity
                .clone()
                .map(|truth| (disparity_map(&r.depth, target.width, target.height), truth)),
            pred: r.rgb,
        });
    }
    Ok(pairs)
}

/// Ranks the trials per metric that every trial has (1 best, ties sharing the mean rank),
/// fills their rank sums and returns the metrics used.
pub(super) fn rank(trials: &mut [Trial]) -> Vec<String> {
    let get = |t: &Trial, k: usize| [t.ssim_bbox, t.lpips_bbox, t.d_psnr_bbox][k];
    let mut used = Vec::new();
    for (k, (name, higher)) in METRICS.iter().enumerate() {
        let values: Option<Vec<f64>> = trials.iter().map(|t| get(t, k)).collect();
        let Some(values) = values else { continue };
        used.push(name.to_string());
        for (j, t) in trials.iter_mut().enumerate() {
            let better = |o: f64| {
                if *higher {
                    o > values[j]
                } else {
                    o < values[j]
                }
            };
            let ahead = values.iter().filter(|o| better(**o)).count() as f64;
            let equal = values.iter().filter(|o| **o == values[j]).count() as f64;
            t.rank_sum += ahead + (equal + 1.0) / 2.0;
        }
    }
    used
}

/// The trial with the lowest rank sum; a tie goes to the smaller total weight.
pub(super) fn best_trial(trials: &[Trial]) -> usize {
    let mut best = 0;
    for (j, t) in trials.iter().enumerate().skip(1) {
        let b = &trials[best];
        let total = |t: &Trial| t.lambda_rgb + t.lambda_normal;
        if t.rank_sum < b.rank_sum || (t.rank_sum == b.rank_sum && total(t) < total(b)) {
            best = j;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Found on `stairs` seed 100: a pseudo-hole 20 pixels wide in one view left ST-LPIPS
    /// out of every trial's ranking.
    #[test]
    fn small_score_boxes_grow_to_the_metrics_minimum_inside_the_image() {
        assert_eq!(grow_box((10, 5, 30, 48), 32, 100, 75), (4, 5, 36, 48));
        // at an edge the box shifts inside
        assert_eq!(grow_box((0, 70, 5, 75), 32, 100, 75), (0, 43, 32, 75));
        // an image smaller than the minimum: its whole side
        assert_eq!(grow_box((3, 3, 5, 5), 32, 20, 10), (0, 0, 20, 10));
        // a large box is kept
        assert_eq!(grow_box((1, 2, 60, 50), 32, 100, 75), (1, 2, 60, 50));
    }

    fn trial(r: f64, n: f64, s: [Option<f64>; 3]) -> Trial {
        Trial {
            lambda_rgb: r,
            lambda_normal: n,
            ssim_bbox: s[0],
            lpips_bbox: s[1],
            d_psnr_bbox: s[2],
            per_hole: Vec::new(),
            rank_sum: 0.0,
            seconds: 0.0,
        }
    }

    #[test]
    fn the_lowest_rank_sum_wins_and_a_tie_goes_to_less_guidance() {
        let mut t = vec![
            trial(0.0, 0.0, [Some(0.5), Some(0.3), Some(20.0)]),
            trial(1e-5, 0.0, [Some(0.6), Some(0.2), Some(19.0)]),
            trial(1e-5, 1e-5, [Some(0.4), Some(0.4), Some(21.0)]),
        ];
        assert_eq!(rank(&mut t), vec!["ssim_bbox", "lpips_bbox", "d_psnr_bbox"]);
        assert_eq!(
            t.iter().map(|t| t.rank_sum).collect::<Vec<_>>(),
            vec![6.0, 5.0, 7.0]
        );
        assert_eq!(best_trial(&t), 1);
        // equal scores: shared ranks, and the smaller weight wins
        let mut tie = vec![
            trial(1e-5, 0.0, [Some(0.5), Some(0.3), None]),
            trial(0.0, 0.0, [Some(0.5), Some(0.3), None]),
        ];
        assert_eq!(rank(&mut tie), vec!["ssim_bbox", "lpips_bbox"]);
        assert_eq!(tie[0].rank_sum, 3.0);
        assert_eq!(best_trial(&tie), 1);
    }

    /// A pseudo-hole seen edge-on: its withheld pixels 20 pixels wide, the render grown to
    /// 32. Every pair gets a pooled ST-LPIPS, which the withheld pixels' own box would not.
    #[test]
    #[cfg_attr(
        gb_no_shared_data,
        ignore = "needs the shared test data (../shared or GB_TEST_DATA): weights/ (ST-LPIPS)"
    )]
    fn an_edge_on_hole_is_scored_on_its_grown_box_with_st_lpips() {
        let (w, h) = (32, 43);
        let gt = RgbImage {
            width: w,
            height: h,
            data: (0..w * h * 3)
                .map(|i| ((i * 37) % 251) as f32 / 255.0)
                .collect(),
        };
        let mut pred = gt.clone();
        for v in pred.data.iter_mut().step_by(5) {
            *v = 1.0 - *v;
        }
        let mask: Vec<bool> = (0..w * h).map(|p| (6..26).contains(&(p % w))).collect();
        let pair = |name: &str, pred: &RgbImage| EvalPair {
            name: name.into(),
            pred: pred.clone(),
            gt: Some(gt.clone()),
            mask: Some(mask.clone()),
            disparity: None,
        };
        let pairs = [pair("edge-on", &pred), pair("exact", &gt)];
        let weights = gb_core::test_data_dir().join("weights");
        let opts = SuiteOptions::new(Some(weights.clone()), gb_core::BackendKind::Flex);
        let (pooled, per_hole) = score_pairs(&pairs, &[0, 1], 2, opts).unwrap();
        let lpips = pooled[1].expect("ST-LPIPS over the grown boxes");
        assert!(lpips > 0.01, "{lpips}");
        assert!(per_hole[1].lpips_bbox.unwrap().abs() < 1e-6, "{per_hole:?}");
        assert!((per_hole[0].lpips_bbox.unwrap() - 2.0 * lpips).abs() < 1e-9);
        assert!(
            (per_hole[1].ssim_bbox.unwrap() - 1.0).abs() < 1e-6,
            "{per_hole:?}"
        );
        assert!(per_hole[0].ssim_bbox.unwrap() < 0.9, "{per_hole:?}");
        // the suite's own mask box is 20 pixels wide: too narrow for ST-LPIPS
        let opts = SuiteOptions {
            metrics: Selection::Only(vec!["lpips".into()]),
            ..SuiteOptions::new(Some(weights), gb_core::BackendKind::Flex)
        };
        let report = evaluate(&PairSet::new(&pairs), &opts).unwrap();
        assert!(!matches!(
            report.values.get("lpips_bbox"),
            Some(Outcome::Value(_))
        ));
    }
}
