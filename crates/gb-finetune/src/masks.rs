//! Random inpainting masks for the self-supervised loss: rectangles, rotated ellipses and
//! free-form brush strokes (a polyline of thick round segments, as in LaMa's and
//! SD-inpainting's training masks).
//!
//! A mask is `Vec<f32>` `[h * w]`, row-major: **1 = hole to inpaint, 0 = keep**. Pixel
//! `(x, y)` is in a shape when its centre `(x + 0.5, y + 0.5)` is.
//!
//! **Coverage guarantee**: every mask from [`MaskGenerator::sample`] has its hole fraction in
//! `[min_coverage, max_coverage]` (to the pixel: the hole has between
//! `ceil(min * w * h)` and `max(floor(max * w * h), ceil(min * w * h))` pixels). The
//! generator draws a target coverage uniformly in the range and adds shapes of one kind, each
//! sized for what is still missing, until the target is reached; a shape that would push the
//! hole above the maximum is dropped and the next one is drawn smaller. After a bounded
//! number of shapes, a mask still below the minimum is grown by one-pixel dilation rings
//! (and finally pixel by pixel along its border) — every loop is bounded, nothing re-draws
//! forever.

use crate::FinetuneError;
use rand::Rng;
use serde::{Deserialize, Serialize};
use std::f32::consts::PI;

/// The shape family of a mask.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MaskKind {
    /// Union of axis-aligned rectangles.
    Rectangles,
    /// Union of rotated ellipses.
    Ellipses,
    /// Free-form brush strokes: polylines of thick segments with round caps and joints.
    Strokes,
}

impl MaskKind {
    /// Every kind.
    pub const ALL: [MaskKind; 3] = [MaskKind::Rectangles, MaskKind::Ellipses, MaskKind::Strokes];

    /// Its name in configs: `rectangles`, `ellipses`, `strokes`.
    pub fn as_str(&self) -> &'static str {
        match self {
            MaskKind::Rectangles => "rectangles",
            MaskKind::Ellipses => "ellipses",
            MaskKind::Strokes => "strokes",
        }
    }
}

impl std::fmt::Display for MaskKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for MaskKind {
    type Err = FinetuneError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "rectangles" | "rectangle" | "rect" => Ok(MaskKind::Rectangles),
            "ellipses" | "ellipse" => Ok(MaskKind::Ellipses),
            "strokes" | "stroke" | "brush" => Ok(MaskKind::Strokes),
            other => Err(FinetuneError::Config {
                field: "masks.kinds".into(),
                message: format!(
                    "unknown mask kind '{other}' (expected rectangles, ellipses or strokes)"
                ),
            }),
        }
    }
}

/// Settings of the mask generator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct MaskConfig {
    /// Smallest hole fraction (default 0.05).
    pub min_coverage: f32,
    /// Largest hole fraction (default 0.6).
    pub max_coverage: f32,
    /// Shape families, one drawn uniformly per mask (default: all three).
    pub kinds: Vec<MaskKind>,
}

impl Default for MaskConfig {
    fn default() -> Self {
        Self {
            min_coverage: 0.05,
            max_coverage: 0.6,
            kinds: MaskKind::ALL.to_vec(),
        }
    }
}

impl MaskConfig {
    /// Checks `0 <= min <= max <= 1`, `max > 0` and a non-empty kind list.
    pub fn validate(&self) -> Result<(), FinetuneError> {
        let bad = |field: &str, message: String| FinetuneError::Config {
            field: field.into(),
            message,
        };
        if !(self.min_coverage.is_finite() && (0.0..=1.0).contains(&self.min_coverage)) {
            return Err(bad(
                "masks.min_coverage",
                format!("{} is not in [0, 1]", self.min_coverage),
            ));
        }
        if !(self.max_coverage.is_finite() && self.max_coverage > 0.0 && self.max_coverage <= 1.0) {
            return Err(bad(
                "masks.max_coverage",
                format!("{} is not in (0, 1]", self.max_coverage),
            ));
        }
        if self.min_coverage > self.max_coverage {
            return Err(bad(
                "masks.min_coverage",
                format!(
                    "{} is larger than max_coverage {}",
                    self.min_coverage, self.max_coverage
                ),
            ));
        }
        if self.kinds.is_empty() {
            return Err(bad("masks.kinds", "no mask kind given".into()));
        }
        Ok(())
    }
}

