//! Pseudo-holes: boxes on observed background that the auto-weight trials withhold from
//! every training view, so that they are hidden exactly like the real hole, yet their truth
//! is known (the training images, and the depth where the scene has it).
//!
//! A pseudo-hole is a world-axis-aligned cube centred on a reconstructed surface point (the
//! scene's sparse points, or its depth maps), sized so that its image in the masked views is
//! about as large as the object's mask. Its withheld region in a view is every pixel whose
//! ray crosses the cube in front of the camera, grown by one pixel: no training ray reaches
//! any point inside it. It is placed only where, in every training view, its image keeps a
//! margin from the object's mask (the real hole stays the real hole), and where at least
//! half of the masked views (two at least) see it whole.
//!
//! Among the places that fit, the pseudo-holes should look like the hole (issue 45): each
//! candidate is scored by how far the ring just outside its image in the masked views is, in
//! colour and texture ([`super::resemblance`]), from the ring just outside the object's mask,
//! and the closest wins. Further pseudo-holes ([`place_holes`]) go on other surfaces: their
//! centres at least twice their two half-sides apart from those chosen, and unlike each of
//! them in appearance, so that one flat wall does not decide the trials.

use gb_nerf::scene::{Camera, Mask, Scene, Split, View};

use super::resemblance::{Appearance, Sums, ViewStats};

/// Candidate centres examined (an even subsample of the surface points).
const MAX_CANDIDATES: usize = 600;
/// The margin between a pseudo-hole's image and the object's mask, as a fraction of the
/// pseudo-hole image's size; also the width of the rings compared ([`super::resemblance`]),
/// as a fraction of the pseudo-hole's and of the mask's side.
const MASK_MARGIN: f32 = 0.25;
/// The smallest appearance distance between two pseudo-holes' rings for them to count as
/// on different surfaces.
const OTHER_SURFACE: f32 = 0.05;

/// A placed pseudo-hole, with what chose it (`metrics.json`'s `auto.holes`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlacedHole {
    /// The cube.
    pub hole: PseudoHole,
    /// Its side as a fraction of the mask's (times `[auto] hole_scale`).
    pub side: f32,
    /// The appearance distance of its ring to the object's ring (0: alike).
    pub resemblance: f32,
    /// The statistics of its ring in the masked views.
    pub appearance: Appearance,
    /// The masked views that see it whole.
    pub whole_views: usize,
}

/// A withheld cube (module docs).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PseudoHole {
    /// Minimum corner, world units.
    pub min: [f32; 3],
    /// Maximum corner.
    pub max: [f32; 3],
}

impl PseudoHole {
    /// The cube of half-side `half` around `centre`.
    pub fn cube(centre: [f32; 3], half: f32) -> Self {
        Self {
            min: centre.map(|c| c - half),
            max: centre.map(|c| c + half),
        }
    }

    fn corners(&self) -> [[f32; 3]; 8] {
        let (a, b) = (self.min, self.max);
        std::array::from_fn(|i| {
            [
                if i & 1 == 0 { a[0] } else { b[0] },
                if i & 2 == 0 { a[1] } else { b[1] },
                if i & 4 == 0 { a[2] } else { b[2] },
            ]
        })
    }

    /// Whether `p` lies inside the cube.
    pub fn contains(&self, p: [f32; 3]) -> bool {
        (0..3).all(|i| p[i] >= self.min[i] && p[i] <= self.max[i])
    }

