//! Solid (3D) procedural textures: the colour is a function of the world position only, so
//! every view sees the same surface colour.

use super::geometry::V3;

/// An RGB colour in [0, 1].
pub type Rgb = [f64; 3];

/// A procedural texture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Texture {
    /// One colour.
    Solid(Rgb),
    /// A 3D checkerboard with cells of size `cell`.
    Checker {
        /// First colour.
        a: Rgb,
        /// Second colour.
        b: Rgb,
        /// Cell size.
        cell: f64,
    },
    /// Wood-like grain: smooth value noise stretched along x, mixed between two colours.
    Grain {
        /// Dark colour.
        a: Rgb,
        /// Light colour.
        b: Rgb,
        /// Spatial frequency.
        freq: f64,
        /// Noise seed.
        seed: u32,
    },
    /// Bricks in the x-y plane (for walls facing +z).
    Bricks {
        /// Brick colour.
        brick: Rgb,
        /// Mortar colour.
        mortar: Rgb,
        /// Brick width.
        width: f64,
        /// Brick height.
        height: f64,
        /// Noise seed (per-brick shade).
        seed: u32,
    },
    /// Multi-octave value noise mixed between two colours (grass, stone).
    Noise {
        /// First colour.
        a: Rgb,
        /// Second colour.
        b: Rgb,
        /// Base frequency.
        freq: f64,
        /// Noise seed.
        seed: u32,
    },
}

fn mix(a: Rgb, b: Rgb, s: f64) -> Rgb {
    [
        a[0] + (b[0] - a[0]) * s,
        a[1] + (b[1] - a[1]) * s,
        a[2] + (b[2] - a[2]) * s,
    ]
}

/// A deterministic hash of integer lattice coordinates to [0, 1).
pub fn lattice(ix: i64, iy: i64, iz: i64, seed: u32) -> f64 {
    let mut h = (ix as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (iy as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (iz as u64).wrapping_mul(0x1656_67B1_9E37_79F9)
        ^ u64::from(seed).wrapping_mul(0x27D4_EB2F_1656_67C5);
    h ^= h >> 33;
    h = h.wrapping_mul(0xFF51_AFD7_ED55_8CCD);
    h ^= h >> 33;
    h = h.wrapping_mul(0xC4CE_B9FE_1A85_EC53);
    h ^= h >> 33;
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Trilinear value noise in [0, 1] with a smoothstep fade.
pub fn value_noise(p: V3, seed: u32) -> f64 {
    let f = [p[0].floor(), p[1].floor(), p[2].floor()];
    let i = [f[0] as i64, f[1] as i64, f[2] as i64];
    let fr = [p[0] - f[0], p[1] - f[1], p[2] - f[2]];
    let s = [fade(fr[0]), fade(fr[1]), fade(fr[2])];
    let mut acc = 0.0;
    for c in 0..8 {
        let (dx, dy, dz) = ((c & 1) as i64, ((c >> 1) & 1) as i64, ((c >> 2) & 1) as i64);
        let w = (if dx == 1 { s[0] } else { 1.0 - s[0] })
            * (if dy == 1 { s[1] } else { 1.0 - s[1] })
            * (if dz == 1 { s[2] } else { 1.0 - s[2] });
        acc += w * lattice(i[0] + dx, i[1] + dy, i[2] + dz, seed);
    }
    acc
}

fn fade(t: f64) -> f64 {
    t * t * (3.0 - 2.0 * t)
}

fn fbm(p: V3, seed: u32) -> f64 {
    let (mut amp, mut f, mut acc, mut norm) = (0.5, 1.0, 0.0, 0.0);
    for o in 0..4 {
        acc += amp * value_noise([p[0] * f, p[1] * f, p[2] * f], seed.wrapping_add(o));
        norm += amp;
        amp *= 0.5;
        f *= 2.0;
    }
    acc / norm
}

impl Texture {
    /// The albedo at world point `p`.
    pub fn albedo(&self, p: V3) -> Rgb {
        match *self {
            Texture::Solid(c) => c,
            Texture::Checker { a, b, cell } => {
                let s = (p[0] / cell).floor() as i64
                    + (p[1] / cell).floor() as i64
                    + (p[2] / cell).floor() as i64;
                if s.rem_euclid(2) == 0 {
                    a
                } else {
                    b
                }
            }
            Texture::Grain { a, b, freq, seed } => {
                let n = fbm([p[0] * freq * 0.15, p[1] * freq, p[2] * freq], seed);
                let rings = (n * 12.0).fract();
                mix(a, b, 0.6 * rings + 0.4 * n)
            }
            Texture::Bricks {
                brick,
                mortar,
                width,
                height,
                seed,
            } => {
                let row = (p[1] / height).floor();
                let shift = if (row as i64).rem_euclid(2) == 1 {
                    0.5 * width
                } else {
                    0.0
                };
                let col = ((p[0] + shift) / width).floor();
                let (fx, fy) = ((p[0] + shift) / width - col, p[1] / height - row);
                let m = 0.06;
                if fx < m * height / width || fy < m {
                    mortar
                } else {
                    let shade = 0.75 + 0.5 * lattice(col as i64, row as i64, 0, seed);
                    let n =
                        0.85 + 0.3 * value_noise([p[0] * 8.0, p[1] * 8.0, p[2] * 8.0], seed ^ 0x55);
                    let k = (shade * n).min(1.3);
                    [
                        (brick[0] * k).min(1.0),
                        (brick[1] * k).min(1.0),
                        (brick[2] * k).min(1.0),
                    ]
                }
            }
            Texture::Noise { a, b, freq, seed } => {
                mix(a, b, fbm([p[0] * freq, p[1] * freq, p[2] * freq], seed))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_deterministic_bounded_and_seeded() {
        for i in 0..200 {
            let p = [i as f64 * 0.37, -(i as f64) * 0.11, 1.5];
            let v = value_noise(p, 7);
            assert!((0.0..=1.0).contains(&v));
            assert_eq!(v, value_noise(p, 7));
        }
        let differs = (0..50)
            .filter(|&i| {
                value_noise([i as f64 + 0.5, 0.5, 0.5], 1)
                    != value_noise([i as f64 + 0.5, 0.5, 0.5], 2)
            })
            .count();
        assert!(differs > 40);
    }

    #[test]
    fn checker_alternates() {
        let t = Texture::Checker {
            a: [0.0; 3],
            b: [1.0; 3],
            cell: 1.0,
        };
        assert_eq!(t.albedo([0.5, 0.5, 0.5]), [0.0; 3]);
        assert_eq!(t.albedo([1.5, 0.5, 0.5]), [1.0; 3]);
        assert_eq!(t.albedo([-0.5, 0.5, 0.5]), [1.0; 3]);
    }
}
