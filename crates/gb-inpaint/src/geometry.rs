//! Geometry that survives the fill (issue 49): the hidden region's depth comes from the
//! reconstruction, its colour from the fill.
//!
//! Without any supervision of the hidden region (`--method none`), the field's depth behind
//! the object is interpolated by the hash grid and pinned by the views that see the surface;
//! every colour term inside the mask (a reference view, the RGB guidance, the normal
//! guidance) moves that geometry, even when the colour it asks for is exact. With
//! `[geometry] depth_weight > 0`, a run first trains the same field without any hidden-region
//! term (exactly the `none` run of its preset and seed: same initialisation, same rays) and
//! keeps its depth through the masked pixels of every training view (at most
//! `max_pixels_per_view` a view, on a stride grid), or with `region = "crop"` through every
//! pixel of the guided crop (the mask's box grown by the method's `crop_margin`), so that
//! the observed surroundings the guidance renders keep their depth as well. Then, on every step of the run, `rays`
//! rays drawn from those pixels carry the disparity loss of the reconstruction toward that
//! depth (weight `depth_weight`), and the distortion loss of mip-NeRF 360 (weight
//! `distortion_weight`) keeps their weights on one surface. The unguided field is computed
//! again on resume (it is deterministic), so checkpoints do not hold it.

use burn::tensor::Tensor;
use gb_core::TensorValuesError;
use gb_nerf::render::render_samples;
use gb_nerf::sampler::RayBatch;
use gb_nerf::train::data::TrainView;
use gb_nerf::train::losses::distortion_of;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::crop::{disparity_pair, disparity_toward, RenderContext};
use crate::error::InpaintError;
pub use crate::method::{GeometryConfig, GeometryRegion};

/// One masked training pixel and the unguided field's depth through it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HiddenPixel {
    /// Training view index.
    pub view: usize,
    /// Pixel centre.
    pub pixel: [f32; 2],
    /// The unguided field's z-depth (non-positive or non-finite: none).
    pub depth: f32,
}

/// The pixels of the training views kept for the geometry term: every `stride`-th pixel of
/// each masked view's region, at most `max` a view. The region is the mask, or with
/// `crop_margin = Some(m)` the mask's bounding box grown by `m` ([`GeometryRegion::Crop`]).
pub fn hidden_pixels(
    views: &[TrainView],
    max: usize,
    crop_margin: Option<f32>,
) -> Vec<(usize, Vec<[f32; 2]>)> {
    let mut out = Vec::new();
    for (k, v) in views.iter().enumerate() {
        let Some(mask) = &v.mask else { continue };
        let masked: Vec<usize> = match crop_margin {
            None => (0..mask.data.len()).filter(|&i| mask.data[i]).collect(),
            Some(m) => match crate::crop::grown_bbox(mask, m) {
                Some((x0, y0, x1, y1)) => (y0..y1)
                    .flat_map(|y| (x0..x1).map(move |x| y * mask.width + x))
                    .collect(),
                None => Vec::new(),
            },
        };
        if masked.is_empty() {
            continue;
        }
        let stride = masked.len().div_ceil(max.max(1));
        let w = mask.width;
        let pixels = masked
            .iter()
            .step_by(stride)
            .map(|&i| [(i % w) as f32 + 0.5, (i / w) as f32 + 0.5])
            .collect();
        out.push((k, pixels));
    }
    out
}

/// The geometry term's targets: the unguided field's depth through the hidden pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct HiddenDepth {
    /// The settings.
    pub config: GeometryConfig,
    /// The pixels and their depths.
    pub pixels: Vec<HiddenPixel>,
}

impl HiddenDepth {
    /// Renders the depth of `field` (an unguided trainer) through the pixels of
    /// `config.region`; `crop_margin` is the method's (for [`GeometryRegion::Crop`]).
    pub fn from_field(
        unguided: &gb_nerf::train::Trainer,
        config: GeometryConfig,
        crop_margin: f32,
    ) -> Result<Self, InpaintError> {
        let mut pixels = Vec::new();
        let margin = (config.region == GeometryRegion::Crop).then_some(crop_margin);
        let views = &unguided.data.views;
        for (view, px) in hidden_pixels(views, config.max_pixels_per_view, margin) {
            let profiles = unguided.ray_profiles(&unguided.data.views[view].camera, &px)?;
            pixels.extend(profiles.iter().map(|p| HiddenPixel {
                view,
                pixel: p.pixel,
                depth: p.depth,
            }));
        }
        Ok(Self { config, pixels })
    }