    /// Whether the ray `origin + t dir`, `t > 0`, crosses the cube (slab test).
    pub fn hit(&self, origin: [f32; 3], dir: [f32; 3]) -> bool {
        let (mut t0, mut t1) = (0.0f32, f32::INFINITY);
        for i in 0..3 {
            if dir[i].abs() < 1e-12 {
                if origin[i] < self.min[i] || origin[i] > self.max[i] {
                    return false;
                }
                continue;
            }
            let (a, b) = (
                (self.min[i] - origin[i]) / dir[i],
                (self.max[i] - origin[i]) / dir[i],
            );
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        t0 <= t1
    }

    /// The bounding rectangle `(x0, y0, x1, y1)` (continuous pixels, unclipped) of the
    /// cube's image in `camera`; `None` when a corner lies behind it.
    pub fn image_rect(&self, camera: &Camera) -> Option<[f32; 4]> {
        let mut r = [
            f32::INFINITY,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NEG_INFINITY,
        ];
        for c in self.corners() {
            let ([x, y], _) = camera.project(c)?;
            r = [r[0].min(x), r[1].min(y), r[2].max(x), r[3].max(y)];
        }
        Some(r)
    }

    /// The withheld pixels of `camera`'s image: those whose ray (through the pixel centre)
    /// crosses the cube, grown by one pixel (module docs).
    pub fn mask(&self, camera: &Camera) -> Mask {
        let (w, h) = (camera.width, camera.height);
        let mut hit = vec![false; w * h];
        let origin = camera.origin();
        // only the pixels of the image rectangle can hit; a corner behind the camera: all
        let (x0, y0, x1, y1) = match self.image_rect(camera) {
            Some([a, b, c, d]) => (
                (a.floor().max(0.0) as usize).min(w),
                (b.floor().max(0.0) as usize).min(h),
                (c.ceil().max(0.0) as usize).min(w),
                (d.ceil().max(0.0) as usize).min(h),
            ),
            None => (0, 0, w, h),
        };
        for y in y0..y1 {
            for x in x0..x1 {
                let d = camera.ray_direction(x as f32 + 0.5, y as f32 + 0.5);
                hit[y * w + x] = self.hit(origin, d);
            }
        }
        let mut data = hit.clone();
        for y in 0..h {
            for x in 0..w {
                if hit[y * w + x] {
                    for (dx, dy) in [
                        (-1i64, 0i64),
                        (1, 0),
                        (0, -1),
                        (0, 1),
                        (-1, -1),
                        (1, 1),
                        (-1, 1),
                        (1, -1),
                    ] {
                        let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                        if nx >= 0 && ny >= 0 && (nx as usize) < w && (ny as usize) < h {
                            data[ny as usize * w + nx as usize] = true;
                        }
                    }
                }
            }
        }
        Mask {
            width: w,
            height: h,
            data,
        }
    }
}

fn under_mask(view: &View, x: f32, y: f32) -> bool {
    view.mask.as_ref().is_some_and(|m| {
        let (px, py) = (x.floor() as i64, y.floor() as i64);
        px >= 0
            && py >= 0
            && (px as usize) < m.width
            && (py as usize) < m.height
            && m.data[py as usize * m.width + px as usize]
    })
}

/// Whether `scene` has observed surface points to place a pseudo-hole on: sparse points or
/// depth-map pixels of its training views outside the masks.
pub fn has_surface_points(scene: &Scene) -> bool {
    let train: Vec<&View> = scene.split(Split::Train).collect();
    !surface_points(scene, &train).is_empty()
}

/// The scene's observed surface points: its sparse points (COLMAP's), else every 8th pixel
/// of its depth maps, leaving out those under a mask (the object).
fn surface_points(scene: &Scene, train: &[&View]) -> Vec<[f32; 3]> {
    let mut out = Vec::new();
    for v in train {
        for p in scene.sparse_depth.get(&v.name).into_iter().flatten() {
            if p.depth.is_finite() && p.depth > 0.0 && !under_mask(v, p.x, p.y) {
                out.push(v.camera.unproject(p.x, p.y, p.depth));
            }
        }
    }
    if !out.is_empty() {
        return out;
    }
    for v in train {
        let Some(depth) = &v.depth else { continue };
        for [px, py] in grid_outside_mask(v) {
            let z = depth[py as usize * v.image.width + px as usize];
            if z.is_finite() && z > 0.0 {
                out.push(v.camera.unproject(px, py, z));
            }
        }
    }
    out
}

/// Pixels between the surface points read from a depth map (or a scout field's depth), in
/// both directions.
pub const SURFACE_STRIDE: usize = 8;

/// Pixel centres every [`SURFACE_STRIDE`] pixels of `view`, outside its mask: where its
/// surface points are read.
pub(super) fn grid_outside_mask(view: &View) -> Vec<[f32; 2]> {
    let (w, h) = (view.image.width, view.image.height);
    let half = SURFACE_STRIDE / 2;
    (half..h)
        .step_by(SURFACE_STRIDE)
        .flat_map(|y| {
            (half..w)
                .step_by(SURFACE_STRIDE)
                .map(move |x| [x as f32 + 0.5, y as f32 + 0.5])
        })
        .filter(|&[px, py]| !under_mask(view, px, py))
        .collect()
}

/// Summed-area table of a mask, `(w + 1) * (h + 1)`.
fn integral(m: &Mask) -> Vec<u32> {
    let (w, h) = (m.width, m.height);
    let mut s = vec![0u32; (w + 1) * (h + 1)];
    for y in 0..h {
        for x in 0..w {
            s[(y + 1) * (w + 1) + x + 1] =
                m.data[y * w + x] as u32 + s[y * (w + 1) + x + 1] + s[(y + 1) * (w + 1) + x]
                    - s[y * (w + 1) + x];
        }
    }
    s
}

/// Masked pixels in the (clipped) rectangle.
fn count_in(s: &[u32], w: usize, h: usize, r: [f32; 4]) -> u32 {
    let clip = |v: f32, n: usize| (v.max(0.0) as usize).min(n);
    let (x0, y0) = (clip(r[0].floor(), w), clip(r[1].floor(), h));
    let (x1, y1) = (clip(r[2].ceil(), w), clip(r[3].ceil(), h));
    if x1 <= x0 || y1 <= y0 {
        return 0;
    }
    let at = |x: usize, y: usize| s[y * (w + 1) + x];
    at(x1, y1) + at(x0, y0) - at(x0, y1) - at(x1, y0)
}

fn median(mut v: Vec<f32>) -> Option<f32> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f32::total_cmp);
    Some(v[v.len() / 2])
}

