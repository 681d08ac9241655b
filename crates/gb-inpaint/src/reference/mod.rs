//! Reference views: one training view with the object removed (a clean plate, or a 2D fill
//! from any tool) supervises the NeRF inside that view's mask, and is carried to the other
//! training views through the rendered depth. This is how the methods that lead SPIn-NeRF's
//! benchmark (3DGIC, GScream, InFusion) use a 2D inpainter: the geometry, not the prior's
//! strength, spreads one good fill over every view.
//!
//! - `--reference VIEW=IMAGE` (repeatable; `[reference] images` in a method): VIEW is a
//!   training view's file name (or stem), IMAGE that view without the object, at the scene's
//!   image size. [`load_references`] checks both and names the flag and the file on every
//!   error: an unknown view, a view without a mask, an unreadable image, a wrong size.
//! - **Direct supervision** ([`ReferenceState::loss`]): from `start_step` (counted out of
//!   the method's `reference_steps`, like the visibility maps: the field needs a geometry
//!   first), `rays` rays a step through the reference views' masked pixels (and through the
//!   carried pixels below) are rendered, and their colour MSE against the reference, times
//!   `weight`, joins the step's loss. The rays, the pixels and the jitter come from a stream
//!   seeded by `(seed, step)`, apart from the reconstruction's, so a run without a reference
//!   is unchanged bit for bit and a resumed run continues exactly.
//! - **Depth anchors**: a reference knows the colour of the hidden surface, not where it lies.
//!   Fitted on colour alone, the field moved its geometry to paint it (exact references on
//!   `stairs` tuning seed 100: mask-box D-PSNR 23.6 against 30.9 dB without a reference), so
//!   each reference ray also carries the disparity loss toward the depth the field rendered
//!   through it when the term started (a carried pixel: when it was carried), times
//!   `anchor_weight`: the reference repaints the geometry that the other views and the
//!   interpolation gave, it does not rebuild it.
//! - **Carried to the other views** ([`carry::carry`]): from `start_step` and every
//!   `refresh_every` steps, each masked pixel of every other training view (on a stride grid
//!   of at most
//!   `max_pixels_per_view`) is lifted to its surface point at the depth the current field
//!   renders, and projected into each reference view. Where it lands inside that view's mask
//!   and in front (the reference view renders a depth within `depth_tolerance`, relative, of
//!   the point's: 3DGIC's depth test), the pixel gets the reference's colour there as its
//!   target. Occluded pixels and pixels no reference reaches get none, and the guidance, if
//!   the method has any, acts there as before. (Decision: a colour target, not ST-LPIPS: it
//!   is per pixel, so it supervises rays drawn one by one like the reconstruction's.)
//! - With visibility-aware guidance ([`crate::visibility`]) a reference view's masked pixels
//!   count as observed: the prior guides only what neither a training view nor a reference
//!   shows.
//! - **Only where no view sees** (`skip_observed`, off by default): about two thirds of the
//!   region behind the object is seen by some other training view outside its mask
//!   (`bench/results/hidden-visibility-*.json`), which the reconstruction already fits. An
//!   inexact reference (a 2D fill) there fights the truth; with `skip_observed` each refresh
//!   also tests the reference's masked pixels with the visibility test
//!   ([`carry::observed_reference_pixels`]), and only the unobserved ones are supervised and
//!   carried.

pub mod carry;

use std::path::Path;

use burn::tensor::{Tensor, TensorData};
use gb_core::{RgbImage, TensorValuesError};
use gb_nerf::render::{render_samples, render_samples_fixed_geometry};
use gb_nerf::sampler::RayBatch;
use gb_nerf::scene::{Scene, Split};
use gb_nerf::train::data::{downscale_image, TrainView};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::crop::{disparity_pair, disparity_toward, RenderContext};
use crate::error::InpaintError;
pub use crate::method::{ReferenceConfig, ReferencePair};
pub use carry::{CarriedPixel, CarriedSet};

