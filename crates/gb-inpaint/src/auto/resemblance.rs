//! How much a pseudo-hole's surroundings look like the real hole's (issue 45): colour and
//! texture statistics of the ring just outside the object's mask in the masked views, against
//! those of the ring just outside a candidate pseudo-hole's image in the same views.
//!
//! The statistics ([`Appearance`]) are each channel's mean and spread, and the texture's
//! energy: the mean absolute luminance difference to the right and below, over pairs of
//! pixels that both lie outside the object's mask (so the object's outline adds nothing).
//! Every sum comes from summed-area tables ([`ViewStats`]), so a candidate's ring costs the
//! same whatever its size.

use gb_core::RgbImage;
use gb_nerf::scene::Mask;
use serde::{Deserialize, Serialize};

/// Colour and texture statistics of a set of pixels (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Appearance {
    /// Mean of each channel, in [0, 1].
    pub mean: [f32; 3],
    /// Standard deviation of each channel.
    pub spread: [f32; 3],
    /// Mean absolute luminance difference between neighbours (the texture's energy).
    pub texture: f32,
}

impl Appearance {
    /// How unlike `other` this is: the Euclidean distances of the means and of the spreads,
    /// plus the difference of the texture energies, all in colour units (0: alike).
    pub fn distance(&self, other: &Appearance) -> f32 {
        let l2 =
            |a: [f32; 3], b: [f32; 3]| (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f32>().sqrt();
        l2(self.mean, other.mean)
            + l2(self.spread, other.spread)
            + (self.texture - other.texture).abs()
    }
}

/// Running sums over pixels: count, each channel's sum and sum of squares, and the texture
/// sum with its own count of pairs.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Sums {
    n: f64,
    sum: [f64; 3],
    squares: [f64; 3],
    texture: f64,
    pairs: f64,
}

impl Sums {
    fn from_slice(v: &[f64; CHANNELS]) -> Self {
        Self {
            n: v[0],
            sum: [v[1], v[2], v[3]],
            squares: [v[4], v[5], v[6]],
            texture: v[7],
            pairs: v[8],
        }
    }

    /// `self + other`.
    pub fn add(&self, o: &Sums) -> Sums {
        Sums {
            n: self.n + o.n,
            sum: std::array::from_fn(|c| self.sum[c] + o.sum[c]),
            squares: std::array::from_fn(|c| self.squares[c] + o.squares[c]),
            texture: self.texture + o.texture,
            pairs: self.pairs + o.pairs,
        }
    }

    /// `self - other` (the ring: a grown rectangle less the rectangle).
    pub fn sub(&self, o: &Sums) -> Sums {
        Sums {
            n: self.n - o.n,
            sum: std::array::from_fn(|c| self.sum[c] - o.sum[c]),
            squares: std::array::from_fn(|c| self.squares[c] - o.squares[c]),
            texture: self.texture - o.texture,
            pairs: self.pairs - o.pairs,
        }
    }

    /// The statistics, `None` without a pixel.
    pub fn appearance(&self) -> Option<Appearance> {
        if self.n < 1.0 {
            return None;
        }
        let mean: [f64; 3] = std::array::from_fn(|c| self.sum[c] / self.n);
        Some(Appearance {
            mean: mean.map(|m| m as f32),
            spread: std::array::from_fn(|c| {
                (self.squares[c] / self.n - mean[c] * mean[c])
                    .max(0.0)
                    .sqrt() as f32
            }),
            texture: if self.pairs > 0.0 {
                (self.texture / self.pairs) as f32
            } else {
                0.0
            },
        })
    }
}

/// Count, three sums, three sums of squares, texture sum, texture pairs.
const CHANNELS: usize = 9;

/// One view's summed-area tables of the [`Sums`] channels (module docs), `(w + 1) * (h + 1)`.
pub struct ViewStats {
    width: usize,
    height: usize,
    table: Vec<[f64; CHANNELS]>,
}