/// The sides tried, as fractions of the requested one ([`place_holes`]).
const SHRINK: [f32; 4] = [1.0, 0.7, 0.5, 0.35];

/// Places the pseudo-hole of `scene` that looks most like the hole ([`place_holes`] with one).
pub fn place(scene: &Scene, scale: f32) -> Result<PseudoHole, String> {
    Ok(place_holes(scene, scale, 1)?[0].hole)
}

/// Places up to `count` pseudo-holes in `scene` (module docs), the one most like the hole
/// first. `scale` multiplies their side (1: the object mask's size). Each candidate centre is
/// tried at the sides of [`SHRINK`] (smaller ones fit where the mask spans much of every view,
/// as on `fence`, or in a recess, as on `alcove`), and a smaller side costs
/// [`SMALLER_SIDE`] of resemblance. Candidates that half the masked views see whole come
/// first; where there are none, two masked views will do. Errors, with the reason, when the
/// scene has no surface points or nothing fits.
pub fn place_holes(scene: &Scene, scale: f32, count: usize) -> Result<Vec<PlacedHole>, String> {
    let ctx = Placement::new(scene)?;
    let half = ctx.masked.len().div_ceil(2).max(2).min(ctx.masked.len());
    let fewest = 2.min(half);
    for need in [half, fewest] {
        let fits: Vec<Fit> = SHRINK
            .iter()
            .flat_map(|&side| ctx.fitting(scale, side, need))
            .collect();
        let candidates = ctx.scored(fits);
        if candidates.is_empty() {
            if need == fewest {
                break;
            }
            continue;
        }
        let holes = choose(candidates, count.max(1));
        if need < half {
            tracing::warn!(
                views = need,
                "auto weights: no pseudo-hole fits that half the masked views see whole; using \
                 ones that {need} see whole"
            );
        }
        return Ok(holes);
    }
    Err(format!(
        "no surface point keeps a pseudo-hole's image clear of the masks while {fewest} masked \
         views see it whole, down to {:.2} of the mask's size; give lambda_rgb and \
         lambda_normal numbers instead of \"auto\"",
        scale * SHRINK[SHRINK.len() - 1]
    ))
}

