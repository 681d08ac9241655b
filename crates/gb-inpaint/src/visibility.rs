//! Visibility-aware guidance: the prior only acts where no training view sees the surface.
//!
//! Most of the region behind a removed object is seen by some other training view, which
//! shows it outside that view's mask; there the reconstruction loss already knows the
//! answer and a 2D prior can only pull it away (on the procedural `fence` scene the guided
//! run lost 1.2 dB to the no-prior run on such pixels, and gained 1.2 dB on the pixels that
//! no view sees; `bench/results/prior-fill-fence.json`).
//!
//! For a guided view, [`ObservedMap::compute`] renders the z-depth of its guidance crop at
//! `resolution x resolution` (no graph), lifts every masked crop pixel to its surface point
//! `o + depth * d`, and projects that point into every other training view. The pixel is
//! **observed** when, in at least one of them, the point lands inside the image, outside
//! that view's mask, and in front: the depth that view renders through that pixel is within
//! `depth_tolerance` (relative) of the point's z-depth (so a point hidden behind other
//! geometry does not count).
//!
//! The guidance then scales the gradient that reaches each rendered pixel of the prior
//! input by `observed_weight` on observed pixels and by 1 elsewhere
//! ([`gate_gradient`]: `x * w + x.detach() * (1 - w)`, whose value is `x`): the prior still
//! sees the whole crop, but only the unobserved part of the field learns from it. The map
//! is recomputed from the current field every `refresh_every` steps, since the depth it
//! relies on is learned during the run; before `start_step` (scaled to the run like
//! `normal_start_step`) there is no geometry to test and every pixel counts as observed.
//! `observed_weight = 1` (the default) turns it off and leaves a method exactly as before.
//!
//! With `condition_on_observed = true` the prior's own input follows the map too: its
//! inpainting mask is the crop's mask less the observed pixels, and its masked image shows the
//! current render (detached) on those pixels, the ground truth outside the mask. The prior then
//! completes what the other views already reconstruct instead of inpainting the whole hole
//! anew, and the score's latent mask confines the gradient to the unobserved pixels as well.
//! On the test views' guidance crops this lifts the tiny prior's own fill of the unobserved
//! pixels by about 2 dB (`tools/diag/prior_fill_vs_runs.py --condition-on none`).

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use gb_core::{f32_values, TensorValuesError};
use gb_nerf::field::NerfField;
use gb_nerf::render::rays::all_pixels;
use gb_nerf::render::render_rays;
use gb_nerf::sampler::RayBatch;
use gb_nerf::train::data::TrainView;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::crop::{CropGeometry, RenderContext};

/// Rays per no-graph render call of the visibility test.
const RAY_CHUNK: usize = 16_384;

/// The `[visibility]` table of a method (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VisibilityConfig {
    /// Scale of the guidance gradient on pixels that a training view observes (1: off, the
    /// default; 0: the prior only shapes what no view sees).
    #[serde(default = "default_weight")]
    pub observed_weight: f64,
    /// Steps between recomputations of a view's map from the current field.
    #[serde(default = "default_refresh")]
    pub refresh_every: usize,
    /// Relative depth agreement that makes a projected point visible in another view.
    #[serde(default = "default_tolerance")]
    pub depth_tolerance: f32,
    /// Side of the crop grid the test runs on (at most the prior's resolution; the map is
    /// upsampled, nearest, to it).
    #[serde(default = "default_resolution")]
    pub resolution: usize,
    /// Before this step (counted, like `normal_start_step`, out of the method's
    /// `reference_steps`) the field has no geometry to test yet, so every masked pixel counts
    /// as observed (weight `observed_weight` everywhere).
    #[serde(default)]
    pub start_step: usize,
    /// Visibility-aware conditioning (needs `observed_weight < 1`): the inpainting prior's
    /// mask is the crop's mask less its observed pixels, and its masked image shows the
    /// current render there, so the prior completes the reconstruction instead of
    /// inpainting the whole hole anew. Off by default.
    #[serde(default)]
    pub condition_on_observed: bool,
}

