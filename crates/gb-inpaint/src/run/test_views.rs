//! A trained run's test views: rendered into `OUT/renders/`, scored per view
//! ([`ViewMetrics`]) and kept as [`ViewPair`]s for the full metric suite and the report.

use std::path::Path;

use gb_eval::disparity::{disparity_to_rgb8, ScalarMap};
use gb_eval::{psnr, ssim, Region};
use gb_nerf::scene::{Scene, Split};
use gb_nerf::train::data::prepare_view;
use gb_nerf::train::output::write_render_pngs;

use super::summary::ViewMetrics;
use crate::error::InpaintError;
use crate::metrics::ViewPair;
use crate::trainer::GuidedTrainer;

/// SSIM's window side: a mask box narrower or lower than this has no SSIM (`null`).
const SSIM_WINDOW: usize = 11;

/// Disparity (`1 / depth`, 0 where the depth is not a positive number) as a map.
pub fn disparity_map(depth: &[f32], width: usize, height: usize) -> ScalarMap {
    let data = depth
        .iter()
        .map(|d| {
            if d.is_finite() && *d > 0.0 {
                1.0 / d
            } else {
                0.0
            }
        })
        .collect();
    ScalarMap {
        width,
        height,
        data,
    }
}

/// Renders every test view of `scene` into `renders/`, and returns each view's metrics and
/// its render / ground-truth pair.
pub fn render_test_views(
    renders: &Path,
    scene: &Scene,
    trainer: &GuidedTrainer,
) -> Result<(Vec<ViewMetrics>, Vec<ViewPair>), InpaintError> {
    let (mut metrics, mut pairs) = (Vec::new(), Vec::new());
    for view in scene.split(Split::Test) {
        let v = prepare_view(view, trainer.config.train.image_downscale);
        let r = trainer.render(&v.camera)?;
        write_render_pngs(renders, &view.name, &r)?;
        let (w, h) = (v.image.width, v.image.height);
        let full = Region::Full;
        let (mut psnr_bbox, mut ssim_bbox) = (None, None);
        if let Some((x0, y0, x1, y1)) = v.mask.as_ref().and_then(|m| m.bbox()) {
            let reg = Region::BBox { x0, y0, x1, y1 };
            psnr_bbox = Some(psnr(&r.rgb, &v.image, &reg)?);
            if x1 - x0 >= SSIM_WINDOW && y1 - y0 >= SSIM_WINDOW {
                ssim_bbox = Some(ssim(&r.rgb, &v.image, &reg)?);
            }
        }
        let d_psnr = match &v.depth {
            Some(gt) => {
                let pred = disparity_to_rgb8(&disparity_map(&r.depth, w, h))?;
                let gt = disparity_to_rgb8(&disparity_map(gt, w, h))?;
                Some(psnr(&pred, &gt, &full)?)
            }
            None => None,
        };
        let m = ViewMetrics {
            view: view.name.clone(),
            psnr: Some(psnr(&r.rgb, &v.image, &full)?),
            ssim: Some(ssim(&r.rgb, &v.image, &full)?),
            psnr_bbox,
            ssim_bbox,
            d_psnr,
            evaluations_per_ray: r.evaluations_per_ray,
        };
        tracing::info!(view = %view.name, psnr = m.psnr, ssim = m.ssim, "test view");
        metrics.push(m);
        pairs.push(ViewPair {
            name: view.name.clone(),
            gt: v.image.clone(),
            mask: v.mask.as_ref().map(|m| m.data.clone()),
            disparity: v
                .depth
                .as_ref()
                .map(|gt| (disparity_map(&r.depth, w, h), disparity_map(gt, w, h))),
            pred: r.rgb,
        });
    }
    Ok((metrics, pairs))
}