/// The resemblance a pseudo-hole gives up by being smaller than the mask, per unit of side
/// lost (colour units): at a quarter of the ring distance between a wall and a tiled recess,
/// a smaller hole wins only where it looks clearly more like the hole.
const SMALLER_SIDE: f32 = 0.05;

/// The candidates in order of preference (resemblance with the [`SMALLER_SIDE`] cost, then
/// seen whole by more views, then nearer the object), taken greedily: each further one must
/// lie at least twice their two half-sides from those chosen and differ from each in
/// appearance by
/// [`OTHER_SURFACE`].
fn choose(mut candidates: Vec<Candidate>, count: usize) -> Vec<PlacedHole> {
    let cost = |c: &Candidate| c.resemblance + SMALLER_SIDE * (1.0 - c.fit.side);
    candidates.sort_by(|a, b| {
        cost(a)
            .total_cmp(&cost(b))
            .then(b.fit.whole.cmp(&a.fit.whole))
            .then(a.fit.to_object.total_cmp(&b.fit.to_object))
    });
    let mut chosen: Vec<Candidate> = Vec::new();
    for c in candidates {
        if chosen.len() == count {
            break;
        }
        let apart = chosen.iter().all(|o| {
            let d = (0..3)
                .map(|i| (c.fit.centre[i] - o.fit.centre[i]).powi(2))
                .sum::<f32>()
                .sqrt();
            d >= 2.0 * (c.fit.half + o.fit.half)
                && c.appearance.distance(&o.appearance) >= OTHER_SURFACE
        });
        if apart {
            chosen.push(c);
        }
    }
    chosen
        .into_iter()
        .map(|c| PlacedHole {
            hole: c.fit.hole,
            side: c.fit.side,
            resemblance: c.resemblance,
            appearance: c.appearance,
            whole_views: c.fit.whole,
        })
        .collect()
}

/// What every try of [`place_holes`] reads, computed once: the training views, each one's
/// mask as a summed-area table, the masked views' mask sides, the candidate surface points
/// and the object's centre.
struct Placement<'a> {
    train: Vec<&'a View>,
    /// Per training view, the summed-area table of its mask (`None`: no mask).
    integrals: Vec<Option<Vec<u32>>>,
    /// `(training view index, square root of its mask's area)` of the masked views.
    masked: Vec<(usize, f32)>,
    points: Vec<[f32; 3]>,
    object: Option<[f32; 3]>,
}

/// A place that fits ([`Placement::fits`]).
struct Fit {
    hole: PseudoHole,
    half: f32,
    /// Its side as a fraction of the mask's (one of [`SHRINK`]).
    side: f32,
    centre: [f32; 3],
    /// Masked views that see it whole.
    whole: usize,
    /// Distance from the object's centre.
    to_object: f32,
}

/// A [`Fit`] with its ring's statistics and their distance to the object's ring.
struct Candidate {
    fit: Fit,
    appearance: Appearance,
    resemblance: f32,
}

impl<'a> Placement<'a> {
    fn new(scene: &'a Scene) -> Result<Self, String> {
        let train: Vec<&View> = scene.split(Split::Train).collect();
        let integrals: Vec<Option<Vec<u32>>> = train
            .iter()
            .map(|v| v.mask.as_ref().map(integral))
            .collect();
        let masked: Vec<(usize, f32)> = train
            .iter()
            .enumerate()
            .filter_map(|(k, v)| {
                let area = v.mask.as_ref()?.data.iter().filter(|b| **b).count();
                (area > 0).then(|| (k, (area as f32).sqrt()))
            })
            .collect();
        if masked.is_empty() {
            return Err("no training view has a mask".into());
        }
        let points = surface_points(scene, &train);
        if points.is_empty() {
            return Err(
                "the scene has no surface points outside the masks (no COLMAP sparse/0 points \
                 and no depth maps) to place a pseudo-hole on"
                    .into(),
            );
        }
        let object = object_centre(scene, &train);
        Ok(Self {
            train,
            integrals,
            masked,
            points,
            object,
        })
    }