/// A loaded reference: training view `view`, its image at the training resolution, and its
/// masked pixels (the pixels the reference supervises directly).
#[derive(Debug, Clone)]
pub struct ReferenceView {
    /// Index into the training views (`TrainData::views`).
    pub view: usize,
    /// The view's file stem.
    pub name: String,
    /// The reference image at the training resolution.
    pub image: RgbImage,
    /// Masked pixels `[x, y]` at the training resolution.
    pub pixels: Vec<[u32; 2]>,
}

fn spec_error(pair: &str, reason: String) -> InpaintError {
    InpaintError::Spec {
        field: format!("--reference {pair}"),
        reason,
    }
}

/// The middle one of the training views of `scene` with a non-empty mask: the view that
/// `--reference auto` fills and that `bench quality`'s reference rows use.
pub fn middle_masked_view(scene: &Scene) -> Option<&gb_nerf::scene::View> {
    let masked: Vec<&gb_nerf::scene::View> = scene
        .split(Split::Train)
        .filter(|v| v.mask.as_ref().is_some_and(|m| m.data.iter().any(|b| *b)))
        .collect();
    masked.get(masked.len() / 2).copied()
}

/// Whether `name` (a file name or stem) names the view `stem`.
fn names_view(name: &str, stem: &str) -> bool {
    name == stem || Path::new(name).file_stem().is_some_and(|s| s == stem)
}

/// Loads the references of `pairs` (`VIEW=IMAGE` strings) for the training views of `scene`
/// at `1 / downscale` resolution (module docs for the errors).
pub fn load_references(
    scene: &Scene,
    pairs: &[String],
    downscale: usize,
) -> Result<Vec<ReferenceView>, InpaintError> {
    let train: Vec<_> = scene.split(Split::Train).collect();
    let mut out: Vec<ReferenceView> = Vec::new();
    for raw in pairs {
        let pair = ReferencePair::parse(raw).map_err(|reason| InpaintError::Spec {
            field: "--reference".into(),
            reason,
        })?;
        let Some((index, view)) = train
            .iter()
            .enumerate()
            .find(|(_, v)| names_view(&pair.view, &v.name))
        else {
            let known: Vec<&str> = train.iter().map(|v| v.name.as_str()).take(8).collect();
            return Err(spec_error(
                raw,
                format!(
                    "'{}' is not a training view of scene '{}' (its training views: {}{})",
                    pair.view,
                    scene.name,
                    known.join(", "),
                    if train.len() > known.len() {
                        ", ..."
                    } else {
                        ""
                    }
                ),
            ));
        };
        if out.iter().any(|r| r.view == index) {
            return Err(spec_error(
                raw,
                format!("view '{}' has a reference already", view.name),
            ));
        }
        let Some(mask) = view.mask.as_ref().filter(|m| m.data.iter().any(|b| *b)) else {
            return Err(spec_error(
                raw,
                format!(
                    "view '{}' has no mask, so there is nothing for a reference to fill",
                    view.name
                ),
            ));
        };
        let image = gb_core::read_rgb(&pair.image, Some(scene.background)).map_err(|e| {
            spec_error(
                raw,
                format!("{}: cannot read the image: {e}", pair.image.display()),
            )
        })?;
        if (image.width, image.height) != (view.image.width, view.image.height) {
            return Err(spec_error(
                raw,
                format!(
                    "{}: the image is {}x{}, the view '{}' is {}x{}",
                    pair.image.display(),
                    image.width,
                    image.height,
                    view.name,
                    view.image.width,
                    view.image.height
                ),
            ));
        }
        let f = downscale.max(1);
        let small = downscale_image(&image, f);
        let mask = gb_nerf::train::data::downscale_mask(mask, f);
        let pixels: Vec<[u32; 2]> = (0..mask.height)
            .flat_map(|y| (0..mask.width).map(move |x| (x, y)))
            .filter(|&(x, y)| mask.data[y * mask.width + x])
            .map(|(x, y)| [x as u32, y as u32])
            .collect();
        out.push(ReferenceView {
            view: index,
            name: view.name.clone(),
            image: small,
            pixels,
        });
    }
    Ok(out)
}

