//! A trained run's test views: rendered into `OUT/renders/` and kept as
//! [`EvalPair`]s for gb-eval's metric suite and the report; each view's
//! [`ViewMetrics`] are read back from the suite's per-image values.

use std::path::Path;

use gb_eval::report::EvalReport;
use gb_eval::suite::EvalPair;
use gb_nerf::scene::{Scene, Split};
use gb_nerf::train::data::prepare_view;
use gb_nerf::train::output::write_render_pngs;

use super::summary::ViewMetrics;
use crate::error::InpaintError;
use crate::trainer::GuidedTrainer;

pub use gb_eval::disparity::disparity_map;

/// The rendered test views: each view's render / ground-truth pair and its mean field
/// evaluations per ray.
pub struct TestViews {
    /// The pairs, in the scene's test order.
    pub pairs: Vec<EvalPair>,
    /// Field evaluations per ray of each render.
    pub evaluations_per_ray: Vec<f32>,
    /// Each view's render (colour, depth, normals), for `--probe`.
    pub renders: Vec<gb_nerf::render::ImageRender>,
}

impl TestViews {
    /// Each view's metrics, from the suite's per-image values of `eval` (the report of
    /// these pairs).
    pub fn metrics(&self, eval: &EvalReport) -> Vec<ViewMetrics> {
        let views = self.pairs.iter().zip(&self.evaluations_per_ray);
        views
            .zip(&eval.per_image)
            .map(|((pair, &evaluations_per_ray), (_, values))| {
                let get = |k: &str| values.get(k).copied();
                let m = ViewMetrics {
                    view: pair.name.clone(),
                    psnr: get("psnr"),
                    ssim: get("ssim"),
                    psnr_bbox: get("psnr_bbox"),
                    ssim_bbox: get("ssim_bbox"),
                    d_psnr: get("d_psnr"),
                    evaluations_per_ray,
                };
                tracing::info!(view = %m.view, psnr = m.psnr, ssim = m.ssim, "test view");
                m
            })
            .collect()
    }
}

/// Renders every test view of `scene` into `renders/`.
pub fn render_test_views(
    renders: &Path,
    scene: &Scene,
    trainer: &GuidedTrainer,
) -> Result<TestViews, InpaintError> {
    let (mut pairs, mut evaluations_per_ray, mut rendered) = (Vec::new(), Vec::new(), Vec::new());
    for view in scene.split(Split::Test) {
        let v = prepare_view(view, trainer.config.train.image_downscale);
        let r = trainer.render(&v.camera)?;
        write_render_pngs(renders, &view.name, &r)?;
        let (w, h) = (v.image.width, v.image.height);
        evaluations_per_ray.push(r.evaluations_per_ray);
        pairs.push(EvalPair {
            name: view.name.clone(),
            gt: Some(v.image),
            mask: v.mask.map(|m| m.data),
            disparity: v
                .depth
                .as_ref()
                .map(|gt| (disparity_map(&r.depth, w, h), disparity_map(gt, w, h))),
            pred: r.rgb.clone(),
        });
        rendered.push(r);
    }
    Ok(TestViews {
        pairs,
        evaluations_per_ray,
        renders: rendered,
    })
}