    /// `fits` with their rings' statistics (the ring just outside each one's image in the
    /// masked views) and their distance to the object's ring; those whose ring no masked
    /// view shows are left out. One masked view's statistics are held at a time.
    fn scored(&self, fits: Vec<Fit>) -> Vec<Candidate> {
        if fits.is_empty() {
            return Vec::new();
        }
        let mut object = Sums::default();
        let mut rings = vec![Sums::default(); fits.len()];
        for (k, side) in &self.masked {
            let view = self.train[*k];
            let Some(mask) = view.mask.as_ref() else {
                continue;
            };
            let stats = ViewStats::new(&view.image, Some(mask));
            object = object.add(&stats.ring(mask, ((MASK_MARGIN * side).round() as usize).max(2)));
            for (fit, ring) in fits.iter().zip(&mut rings) {
                let Some(r) = fit.hole.image_rect(&view.camera) else {
                    continue;
                };
                let (mx, my) = (MASK_MARGIN * (r[2] - r[0]), MASK_MARGIN * (r[3] - r[1]));
                let grown = stats.rect([r[0] - mx, r[1] - my, r[2] + mx, r[3] + my]);
                *ring = ring.add(&grown.sub(&stats.rect(r)));
            }
        }
        let object = object.appearance();
        fits.into_iter()
            .zip(rings)
            .filter_map(|(fit, ring)| {
                let appearance = ring.appearance()?;
                Some(Candidate {
                    fit,
                    appearance,
                    resemblance: object.map_or(0.0, |o| o.distance(&appearance)),
                })
            })
            .collect()
    }

    /// Every candidate centre's pseudo-hole at `side` of the mask's size (times `scale`)
    /// that fits with at least `need` masked views seeing it whole.
    fn fitting(&self, scale: f32, side: f32, need: usize) -> Vec<Fit> {
        let stride = self.points.len().div_ceil(MAX_CANDIDATES).max(1);
        let mut out = Vec::new();
        for p in self.points.iter().step_by(stride) {
            // the half-side that makes the cube's image as large as the mask, per masked view
            let sizes: Vec<f32> = self
                .masked
                .iter()
                .filter_map(|(k, mask_side)| {
                    let camera = &self.train[*k].camera;
                    let (_, z) = camera.project(*p)?;
                    Some(0.5 * scale * side * mask_side * z / camera.fx)
                })
                .collect();
            let Some(half) = median(sizes) else { continue };
            let hole = PseudoHole::cube(*p, half);
            let Some(whole) = self.fits(&hole, need) else {
                continue;
            };
            out.push(Fit {
                hole,
                half,
                side,
                centre: *p,
                whole,
                to_object: self.object.map_or(0.0, |o| {
                    (0..3).map(|i| (p[i] - o[i]).powi(2)).sum::<f32>().sqrt()
                }),
            });
        }
        out
    }

    /// The number of masked views that see `hole` whole, when its image keeps its margin
    /// from every view's mask and at least `need` masked views see it whole; else `None`.
    fn fits(&self, hole: &PseudoHole, need: usize) -> Option<usize> {
        let mut whole = 0;
        for (v, integral) in self.train.iter().zip(&self.integrals) {
            let (w, h) = (v.camera.width as f32, v.camera.height as f32);
            let Some(r) = hole.image_rect(&v.camera) else {
                // the camera is inside or beside the cube: no margin can be checked
                return None;
            };
            if r[2] <= 0.0 || r[3] <= 0.0 || r[0] >= w || r[1] >= h {
                continue;
            }
            let (Some(mask), Some(integral)) = (&v.mask, integral) else {
                continue;
            };
            let (mx, my) = (MASK_MARGIN * (r[2] - r[0]), MASK_MARGIN * (r[3] - r[1]));
            let grown = [r[0] - mx, r[1] - my, r[2] + mx, r[3] + my];
            if count_in(integral, mask.width, mask.height, grown) > 0 {
                return None;
            }
            if r[0] >= 0.0 && r[1] >= 0.0 && r[2] <= w && r[3] <= h {
                whole += 1;
            }
        }
        (whole >= need).then_some(whole)
    }
}