/// Most shapes added to one mask before the deterministic growth takes over.
const MAX_SHAPES: usize = 48;

/// Draws random inpainting masks (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct MaskGenerator {
    config: MaskConfig,
}

/// The pixel-count bounds of the coverage range for `n` pixels.
fn count_bounds(cfg: &MaskConfig, n: usize) -> (usize, usize) {
    let nf = n as f64;
    let lo = ((cfg.min_coverage as f64 * nf) - 1e-9).ceil().max(0.0) as usize;
    let hi = ((cfg.max_coverage as f64 * nf) + 1e-9).floor() as usize;
    let lo = lo.min(n);
    (lo, hi.max(lo).min(n))
}

/// A canvas of hole pixels with a running count.
struct Canvas {
    w: usize,
    h: usize,
    px: Vec<bool>,
    count: usize,
}

impl Canvas {
    /// Pixels that `shape` would add, without adding them.
    fn added(&self, shape: &Shape) -> Vec<usize> {
        let (x0, y0, x1, y1) = shape.bbox(self.w, self.h);
        let mut out = Vec::new();
        for y in y0..y1 {
            for x in x0..x1 {
                let i = y * self.w + x;
                if !self.px[i] && shape.contains(x as f32 + 0.5, y as f32 + 0.5) {
                    out.push(i);
                }
            }
        }
        out
    }

    fn set(&mut self, idx: &[usize]) {
        for &i in idx {
            if !self.px[i] {
                self.px[i] = true;
                self.count += 1;
            }
        }
    }

    /// Unset pixels with a 4-neighbour in the hole, in raster order.
    fn border(&self) -> Vec<usize> {
        let (w, h) = (self.w, self.h);
        let mut out = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if self.px[i] {
                    continue;
                }
                let near = (x > 0 && self.px[i - 1])
                    || (x + 1 < w && self.px[i + 1])
                    || (y > 0 && self.px[i - w])
                    || (y + 1 < h && self.px[i + w]);
                if near {
                    out.push(i);
                }
            }
        }
        out
    }
}

/// One primitive shape in continuous pixel coordinates.
enum Shape {
    Rect {
        x0: f32,
        y0: f32,
        x1: f32,
        y1: f32,
    },
    Ellipse {
        cx: f32,
        cy: f32,
        a: f32,
        b: f32,
        cos: f32,
        sin: f32,
    },
    /// Polyline with a round brush of radius `r`.
    Stroke {
        pts: Vec<(f32, f32)>,
        r: f32,
    },
}