    /// The term of one step (module docs), drawn from a stream seeded by `seed`; `None`
    /// without pixels. Errors when early ray termination cannot read the field's densities.
    pub fn loss(
        &self,
        ctx: &RenderContext<'_>,
        views: &[TrainView],
        seed: u64,
    ) -> Result<Option<Tensor<1>>, TensorValuesError> {
        if self.pixels.is_empty() || !self.config.enabled() {
            return Ok(None);
        }
        let n = self.config.rays;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut rays = RayBatch::default();
        let mut target = Vec::with_capacity(2 * n);
        for _ in 0..n {
            let p = self.pixels[rng.random_range(0..self.pixels.len())];
            target.extend(disparity_pair(ctx.settings.near, p.depth));
            let Some(view) = views.get(p.view) else {
                return Ok(None);
            };
            rays.append(ctx.ray_through(&view.camera, p.pixel));
        }
        let samples = ctx.settings.samples(ctx.field, &rays, Some(&mut rng))?;
        let out = render_samples(ctx.field, &samples, ctx.settings.background);
        let mut loss = Tensor::<1>::zeros([1], &ctx.field.device());
        if self.config.depth_weight > 0.0 {
            let d = disparity_toward(out.disparity, target, ctx.settings.near);
            loss = loss + d.mul_scalar(self.config.depth_weight);
        }
        if self.config.distortion_weight > 0.0 {
            let dl = distortion_of(out.weights, &rays, &samples, ctx.settings.space.spacing());
            loss = loss + dl.mul_scalar(self.config.distortion_weight);
        }
        Ok(Some(loss))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gb_core::RgbImage;
    use gb_nerf::scene::{Camera, Mask};

    fn view(mask: Option<Vec<bool>>) -> TrainView {
        TrainView {
            camera: Camera {
                width: 4,
                height: 2,
                fx: 4.0,
                fy: 4.0,
                cx: 2.0,
                cy: 1.0,
                c2w: [
                    [1.0, 0.0, 0.0, 0.0],
                    [0.0, 1.0, 0.0, 0.0],
                    [0.0, 0.0, 1.0, 0.0],
                ],
            },
            image: RgbImage::filled(4, 2, [0.5; 3]),
            mask: mask.map(|data| Mask {
                width: 4,
                height: 2,
                data,
            }),
            depth: None,
        }
    }

    #[test]
    fn hidden_pixels_keep_a_stride_grid_of_each_masked_view() {
        let all = vec![true; 8];
        let mut one = vec![false; 8];
        one[6] = true;
        let views = [
            view(Some(all)),
            view(None),
            view(Some(vec![false; 8])),
            view(Some(one)),
        ];
        let got = hidden_pixels(&views, 3, None);
        assert_eq!(got.len(), 2);
        // 8 masked pixels, at most 3: stride 3, pixels 0, 3, 6
        assert_eq!(got[0], (0, vec![[0.5, 0.5], [3.5, 0.5], [2.5, 1.5]]));
        assert_eq!(got[1], (3, vec![[2.5, 1.5]]));
    }

    #[test]
    fn the_crop_region_adds_the_surroundings_of_the_grown_box() {
        // one masked pixel at (2, 1) of a 4 x 2 view
        let mut one = vec![false; 8];
        one[6] = true;
        let views = [view(Some(one))];
        assert_eq!(
            hidden_pixels(&views, 100, Some(0.0)),
            vec![(0, vec![[2.5, 1.5]])]
        );
        // a 1-pixel box grown by 1 of its size on each side: x 1..4, y 0..2 (clamped)
        let got = hidden_pixels(&views, 100, Some(1.0));
        let want: Vec<[f32; 2]> = [(1, 0), (2, 0), (3, 0), (1, 1), (2, 1), (3, 1)]
            .iter()
            .map(|&(x, y)| [x as f32 + 0.5, y as f32 + 0.5])
            .collect();
        assert_eq!(got, vec![(0, want)]);
        // the cap keeps a stride grid of the box: 6 pixels, at most 2: stride 3
        let got = hidden_pixels(&views, 2, Some(1.0));
        assert_eq!(got, vec![(0, vec![[1.5, 0.5], [1.5, 1.5]])]);
    }

    #[test]
    fn the_default_is_off_and_bad_fields_are_named() {
        let d = GeometryConfig::default();
        assert!(d.is_default() && !d.enabled() && d.check().is_none());
        let on = GeometryConfig {
            depth_weight: 1.0,
            ..d.clone()
        };
        assert!(on.enabled() && !on.is_default());
        let bad = GeometryConfig {
            distortion_weight: f64::NAN,
            ..d.clone()
        };
        assert!(bad.check().unwrap().contains("geometry.distortion_weight"));
        let bad = GeometryConfig { rays: 0, ..d };
        assert!(bad.check().unwrap().contains("geometry.rays"));
        let crop: GeometryConfig = toml::from_str("depth_weight = 1.0\nregion = \"crop\"").unwrap();
        assert_eq!(crop.region, GeometryRegion::Crop);
        assert!(toml::from_str::<GeometryConfig>("region = \"ring\"").is_err());
    }
}