fn default_weight() -> f64 {
    1.0
}
fn default_refresh() -> usize {
    50
}
fn default_tolerance() -> f32 {
    0.05
}
fn default_resolution() -> usize {
    64
}

impl Default for VisibilityConfig {
    fn default() -> Self {
        Self {
            observed_weight: default_weight(),
            refresh_every: default_refresh(),
            depth_tolerance: default_tolerance(),
            resolution: default_resolution(),
            start_step: 0,
            condition_on_observed: false,
        }
    }
}

impl VisibilityConfig {
    /// True when the map changes anything (`observed_weight != 1`).
    pub fn enabled(&self) -> bool {
        self.observed_weight != 1.0
    }

    /// A message naming the first invalid field, if any.
    pub fn check(&self) -> Option<&'static str> {
        if !(self.observed_weight.is_finite() && (0.0..=1.0).contains(&self.observed_weight)) {
            return Some("visibility.observed_weight must be in [0, 1]");
        }
        if self.refresh_every == 0 {
            return Some("visibility.refresh_every must be >= 1");
        }
        if !(self.depth_tolerance.is_finite() && self.depth_tolerance > 0.0) {
            return Some("visibility.depth_tolerance must be a positive number");
        }
        if self.resolution == 0 {
            return Some("visibility.resolution must be >= 1");
        }
        if self.condition_on_observed && !self.enabled() {
            return Some("visibility.condition_on_observed needs visibility.observed_weight < 1");
        }
        None
    }
}

/// Which crop pixels of one guided view other training views observe.
#[derive(Debug, Clone, PartialEq)]
pub struct ObservedMap {
    /// Side of the grid.
    pub resolution: usize,
    /// Row-major flags: inside the crop's mask and observed by some other view.
    pub observed: Vec<bool>,
    /// Masked pixels of the grid.
    pub masked: usize,
    /// Step of the field it was computed from.
    pub step: usize,
}

impl ObservedMap {
    /// The map of training view `index` (crop `margin`, module docs) from the field of
    /// `ctx` at `step`; `None` when the view has no guidance crop. The training views of
    /// `references` have a reference image ([`crate::reference`]): their masked pixels count
    /// as observing too, and a reference view's own masked pixels are all observed. Errors
    /// when a rendered depth does not hold `f32` values (never a silently misaligned map).
    pub fn compute(
        ctx: &RenderContext<'_>,
        views: &[TrainView],
        index: usize,
        margin: f32,
        cfg: &VisibilityConfig,
        step: usize,
        references: &[usize],
    ) -> Result<Option<Self>, TensorValuesError> {
        let rv = cfg.resolution.max(1);
        let Some(geometry) = views
            .get(index)
            .and_then(|view| CropGeometry::new(view, margin, rv))
        else {
            return Ok(None);
        };
        if references.contains(&index) {
            let mut observed = vec![false; rv * rv];
            for &i in &geometry.masked {
                observed[i] = true;
            }
            return Ok(Some(Self {
                resolution: rv,
                observed,
                masked: geometry.masked.len(),
                step,
            }));
        }
        let camera = geometry.camera(rv);
        let grid = all_pixels(rv, rv);
        let pixels: Vec<[f32; 2]> = geometry.masked.iter().map(|&i| grid[i]).collect();
        let field = ctx.field.valid();
        let rays = ctx.settings.rays(&camera, &pixels);
        let depth = render_depth(&field, ctx, &rays)?;
        let points: Vec<[f32; 3]> = (0..pixels.len())
            .map(|k| {
                let (o, d) = (rays.origins[k], rays.dirs[k]);
                [0, 1, 2].map(|i| o[i] + depth[k] * d[i])
            })
            .collect();
        let hit = observed_points(
            &field,
            ctx,
            views,
            &points,
            &[index],
            references,
            cfg.depth_tolerance,
        )?;
        let mut observed = vec![false; rv * rv];
        for (&i, h) in geometry.masked.iter().zip(&hit) {
            observed[i] = *h;
        }
        Ok(Some(Self {
            resolution: rv,
            observed,
            masked: geometry.masked.len(),
            step,
        }))
    }

