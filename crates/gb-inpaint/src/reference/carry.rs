//! Carrying a reference to the other training views through the rendered depth (the
//! module docs of [`crate::reference`]).

use burn::module::Module;
use gb_core::TensorValuesError;
use gb_nerf::train::data::TrainView;
use serde::{Deserialize, Serialize};

use super::{ReferenceConfig, ReferenceView};
use crate::crop::RenderContext;
use crate::visibility::{observed_points, render_depth};

/// A masked pixel of a training view with the colour a reference gives it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CarriedPixel {
    /// Index into the training views.
    pub view: u32,
    /// Column at the training resolution.
    pub x: u32,
    /// Row.
    pub y: u32,
    /// Target colour.
    pub rgb: [f32; 3],
    /// The z-depth the field rendered through the pixel when it was carried: the depth
    /// anchor of its ray (0: none).
    #[serde(default)]
    pub depth: f32,
}

/// The carried pixels of one refresh.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CarriedSet {
    /// Step of the field they were computed from.
    pub step: usize,
    /// The pixels.
    pub pixels: Vec<CarriedPixel>,
    /// Masked pixels tested (reached or not).
    pub tested: usize,
    /// Per reference view, the z-depth the field rendered through each of its masked pixels
    /// when the reference term started: the depth anchors of the direct rays (kept from the
    /// first refresh on).
    #[serde(default)]
    pub anchors: Vec<Vec<f32>>,
    /// Per reference view, whether another training view observes each of its masked pixels
    /// (`[reference] skip_observed`; recomputed at every refresh): those pixels are neither
    /// supervised nor carried. Empty when the setting is off.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub observed: Vec<Vec<bool>>,
}

impl CarriedSet {
    /// Whether pixel `i` of reference `k` is observed by another view (module docs).
    pub fn is_observed(&self, k: usize, i: usize) -> bool {
        self.observed
            .get(k)
            .and_then(|o| o.get(i))
            .copied()
            .unwrap_or(false)
    }
}

/// Masked pixels of `view` on a stride grid of at most `max` pixels (row-major).
fn masked_on_grid(view: &TrainView, max: usize) -> Vec<[u32; 2]> {
    let Some(mask) = view.mask.as_ref() else {
        return Vec::new();
    };
    let all = mask.data.iter().filter(|b| **b).count();
    // the smallest square stride that keeps at most `max` pixels (about all / stride^2)
    let mut stride = 1usize;
    while all.div_ceil(stride * stride) > max {
        stride += 1;
    }
    (0..mask.height)
        .step_by(stride)
        .flat_map(|y| (0..mask.width).step_by(stride).map(move |x| (x, y)))
        .filter(|&(x, y)| mask.data[y * mask.width + x])
        .map(|(x, y)| [x as u32, y as u32])
        .collect()
}

/// The z-depth map `[width * height]` a field renders through a reference view's masked
/// pixels (NaN elsewhere).
fn reference_depth(
    ctx: &RenderContext<'_>,
    field: &gb_nerf::field::NerfField,
    views: &[TrainView],
    r: &ReferenceView,
) -> Result<Vec<f32>, TensorValuesError> {
    let cam = &views[r.view].camera;
    let px: Vec<[f32; 2]> = r
        .pixels
        .iter()
        .map(|[x, y]| [*x as f32 + 0.5, *y as f32 + 0.5])
        .collect();
    let rays = ctx.settings.rays(cam, &px);
    let depth = render_depth(field, ctx, &rays)?;
    let mut map = vec![f32::NAN; cam.width * cam.height];
    for ([x, y], d) in r.pixels.iter().zip(depth) {
        map[*y as usize * cam.width + *x as usize] = d;
    }
    Ok(map)
}