/// The median of the surface points under the masks (the object's), if any.
fn object_centre(scene: &Scene, train: &[&View]) -> Option<[f32; 3]> {
    let mut pts = Vec::new();
    for v in train {
        for p in scene.sparse_depth.get(&v.name).into_iter().flatten() {
            if p.depth.is_finite() && p.depth > 0.0 && under_mask(v, p.x, p.y) {
                pts.push(v.camera.unproject(p.x, p.y, p.depth));
            }
        }
    }
    let axis = |i: usize| median(pts.iter().map(|p| p[i]).collect());
    Some([axis(0)?, axis(1)?, axis(2)?])
}

/// Each training view's withheld region of `hole` at full resolution (`None` where the hole
/// does not show).
pub fn withheld(scene: &Scene, hole: &PseudoHole) -> Vec<Option<Mask>> {
    scene
        .split(Split::Train)
        .map(|v| {
            let m = hole.mask(&v.camera);
            m.data.iter().any(|b| *b).then_some(m)
        })
        .collect()
}

/// Per training view, the union of the pseudo-holes' withheld regions (`None`: none shows).
pub fn union_per_view(each: &[Vec<Option<Mask>>]) -> Vec<Option<Mask>> {
    let views = each.first().map_or(0, Vec::len);
    (0..views)
        .map(|v| {
            each.iter()
                .filter_map(|h| h[v].as_ref())
                .fold(None, |acc: Option<Mask>, m| {
                    Some(match acc {
                        None => m.clone(),
                        Some(mut a) => {
                            a.data.iter_mut().zip(&m.data).for_each(|(x, y)| *x |= *y);
                            a
                        }
                    })
                })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> Camera {
        Camera {
            width: 40,
            height: 30,
            fx: 40.0,
            fy: 40.0,
            cx: 20.0,
            cy: 15.0,
            c2w: [
                [1.0, 0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 4.0],
            ],
        }
    }

    #[test]
    fn the_withheld_region_is_the_cubes_image_grown_by_a_pixel() {
        let c = camera();
        // a cube of side 1 at depth 4 (its front face at 3.5): 40 / 3.5 = 11.4 pixels wide
        let hole = PseudoHole::cube([0.0, 0.0, 0.0], 0.5);
        let m = hole.mask(&c);
        let row: Vec<bool> = (0..40).map(|x| m.data[15 * 40 + x]).collect();
        let n = row.iter().filter(|b| **b).count();
        // the front face spans 20 +- 5.71: pixels 14..=25 (12), grown by one on each side
        assert_eq!(n, 14, "{row:?}");
        assert!(row[13] && row[26] && !row[12] && !row[27]);
        // the point just inside the cube projects into the region
        let ([x, y], _) = c.project([0.49, 0.49, 0.49]).unwrap();
        assert!(m.data[y as usize * 40 + x as usize]);
        assert_eq!(c.unproject(30.0, 15.0, 4.0), [1.0, 0.0, 0.0]);
    }

    #[test]
    fn rays_beside_the_cube_miss_it() {
        let hole = PseudoHole::cube([0.0, 0.0, 0.0], 0.5);
        assert!(hole.hit([0.0, 0.0, 4.0], [0.0, 0.0, -1.0]));
        assert!(
            !hole.hit([0.0, 0.0, 4.0], [0.0, 0.0, 1.0]),
            "behind the camera"
        );
        assert!(!hole.hit([0.6, 0.0, 4.0], [0.0, 0.0, -1.0]));
        assert!(hole.hit([-2.0, 0.4, 0.0], [1.0, 0.0, 0.0]));
    }
}