    /// Fraction of the masked pixels that are observed.
    pub fn observed_share(&self) -> f64 {
        let n = self.observed.iter().filter(|o| **o).count();
        n as f64 / self.masked.max(1) as f64
    }

    /// The per-pixel gradient weights `[1, 1, r, r]` on `device`: `observed_weight` on
    /// observed pixels (nearest upsampling of the grid), 1 elsewhere.
    pub fn weights(&self, r: usize, observed_weight: f64, device: &Device) -> Tensor<4> {
        let rv = self.resolution;
        let mut w = Vec::with_capacity(r * r);
        for j in 0..r {
            for i in 0..r {
                let (gi, gj) = ((i * rv / r).min(rv - 1), (j * rv / r).min(rv - 1));
                let obs = self.observed[gj * rv + gi];
                w.push(if obs { observed_weight as f32 } else { 1.0 });
            }
        }
        Tensor::from_data(TensorData::new(w, [1, 1, r, r]), device)
    }
}

/// Which of `points` a training view outside `skip` observes (module docs): the point
/// lands inside that view's image, outside its mask (a view of `masked_observes` observes
/// through its masked pixels too), and in front: the depth that `field` (a no-graph copy)
/// renders through that pixel is within `tolerance` (relative) of the point's z-depth. A
/// point that is not finite is observed by none.
pub(crate) fn observed_points(
    field: &NerfField,
    ctx: &RenderContext<'_>,
    views: &[TrainView],
    points: &[[f32; 3]],
    skip: &[usize],
    masked_observes: &[usize],
    tolerance: f32,
) -> Result<Vec<bool>, TensorValuesError> {
    // candidate (point, other view pixel) pairs: in the image, outside its mask; the depth
    // each other view renders through its candidate pixels
    let mut owner = Vec::new();
    let mut expected = Vec::new();
    let mut seen = Vec::new();
    for (j, other) in views.iter().enumerate() {
        if skip.contains(&j) {
            continue;
        }
        let cam = &other.camera;
        let mut px_list = Vec::new();
        for (k, p) in points.iter().enumerate() {
            if !p.iter().all(|c| c.is_finite()) {
                continue;
            }
            let Some(([px, py], z)) = cam.project(*p) else {
                continue;
            };
            if !(px >= 0.0 && py >= 0.0 && px < cam.width as f32 && py < cam.height as f32) {
                continue;
            }
            let (x, y) = (px as usize, py as usize);
            if !masked_observes.contains(&j)
                && other
                    .mask
                    .as_ref()
                    .is_some_and(|m| m.data.get(y * m.width + x).copied().unwrap_or(true))
            {
                continue;
            }
            px_list.push([px, py]);
            owner.push(k);
            expected.push(z);
        }
        let r = ctx.settings.rays(cam, &px_list);
        seen.extend(render_depth(field, ctx, &r)?);
    }
    let mut hit = vec![false; points.len()];
    for ((k, z), d) in owner.iter().zip(&expected).zip(&seen) {
        if (d - z).abs() <= tolerance * z.abs().max(1e-6) {
            hit[*k] = true;
        }
    }
    Ok(hit)
}