/// The pixels of every training view but the references' that a reference reaches through
/// the field of `ctx` at `step` (module docs of [`crate::reference`]; none when
/// `cfg.carry` is off), with the direct rays' depth anchors: `anchors` when given (those of
/// the first refresh), else the depths rendered now, and, with `cfg.skip_observed`, which
/// reference pixels another view observes ([`observed_reference_pixels`]; nothing is carried
/// from those). Errors when a rendered depth does not hold `f32` values.
pub fn carry(
    ctx: &RenderContext<'_>,
    views: &[TrainView],
    refs: &[ReferenceView],
    cfg: &ReferenceConfig,
    step: usize,
    anchors: Option<Vec<Vec<f32>>>,
) -> Result<CarriedSet, TensorValuesError> {
    let field = ctx.field.valid();
    let ref_depths: Vec<Vec<f32>> = refs
        .iter()
        .map(|r| reference_depth(ctx, &field, views, r))
        .collect::<Result<_, _>>()?;
    let anchors = anchors.unwrap_or_else(|| {
        refs.iter()
            .zip(&ref_depths)
            .map(|(r, map)| {
                let w = views[r.view].camera.width;
                r.pixels
                    .iter()
                    .map(|[x, y]| map[*y as usize * w + *x as usize])
                    .collect()
            })
            .collect()
    });
    let observed = if cfg.skip_observed {
        observed_reference_pixels(ctx, &field, views, refs, &ref_depths, cfg.depth_tolerance)?
    } else {
        Vec::new()
    };
    let mut tested = Vec::new();
    for (j, view) in views.iter().enumerate() {
        if !cfg.carry || refs.iter().any(|r| r.view == j) {
            continue;
        }
        let grid = masked_on_grid(view, cfg.max_pixels_per_view);
        if grid.is_empty() {
            continue;
        }
        let px: Vec<[f32; 2]> = grid
            .iter()
            .map(|[x, y]| [*x as f32 + 0.5, *y as f32 + 0.5])
            .collect();
        let rays = ctx.settings.rays(&view.camera, &px);
        let depth = render_depth(&field, ctx, &rays)?;
        tested.push(TestedView {
            view: j,
            pixels: grid,
            depth,
        });
    }
    let mut set = carry_from_depths(
        views,
        refs,
        &ref_depths,
        &observed,
        &tested,
        cfg.depth_tolerance,
        step,
    );
    set.anchors = anchors;
    set.observed = observed;
    Ok(set)
}

/// For each reference, which of its masked pixels another training view observes: the
/// pixel's surface point, at the depth `ref_depths` gives it, passes the visibility test of
/// [`crate::visibility`] in some other training view, outside that view's mask (so another
/// reference's masked pixels, which hold a fill, do not observe). A pixel without a finite
/// depth is not observed.
pub fn observed_reference_pixels(
    ctx: &RenderContext<'_>,
    field: &gb_nerf::field::NerfField,
    views: &[TrainView],
    refs: &[ReferenceView],
    ref_depths: &[Vec<f32>],
    tolerance: f32,
) -> Result<Vec<Vec<bool>>, TensorValuesError> {
    refs.iter()
        .zip(ref_depths)
        .map(|(r, map)| {
            let cam = &views[r.view].camera;
            let points: Vec<[f32; 3]> = r
                .pixels
                .iter()
                .map(|[x, y]| {
                    let d = map[*y as usize * cam.width + *x as usize];
                    if d.is_finite() {
                        cam.unproject(*x as f32 + 0.5, *y as f32 + 0.5, d)
                    } else {
                        [f32::NAN; 3]
                    }
                })
                .collect();
            observed_points(field, ctx, views, &points, &[r.view], &[], tolerance)
        })
        .collect()
}

/// The masked pixels of one view that the carrying tests, with the z-depth rendered
/// through each.
#[derive(Debug, Clone)]
pub struct TestedView {
    /// Index into the training views.
    pub view: usize,
    /// Pixels `[x, y]`.
    pub pixels: Vec<[u32; 2]>,
    /// Their z-depths.
    pub depth: Vec<f32>,
}