/// The pixels `(reference, index into its pixels)` that the direct rays draw from, in order:
/// every masked pixel of every reference, less those that `set` marks as observed by another
/// view (`skip_observed`).
fn direct_pixels(views: &[ReferenceView], set: &CarriedSet) -> Vec<(usize, usize)> {
    views
        .iter()
        .enumerate()
        .flat_map(|(k, r)| (0..r.pixels.len()).map(move |i| (k, i)))
        .filter(|&(k, i)| !set.is_observed(k, i))
        .collect()
}

/// The references of a run and what was carried from them.
#[derive(Debug, Clone)]
pub struct ReferenceState {
    /// The settings.
    pub config: ReferenceConfig,
    /// The references.
    pub views: Vec<ReferenceView>,
    /// The carried pixels (recomputed as they age; restored on resume).
    pub carried: Option<CarriedSet>,
    /// First step of the carrying in this run.
    pub carry_start: usize,
}

/// One step's reference term.
pub struct ReferenceTerm {
    /// `weight * MSE`, with its graph to the field.
    pub loss: Tensor<1>,
    /// Rays through reference pixels.
    pub direct_rays: usize,
    /// Rays through carried pixels.
    pub carried_rays: usize,
}

impl ReferenceState {
    /// Training view indices with a reference.
    pub fn view_indices(&self) -> Vec<usize> {
        self.views.iter().map(|r| r.view).collect()
    }

    /// Recomputes the carried pixels when they are due (module docs); errors when a rendered
    /// depth cannot be read back.
    pub fn refresh(
        &mut self,
        ctx: &RenderContext<'_>,
        views: &[TrainView],
        step: usize,
    ) -> Result<(), InpaintError> {
        if step < self.carry_start {
            return Ok(());
        }
        let due = self
            .carried
            .as_ref()
            .is_none_or(|c| step >= c.step + self.config.refresh_every);
        if due {
            let anchors = self.carried.take().map(|c| c.anchors);
            let set = carry::carry(ctx, views, &self.views, &self.config, step, anchors)
                .map_err(gb_nerf::train::NerfError::from)?;
            tracing::debug!(step, pixels = set.pixels.len(), "reference carried");
            self.carried = Some(set);
        }
        Ok(())
    }