fn seg_dist2(px: f32, py: f32, a: (f32, f32), b: (f32, f32)) -> f32 {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let l2 = dx * dx + dy * dy;
    let t = if l2 > 0.0 {
        (((px - a.0) * dx + (py - a.1) * dy) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (qx, qy) = (a.0 + t * dx - px, a.1 + t * dy - py);
    qx * qx + qy * qy
}

impl Shape {
    /// Integer pixel bounds `[x0, x1) x [y0, y1)` clipped to the image.
    fn bbox(&self, w: usize, h: usize) -> (usize, usize, usize, usize) {
        let (lx, ly, hx, hy) = match self {
            Shape::Rect { x0, y0, x1, y1 } => (*x0, *y0, *x1, *y1),
            Shape::Ellipse { cx, cy, a, .. } => (cx - a, cy - a, cx + a, cy + a),
            Shape::Stroke { pts, r } => pts.iter().fold(
                (
                    f32::INFINITY,
                    f32::INFINITY,
                    f32::NEG_INFINITY,
                    f32::NEG_INFINITY,
                ),
                |(a, b, c, d), p| {
                    (
                        a.min(p.0 - r),
                        b.min(p.1 - r),
                        c.max(p.0 + r),
                        d.max(p.1 + r),
                    )
                },
            ),
        };
        let clip = |v: f32, n: usize| (v.max(0.0) as usize).min(n);
        (
            clip(lx.floor(), w),
            clip(ly.floor(), h),
            clip(hx.ceil() + 1.0, w),
            clip(hy.ceil() + 1.0, h),
        )
    }

    fn contains(&self, x: f32, y: f32) -> bool {
        match self {
            Shape::Rect { x0, y0, x1, y1 } => x >= *x0 && x < *x1 && y >= *y0 && y < *y1,
            Shape::Ellipse {
                cx,
                cy,
                a,
                b,
                cos,
                sin,
            } => {
                let (dx, dy) = (x - cx, y - cy);
                let u = dx * cos + dy * sin;
                let v = -dx * sin + dy * cos;
                (u / a).powi(2) + (v / b).powi(2) <= 1.0
            }
            Shape::Stroke { pts, r } => {
                let r2 = r * r;
                if pts.len() == 1 {
                    return seg_dist2(x, y, pts[0], pts[0]) <= r2;
                }
                pts.windows(2).any(|s| seg_dist2(x, y, s[0], s[1]) <= r2)
            }
        }
    }
}

/// A shape of `kind` with an expected area of about `area` pixels, placed at random.
fn draw_shape<R: Rng + ?Sized>(
    rng: &mut R,
    kind: MaskKind,
    area: f32,
    w: usize,
    h: usize,
) -> Shape {
    let (wf, hf) = (w as f32, h as f32);
    let area = area.max(1.0);
    // aspect ratio, log-uniform in [1/3, 3]
    let aspect = (rng.random_range(-1.0f32..=1.0) * 3f32.ln()).exp();
    match kind {
        MaskKind::Rectangles => {
            let rw = (area * aspect).sqrt().clamp(1.0, wf);
            let rh = (area / rw).clamp(1.0, hf);
            let x0 = rng.random_range(0.0..=(wf - rw).max(0.0));
            let y0 = rng.random_range(0.0..=(hf - rh).max(0.0));
            Shape::Rect {
                x0,
                y0,
                x1: x0 + rw,
                y1: y0 + rh,
            }
        }
        MaskKind::Ellipses => {
            let a = (area * aspect / PI).sqrt().clamp(0.75, wf.max(hf));
            let b = (area / (PI * a)).clamp(0.75, wf.max(hf));
            let theta = rng.random_range(0.0..PI);
            Shape::Ellipse {
                cx: rng.random_range(0.0..=wf),
                cy: rng.random_range(0.0..=hf),
                a,
                b,
                cos: theta.cos(),
                sin: theta.sin(),
            }
        }
        MaskKind::Strokes => {
            let side = wf.min(hf);
            // brush radius: 1.5% .. 6% of the short side, at least one pixel
            let r = (side * rng.random_range(0.015f32..0.06)).max(1.0);
            // length so that 2 r L ~ area, split over 2..8 segments
            let length = area / (2.0 * r);
            let segments = rng.random_range(2usize..=8);
            let seg = (length / segments as f32).max(1.0);
            let mut p = (rng.random_range(0.0..=wf), rng.random_range(0.0..=hf));
            let mut angle = rng.random_range(0.0..2.0 * PI);
            let mut pts = vec![p];
            for _ in 0..segments {
                angle += rng.random_range(-0.6 * PI..0.6 * PI);
                let l = seg * rng.random_range(0.7f32..1.3);
                let mut q = (p.0 + l * angle.cos(), p.1 + l * angle.sin());
                // bounce off the image border so that strokes stay inside
                if q.0 < 0.0 || q.0 > wf {
                    angle = PI - angle;
                    q.0 = q.0.clamp(0.0, wf);
                }
                if q.1 < 0.0 || q.1 > hf {
                    angle = -angle;
                    q.1 = q.1.clamp(0.0, hf);
                }
                pts.push(q);
                p = q;
            }
            Shape::Stroke { pts, r }
        }
    }
}

impl MaskGenerator {
    /// A generator with a validated configuration.
    pub fn new(config: MaskConfig) -> Result<Self, FinetuneError> {
        config.validate()?;
        Ok(Self { config })
    }

    /// Its configuration.
    pub fn config(&self) -> &MaskConfig {
        &self.config
    }

    /// A mask `[height * width]` (1 = hole) of a kind drawn uniformly from the configured
    /// kinds, with its coverage in the configured range (see the module docs). An empty
    /// image gives an empty vector.
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R, width: usize, height: usize) -> Vec<f32> {
        let kind = self.config.kinds[rng.random_range(0..self.config.kinds.len())];
        self.sample_kind(rng, kind, width, height)
    }

    /// A mask of one given kind (see [`MaskGenerator::sample`]).
    pub fn sample_kind<R: Rng + ?Sized>(
        &self,
        rng: &mut R,
        kind: MaskKind,
        width: usize,
        height: usize,
    ) -> Vec<f32> {
        let n = width * height;
        if n == 0 {
            return Vec::new();
        }
        let (lo, hi) = count_bounds(&self.config, n);
        // target pixel count, uniform in [lo, hi]
        let target = rng.random_range(lo..=hi);
        let mut canvas = Canvas {
            w: width,
            h: height,
            px: vec![false; n],
            count: 0,
        };
        let mut shrink = 1.0f32;
        for _ in 0..MAX_SHAPES {
            if canvas.count >= target {
                break;
            }
            let missing = (target - canvas.count) as f32;
            // each shape covers 60%..140% of what is missing (overlap makes it less)
            let area = missing * rng.random_range(0.6f32..1.4) * shrink;
            let shape = draw_shape(rng, kind, area, width, height);
            let added = canvas.added(&shape);
            if canvas.count + added.len() > hi {
                shrink *= 0.5;
                continue;
            }
            canvas.set(&added);
        }
        grow_to(&mut canvas, lo, hi, rng);
        canvas
            .px
            .iter()
            .map(|&b| if b { 1.0 } else { 0.0 })
            .collect()
    }
}

/// Deterministic growth up to `lo` pixels without exceeding `hi`: whole dilation rings while
/// they fit, then single border pixels (a random pixel when the mask is empty).
fn grow_to<R: Rng + ?Sized>(canvas: &mut Canvas, lo: usize, hi: usize, rng: &mut R) {
    if canvas.count >= lo {
        return;
    }
    if canvas.count == 0 {
        let i = rng.random_range(0..canvas.px.len());
        canvas.set(&[i]);
    }
    // at most w + h rings can be needed to fill the image
    for _ in 0..(canvas.w + canvas.h) {
        if canvas.count >= lo {
            return;
        }
        let ring = canvas.border();
        if ring.is_empty() {
            break;
        }
        if canvas.count + ring.len() <= hi {
            canvas.set(&ring);
        } else {
            let need = lo - canvas.count;
            canvas.set(&ring[..need.min(ring.len())]);
        }
    }
    // a ring never falls short of the need while the border is non-empty and the mask is
    // connected to the rest of the image; as a last resort fill remaining pixels in order
    if canvas.count < lo {
        let free: Vec<usize> = (0..canvas.px.len()).filter(|&i| !canvas.px[i]).collect();
        let need = lo - canvas.count;
        canvas.set(&free[..need.min(free.len())]);
    }
}

/// The hole fraction of a mask (`mean(mask > 0.5)`); 0 for an empty mask.
pub fn coverage(mask: &[f32]) -> f32 {
    if mask.is_empty() {
        return 0.0;
    }
    mask.iter().filter(|&&v| v > 0.5).count() as f32 / mask.len() as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn tiny_and_extreme_ranges_hold() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for (lo, hi) in [(0.0, 0.01), (0.99, 1.0), (0.5, 0.5), (0.3, 0.31)] {
            let g = MaskGenerator::new(MaskConfig {
                min_coverage: lo,
                max_coverage: hi,
                kinds: MaskKind::ALL.to_vec(),
            })
            .unwrap();
            for (w, h) in [(1, 1), (5, 3), (32, 17)] {
                for _ in 0..20 {
                    let m = g.sample(&mut rng, w, h);
                    let (clo, chi) = count_bounds(g.config(), w * h);
                    let c = m.iter().filter(|&&v| v > 0.5).count();
                    assert!(
                        c >= clo && c <= chi,
                        "{lo}..{hi} at {w}x{h}: {c} not in {clo}..{chi}"
                    );
                }
            }
        }
    }

    #[test]
    fn bad_configs_are_errors() {
        for (lo, hi) in [(-0.1, 0.5), (0.6, 0.5), (0.1, 1.5), (0.0, 0.0)] {
            let e = MaskGenerator::new(MaskConfig {
                min_coverage: lo,
                max_coverage: hi,
                ..Default::default()
            })
            .unwrap_err();
            assert!(e.to_string().contains("masks."), "{e}");
        }
        let e = MaskGenerator::new(MaskConfig {
            kinds: vec![],
            ..Default::default()
        })
        .unwrap_err();
        assert!(e.to_string().contains("masks.kinds"), "{e}");
    }
}