/// The geometry of [`carry`] on given depths: each tested pixel's surface point is projected
/// into each reference view (`ref_depths[k]`: the z-depth map, `width * height`, that
/// reference `k` renders, NaN where unknown); the first reference whose mask it lands in,
/// with a depth there within `tolerance` (relative) of the point's, gives its colour, unless
/// `observed[k]` (per masked pixel of reference `k`, in its `pixels` order; empty: none)
/// marks that reference pixel as observed by another view.
pub fn carry_from_depths(
    views: &[TrainView],
    refs: &[ReferenceView],
    ref_depths: &[Vec<f32>],
    observed: &[Vec<bool>],
    tested: &[TestedView],
    tolerance: f32,
    step: usize,
) -> CarriedSet {
    // each reference's observed pixels as a map of its image
    let observed_maps: Vec<Vec<bool>> = refs
        .iter()
        .enumerate()
        .map(|(k, r)| {
            let w = views[r.view].camera.width;
            let mut map = vec![false; w * views[r.view].camera.height];
            if let Some(flags) = observed.get(k) {
                for ([x, y], o) in r.pixels.iter().zip(flags) {
                    map[*y as usize * w + *x as usize] = *o;
                }
            }
            map
        })
        .collect();
    let mut pixels = Vec::new();
    let mut count = 0;
    for t in tested {
        let cam = &views[t.view].camera;
        count += t.pixels.len();
        for ([x, y], d) in t.pixels.iter().zip(&t.depth) {
            let point = cam.unproject(*x as f32 + 0.5, *y as f32 + 0.5, *d);
            let hit =
                refs.iter()
                    .zip(ref_depths)
                    .zip(&observed_maps)
                    .find_map(|((r, map), obs)| {
                        let rv = &views[r.view];
                        let rc = &rv.camera;
                        let ([u, v], z) = rc.project(point)?;
                        if !(u >= 0.0 && v >= 0.0 && u < rc.width as f32 && v < rc.height as f32) {
                            return None;
                        }
                        let (ui, vi) = (u as usize, v as usize);
                        let masked = rv.mask.as_ref().is_some_and(|m| {
                            m.data.get(vi * m.width + ui).copied().unwrap_or(false)
                        });
                        let seen = map.get(vi * rc.width + ui).copied().unwrap_or(f32::NAN);
                        let in_front =
                            seen.is_finite() && (seen - z).abs() <= tolerance * z.abs().max(1e-6);
                        let observed = obs.get(vi * rc.width + ui).copied().unwrap_or(false);
                        (masked && in_front && !observed).then(|| r.image.get(ui, vi))
                    });
            if let Some(rgb) = hit {
                pixels.push(CarriedPixel {
                    view: t.view as u32,
                    x: *x,
                    y: *y,
                    rgb,
                    depth: *d,
                });
            }
        }
    }
    CarriedSet {
        step,
        pixels,
        tested: count,
        anchors: Vec::new(),
        observed: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gb_core::RgbImage;
    use gb_nerf::scene::{Camera, Mask};

    fn view(w: usize, h: usize, masked: impl Fn(usize, usize) -> bool) -> TrainView {
        let data = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| masked(x, y))
            .collect();
        TrainView {
            camera: Camera {
                width: w,
                height: h,
                fx: 50.0,
                fy: 50.0,
                cx: w as f32 / 2.0,
                cy: h as f32 / 2.0,
                c2w: [
                    [1.0, 0.0, 0.0, 0.0],
                    [0.0, 1.0, 0.0, 0.0],
                    [0.0, 0.0, 1.0, 0.0],
                ],
            },
            image: RgbImage::filled(w, h, [0.0; 3]),
            mask: Some(Mask {
                width: w,
                height: h,
                data,
            }),
            depth: None,
        }
    }

    #[test]
    fn the_stride_grid_keeps_at_most_the_cap_and_only_masked_pixels() {
        let v = view(40, 30, |x, y| (10..30).contains(&x) && (5..25).contains(&y));
        assert_eq!(masked_on_grid(&v, 10_000).len(), 400);
        let g = masked_on_grid(&v, 100);
        assert!(g.len() <= 100 && g.len() >= 80, "{}", g.len());
        let m = v.mask.as_ref().unwrap();
        assert!(g
            .iter()
            .all(|[x, y]| m.data[*y as usize * 40 + *x as usize]));
    }

    fn plane_view(offset_x: f32, masked: impl Fn(usize, usize) -> bool) -> TrainView {
        let mut v = view(32, 24, masked);
        v.camera.fx = 20.0;
        v.camera.fy = 20.0;
        v.camera.c2w[0][3] = offset_x;
        v
    }

    /// Three cameras side by side (x = -1, 0, 1) facing a plane 5 units away; the middle
    /// one is the reference, its colours coding its pixel positions. A point at z-depth 5
    /// moves by fx / 5 = 4 pixels between neighbouring cameras, so pixel (x, y) of the left
    /// view must get the reference's colour at (x - 4, y) wherever that lies in the
    /// reference's mask; pixels whose surface an occluder hides get nothing: an occluder the
    /// right view sees (its depth 2.5 on columns 8 to 11) and one the reference sees in
    /// front of the plane (its depth 2 on columns 12 and 13).
    #[test]
    fn a_reference_reaches_the_views_that_see_its_surface_and_not_occluded_ones() {
        let in_box = |x: usize, y: usize| (8..24).contains(&x) && (6..18).contains(&y);
        let mut views = vec![
            plane_view(-1.0, in_box),
            plane_view(0.0, in_box),
            plane_view(1.0, in_box),
        ];
        let mut image = RgbImage::filled(32, 24, [0.0; 3]);
        for y in 0..24 {
            for x in 0..32 {
                image.set(x, y, [x as f32 / 32.0, y as f32 / 24.0, 0.5]);
            }
        }
        views[1].image = image.clone();
        let pixels: Vec<[u32; 2]> = (0..24u32)
            .flat_map(|y| (0..32u32).map(move |x| [x, y]))
            .filter(|[x, y]| in_box(*x as usize, *y as usize))
            .collect();
        let reference = ReferenceView {
            view: 1,
            name: "middle".into(),
            image,
            pixels: pixels.clone(),
        };
        let mut ref_depth = vec![f32::NAN; 32 * 24];
        for [x, y] in &pixels {
            let occluded = (12..14).contains(x);
            ref_depth[*y as usize * 32 + *x as usize] = if occluded { 2.0 } else { 5.0 };
        }
        let tested: Vec<TestedView> = [0usize, 2]
            .iter()
            .map(|&j| {
                let grid = masked_on_grid(&views[j], 10_000);
                let depth = grid
                    .iter()
                    .map(|[x, _]| if j == 2 && *x < 12 { 2.5 } else { 5.0 })
                    .collect();
                TestedView {
                    view: j,
                    pixels: grid,
                    depth,
                }
            })
            .collect();
        let set = carry_from_depths(&views, &[reference], &[ref_depth], &[], &tested, 0.05, 7);
        assert_eq!((set.step, set.tested), (7, 2 * 16 * 12));
        // the left view: columns whose partner column x - 4 is in the box (8..24) and not
        // behind the reference's occluder (12, 13)
        let left: Vec<&CarriedPixel> = set.pixels.iter().filter(|p| p.view == 0).collect();
        let expected_left: usize = (8..24)
            .filter(|x| (8..24).contains(&(x - 4)) && !(12..14).contains(&(x - 4)))
            .count()
            * 12;
        assert_eq!(left.len(), expected_left);
        for p in &left {
            let (u, v) = (p.x - 4, p.y);
            assert_eq!(p.rgb, [u as f32 / 32.0, v as f32 / 24.0, 0.5], "{p:?}");
        }
        // the right view: partner column x + 4; its own occluder (depth 2.5) on columns 8 to
        // 11 lands at columns 16 to 19 of the reference, inside its mask, but in front of
        // the surface the reference shows there
        let right: Vec<&CarriedPixel> = set.pixels.iter().filter(|p| p.view == 2).collect();
        let expected_right: usize = (12..24)
            .filter(|x| (8..24).contains(&(x + 4)) && !(12..14).contains(&(x + 4)))
            .count()
            * 12;
        assert_eq!(right.len(), expected_right);
        for p in &right {
            assert!(p.x >= 12, "an occluded pixel was reached: {p:?}");
            assert_eq!(p.rgb[0], (p.x + 4) as f32 / 32.0, "{p:?}");
        }
        // `skip_observed`: the reference's pixels left of column 16 are observed by another
        // view, so nothing is carried from them; the rest is carried as before
        let observed = vec![pixels.iter().map(|[x, _]| *x < 16).collect::<Vec<bool>>()];
        let ref_depth = {
            let mut d = vec![f32::NAN; 32 * 24];
            for [x, y] in &pixels {
                d[*y as usize * 32 + *x as usize] = if (12..14).contains(x) { 2.0 } else { 5.0 };
            }
            d
        };
        let reference = ReferenceView {
            view: 1,
            name: "middle".into(),
            image: views[1].image.clone(),
            pixels: pixels.clone(),
        };
        let skipped = carry_from_depths(
            &views,
            &[reference],
            &[ref_depth],
            &observed,
            &tested,
            0.05,
            7,
        );
        let kept: Vec<&CarriedPixel> = set
            .pixels
            .iter()
            .filter(|p| {
                if p.view == 0 {
                    p.x - 4 >= 16
                } else {
                    p.x + 4 >= 16
                }
            })
            .collect();
        assert!(!kept.is_empty() && kept.len() < set.pixels.len());
        assert_eq!(skipped.pixels.iter().collect::<Vec<_>>(), kept);
    }
}