    /// The reference term of `step` (module docs), drawn from a stream seeded by `seed`.
    /// Errors when early ray termination cannot read the field's densities.
    pub fn loss(
        &self,
        ctx: &RenderContext<'_>,
        views: &[TrainView],
        seed: u64,
    ) -> Result<Option<ReferenceTerm>, TensorValuesError> {
        // before the first refresh (the term's start) there is no anchor and no term
        let Some(set) = self.carried.as_ref() else {
            return Ok(None);
        };
        let direct_pixels = direct_pixels(&self.views, set);
        let direct = direct_pixels.len();
        let carried = set.pixels.len();
        if direct + carried == 0 || self.config.weight == 0.0 {
            return Ok(None);
        }
        let n = self.config.rays;
        let n_carried = if carried == 0 {
            0
        } else if direct == 0 {
            n
        } else {
            ((n as f32 * self.config.carry_share).round() as usize).min(n)
        };
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut rays = RayBatch::default();
        let mut target = Vec::with_capacity(n * 3);
        let mut anchor = Vec::with_capacity(2 * n);
        for k in 0..n {
            let (view, x, y, rgb, depth) = if k < n_carried {
                let c = &set.pixels[rng.random_range(0..carried)];
                (c.view as usize, c.x, c.y, c.rgb, c.depth)
            } else {
                let (k_ref, i) = direct_pixels[rng.random_range(0..direct)];
                let r = &self.views[k_ref];
                let [x, y] = r.pixels[i];
                let depth = set
                    .anchors
                    .get(k_ref)
                    .and_then(|a| a.get(i))
                    .copied()
                    .unwrap_or(0.0);
                (r.view, x, y, r.image.get(x as usize, y as usize), depth)
            };
            anchor.extend(disparity_pair(ctx.settings.near, depth));
            let px = [x as f32 + 0.5, y as f32 + 0.5];
            let Some(v) = views.get(view) else {
                return Ok(None);
            };
            rays.append(ctx.ray_through(&v.camera, px));
            target.extend_from_slice(&rgb);
        }
        let device = ctx.field.device();
        let samples = ctx.settings.samples(ctx.field, &rays, Some(&mut rng))?;
        let out = if self.config.shapes_geometry {
            render_samples(ctx.field, &samples, ctx.settings.background)
        } else {
            render_samples_fixed_geometry(ctx.field, &samples, ctx.settings.background)
        };
        let target = Tensor::<2>::from_data(TensorData::new(target, [n, 3]), &device);
        let diff = out.rgb - target;
        let mut loss = (diff.clone() * diff).mean().mul_scalar(self.config.weight);
        if self.config.anchor_weight > 0.0 {
            let d = disparity_toward(out.disparity, anchor, ctx.settings.near);
            loss = loss + d.mul_scalar(self.config.anchor_weight);
        }
        Ok(Some(ReferenceTerm {
            loss,
            direct_rays: n - n_carried,
            carried_rays: n_carried,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn direct_rays_draw_from_every_reference_pixel_less_the_observed_ones() {
        let reference = |view: usize, n: u32| ReferenceView {
            view,
            name: format!("view_{view:03}"),
            image: RgbImage::filled(4, 4, [0.0; 3]),
            pixels: (0..n).map(|i| [i, 0]).collect(),
        };
        let views = [reference(1, 3), reference(5, 2)];
        let mut set = CarriedSet {
            step: 0,
            pixels: Vec::new(),
            tested: 0,
            anchors: Vec::new(),
            observed: Vec::new(),
        };
        let all = [(0, 0), (0, 1), (0, 2), (1, 0), (1, 1)];
        assert_eq!(direct_pixels(&views, &set), all);
        set.observed = vec![vec![false, true, false], vec![true, false]];
        assert_eq!(direct_pixels(&views, &set), [(0, 0), (0, 2), (1, 1)]);
    }

    #[test]
    fn pairs_parse_at_the_first_equals_sign_and_bad_ones_name_the_flag() {
        let p = ReferencePair::parse("view_010.png=fills/a=b.png").unwrap();
        assert_eq!(p.view, "view_010.png");
        assert_eq!(p.image, std::path::PathBuf::from("fills/a=b.png"));
        for bad in ["view_010.png", "=x.png", "view_010="] {
            let e = ReferencePair::parse(bad).unwrap_err();
            assert!(e.starts_with(&format!("--reference {bad}:")), "{e}");
        }
        assert!(names_view("view_010.png", "view_010"));
        assert!(names_view("view_010", "view_010"));
        assert!(!names_view("view_01", "view_010"));
    }

    #[test]
    fn the_default_table_is_off_and_each_bad_field_is_named() {
        let d = ReferenceConfig::default();
        assert!(d.is_default() && !d.enabled() && d.check().is_none());
        let bad = |c: ReferenceConfig, field: &str| {
            let msg = c.check().expect("an error");
            assert!(msg.contains(field), "{msg} should name {field}");
        };
        bad(
            ReferenceConfig {
                weight: -1.0,
                ..d.clone()
            },
            "reference.weight",
        );
        bad(
            ReferenceConfig {
                rays: 0,
                ..d.clone()
            },
            "reference.rays",
        );
        bad(
            ReferenceConfig {
                carry_share: 1.5,
                ..d.clone()
            },
            "reference.carry_share",
        );
        bad(
            ReferenceConfig {
                refresh_every: 0,
                ..d.clone()
            },
            "reference.refresh_every",
        );
        bad(
            ReferenceConfig {
                images: vec!["nothing".into()],
                ..d
            },
            "--reference nothing",
        );
    }
}