/// The z-depth that `field` (a no-graph copy) renders along `rays`, in chunks.
pub(crate) fn render_depth(
    field: &NerfField,
    ctx: &RenderContext<'_>,
    rays: &RayBatch,
) -> Result<Vec<f32>, TensorValuesError> {
    let mut out = Vec::with_capacity(rays.len());
    let n = rays.len();
    let mut start = 0;
    while start < n {
        let end = (start + RAY_CHUNK).min(n);
        let chunk = RayBatch {
            origins: rays.origins[start..end].to_vec(),
            dirs: rays.dirs[start..end].to_vec(),
            near: rays.near[start..end].to_vec(),
            far: rays.far[start..end].to_vec(),
        };
        let (o, _) = render_rays::<ChaCha8Rng>(
            field,
            ctx.settings.space,
            &chunk,
            ctx.settings.samples_per_ray,
            ctx.settings.occupancy,
            ctx.settings.background,
            None,
        )?;
        out.extend(f32_values(o.depth.into_data(), "visibility depth")?);
        start = end;
    }
    Ok(out)
}

/// `x * w + x.detach() * (1 - w)`: the value of `x`, with the gradient that reaches `x`
/// scaled per pixel by `w [1, 1, R, R]` (broadcast over channels).
pub fn gate_gradient(x: Tensor<4>, w: Tensor<4>) -> Tensor<4> {
    let c = x.dims()[1];
    let w = w.repeat_dim(1, c);
    let w = if x.is_autodiff() && !w.is_autodiff() {
        w.autodiff()
    } else {
        w
    };
    let keep = w.ones_like() - w.clone();
    x.clone() * w + x.detach() * keep
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_gate_keeps_the_value_and_scales_the_gradient_per_pixel() {
        let device = gb_core::BackendKind::Flex.autodiff_device();
        let x: Vec<f32> = (0..2 * 2 * 2).map(|k| k as f32 * 0.1 - 0.3).collect();
        let xt = Tensor::<4>::from_data(TensorData::new(x.clone(), [1, 2, 2, 2]), &device)
            .require_grad();
        let w = [0.0f32, 0.25, 1.0, 0.5];
        let wt = Tensor::<4>::from_data(
            TensorData::new(w.to_vec(), [1, 1, 2, 2]),
            &gb_core::BackendKind::Flex.device(),
        );
        let up: Vec<f32> = (0..8).map(|k| 1.0 + k as f32).collect();
        let upt = Tensor::<4>::from_data(TensorData::new(up.clone(), [1, 2, 2, 2]), &device);
        let y = gate_gradient(xt.clone(), wt);
        let yv = y.clone().into_data().try_to_vec::<f32>().unwrap();
        assert_eq!(yv, x, "the gate must not change the value");
        let grads = (y * upt).sum().backward();
        let g = xt
            .grad(&grads)
            .unwrap()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        for k in 0..8 {
            let expected = up[k] * w[k % 4];
            assert!(
                (g[k] - expected).abs() < 1e-6,
                "{k}: {} vs {expected}",
                g[k]
            );
        }
    }

    #[test]
    fn weights_upsample_the_map_and_default_config_is_off() {
        let map = ObservedMap {
            resolution: 2,
            observed: vec![true, false, false, true],
            masked: 3,
            step: 0,
        };
        assert!((map.observed_share() - 2.0 / 3.0).abs() < 1e-12);
        let w = map.weights(4, 0.2, &gb_core::BackendKind::Flex.device());
        let w = w.into_data().try_to_vec::<f32>().unwrap();
        let expected = [
            0.2, 0.2, 1.0, 1.0, 0.2, 0.2, 1.0, 1.0, 1.0, 1.0, 0.2, 0.2, 1.0, 1.0, 0.2, 0.2,
        ];
        assert_eq!(w, expected);
        let off = VisibilityConfig::default();
        assert!(!off.enabled() && off.check().is_none());
        let bad = VisibilityConfig {
            observed_weight: 1.5,
            ..off.clone()
        };
        assert!(bad.check().unwrap().contains("observed_weight"));
        let bad = VisibilityConfig {
            refresh_every: 0,
            ..off.clone()
        };
        assert!(bad.check().unwrap().contains("refresh_every"));
        let bad = VisibilityConfig {
            condition_on_observed: true,
            ..off
        };
        assert!(bad.check().unwrap().contains("condition_on_observed"));
    }
}