impl ViewStats {
    /// The tables of `image`, leaving out the pixels under `mask` (the object's) and every
    /// neighbour difference that touches one. Each difference counts half at each of its two
    /// pixels, so a rectangle's ring sees the pairs across all four of its edges alike.
    pub fn new(image: &RgbImage, mask: Option<&Mask>) -> Self {
        let (w, h) = (image.width, image.height);
        let out = |i: usize| mask.is_none_or(|m| !m.data[i]);
        let luma = |i: usize| {
            let p = &image.data[i * 3..i * 3 + 3];
            0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64
        };
        // per pixel: half of each difference to the right and below, and half a pair each
        let mut texture = vec![(0.0f64, 0.0f64); w * h];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if !out(i) {
                    continue;
                }
                let right = (x + 1 < w).then_some(i + 1);
                let below = (y + 1 < h).then_some(i + w);
                for j in [right, below].into_iter().flatten().filter(|&j| out(j)) {
                    let d = 0.5 * (luma(i) - luma(j)).abs();
                    for k in [i, j] {
                        texture[k].0 += d;
                        texture[k].1 += 0.5;
                    }
                }
            }
        }
        let at = |x: usize, y: usize| y * (w + 1) + x;
        let mut table = vec![[0.0f64; CHANNELS]; (w + 1) * (h + 1)];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let mut v = [0.0f64; CHANNELS];
                if out(i) {
                    v[0] = 1.0;
                    for c in 0..3 {
                        let p = image.data[i * 3 + c] as f64;
                        v[1 + c] = p;
                        v[4 + c] = p * p;
                    }
                    (v[7], v[8]) = texture[i];
                }
                let (up, left, diag) = (table[at(x + 1, y)], table[at(x, y + 1)], table[at(x, y)]);
                table[at(x + 1, y + 1)] = std::array::from_fn(|k| v[k] + up[k] + left[k] - diag[k]);
            }
        }
        Self {
            width: w,
            height: h,
            table,
        }
    }

    /// The sums over the rectangle `(x0, y0, x1, y1)` in continuous pixels, clipped to the
    /// image (pixels whose index lies in `[floor(x0), ceil(x1))`).
    pub fn rect(&self, r: [f32; 4]) -> Sums {
        let clip = |v: f32, n: usize| (v.max(0.0) as usize).min(n);
        let (x0, y0) = (
            clip(r[0].floor(), self.width),
            clip(r[1].floor(), self.height),
        );
        let (x1, y1) = (
            clip(r[2].ceil(), self.width),
            clip(r[3].ceil(), self.height),
        );
        if x1 <= x0 || y1 <= y0 {
            return Sums::default();
        }
        let at = |x: usize, y: usize| &self.table[y * (self.width + 1) + x];
        let (a, b, c, d) = (at(x1, y1), at(x0, y0), at(x0, y1), at(x1, y0));
        Sums::from_slice(&std::array::from_fn(|k| a[k] + b[k] - c[k] - d[k]))
    }

    /// The sums over the pixels within `width` pixels of `mask` (a square neighbourhood,
    /// [`gb_nerf::scene::masks::dilate`]), not under it: the ring just outside the object.
    pub fn ring(&self, mask: &Mask, width: usize) -> Sums {
        let grown = gb_nerf::scene::masks::dilate(mask, width);
        let w = mask.width;
        (0..w * mask.height)
            .filter(|&i| grown.data[i] && !mask.data[i])
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                self.rect([x, y, x + 1.0, y + 1.0])
            })
            .fold(Sums::default(), |a, b| a.add(&b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: usize, h: usize, f: impl Fn(usize, usize) -> [f32; 3]) -> RgbImage {
        RgbImage {
            width: w,
            height: h,
            data: (0..w * h).flat_map(|i| f(i % w, i / w)).collect(),
        }
    }

    #[test]
    fn a_flat_region_has_its_colour_no_spread_and_no_texture() {
        let img = image(8, 6, |_, _| [0.2, 0.4, 0.6]);
        let a = ViewStats::new(&img, None)
            .rect([1.0, 1.0, 5.0, 4.0])
            .appearance()
            .unwrap();
        assert!((a.mean[1] - 0.4).abs() < 1e-6 && a.spread[0] < 1e-3 && a.texture < 1e-6);
    }

    #[test]
    fn stripes_have_their_mean_spread_and_texture_and_the_ring_skips_the_mask() {
        // columns alternate 0 and 1: mean 0.5, spread 0.5, luminance step 1 to the right only
        let img = image(10, 10, |x, _| [(x % 2) as f32; 3]);
        let stats = ViewStats::new(&img, None);
        let a = stats.rect([0.0, 0.0, 10.0, 10.0]).appearance().unwrap();
        assert!((a.mean[0] - 0.5).abs() < 1e-6 && (a.spread[2] - 0.5).abs() < 1e-6);
        // 90 horizontal pairs of step 1, 90 vertical of step 0
        assert!((a.texture - 0.5).abs() < 1e-6, "{}", a.texture);
        // a 2x2 mask in the middle, ring of width 1: the 4x4 square less the mask
        let mut m = Mask {
            width: 10,
            height: 10,
            data: vec![false; 100],
        };
        for (x, y) in [(4, 4), (5, 4), (4, 5), (5, 5)] {
            m.data[y * 10 + x] = true;
        }
        let masked = ViewStats::new(&img, Some(&m));
        let ring = masked.ring(&m, 1);
        assert_eq!(ring.n, 12.0);
        // the object's pixels count nowhere
        assert_eq!(masked.rect([0.0, 0.0, 10.0, 10.0]).n, 96.0);
        assert!(Appearance::distance(&a, &ring.appearance().unwrap()) < 0.1);
        let flat = image(10, 10, |_, _| [0.5; 3]);
        let b = ViewStats::new(&flat, None)
            .rect([0.0, 0.0, 10.0, 10.0])
            .appearance()
            .unwrap();
        // same mean, no spread, no texture: 0.5 * sqrt(3) + 0.5
        assert!((a.distance(&b) - (0.5 * 3f32.sqrt() + 0.5)).abs() < 1e-5);
    }
}
