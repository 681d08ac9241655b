//! A hand-held-looking forward-facing arc of pinhole cameras (OpenGL axes, f64).
// Component loops over xyz / matrix entries read clearer with indices than with zips.
#![allow(clippy::needless_range_loop)]

use super::geometry::{cross, dot, normalize, sub, Ray, V3};
use super::scenes::Rig;
use crate::scene::Camera;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A pinhole camera in f64: principal point at the image centre, square pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinholeF64 {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Focal length in pixels.
    pub focal: f64,
    /// Camera-to-world `[R | t]`, OpenGL axes (x right, y up, z back).
    pub c2w: [[f64; 4]; 3],
}

impl PinholeF64 {
    /// The camera centre.
    pub fn origin(&self) -> V3 {
        [self.c2w[0][3], self.c2w[1][3], self.c2w[2][3]]
    }

    /// The viewing direction (-z axis) in world space.
    pub fn forward(&self) -> V3 {
        [-self.c2w[0][2], -self.c2w[1][2], -self.c2w[2][2]]
    }

    /// The unit ray through continuous pixel coordinates `(px, py)`.
    pub fn ray(&self, px: f64, py: f64) -> Ray {
        let (cx, cy) = (self.width as f64 / 2.0, self.height as f64 / 2.0);
        let d = [(px - cx) / self.focal, -(py - cy) / self.focal, -1.0];
        let r = &self.c2w;
        let w = [
            r[0][0] * d[0] + r[0][1] * d[1] + r[0][2] * d[2],
            r[1][0] * d[0] + r[1][1] * d[1] + r[1][2] * d[2],
            r[2][0] * d[0] + r[2][1] * d[1] + r[2][2] * d[2],
        ];
        Ray {
            origin: self.origin(),
            dir: normalize(w),
        }
    }

    /// World direction to camera coordinates (`R^T d`).
    pub fn to_camera(&self, d: V3) -> V3 {
        let r = &self.c2w;
        [
            r[0][0] * d[0] + r[1][0] * d[1] + r[2][0] * d[2],
            r[0][1] * d[0] + r[1][1] * d[1] + r[2][1] * d[2],
            r[0][2] * d[0] + r[1][2] * d[1] + r[2][2] * d[2],
        ]
    }

    /// The f32 scene-model camera.
    pub fn to_camera_model(&self) -> Camera {
        let mut c2w = [[0.0f32; 4]; 3];
        for i in 0..3 {
            for j in 0..4 {
                c2w[i][j] = self.c2w[i][j] as f32;
            }
        }
        Camera {
            width: self.width,
            height: self.height,
            fx: self.focal as f32,
            fy: self.focal as f32,
            cx: self.width as f32 / 2.0,
            cy: self.height as f32 / 2.0,
            c2w,
        }
    }
}

/// A camera looking from `eye` at `at`, world up +y, rolled by `roll` radians.
pub fn look_at(eye: V3, at: V3, roll: f64, width: usize, height: usize, focal: f64) -> PinholeF64 {
    let back = normalize(sub(eye, at));
    let right0 = normalize(cross([0.0, 1.0, 0.0], back));
    let up0 = cross(back, right0);
    let (s, c) = roll.sin_cos();
    let right = [
        c * right0[0] + s * up0[0],
        c * right0[1] + s * up0[1],
        c * right0[2] + s * up0[2],
    ];
    let up = cross(back, right);
    debug_assert!(dot(right, back).abs() < 1e-9);
    PinholeF64 {
        width,
        height,
        focal,
        c2w: [
            [right[0], up[0], back[0], eye[0]],
            [right[1], up[1], back[1], eye[1]],
            [right[2], up[2], back[2], eye[2]],
        ],
    }
}

/// `n` cameras along the rig's arc, in arc order, with a seeded hand-held wobble: a smooth
/// elevation sway plus small random offsets of the position (2% of the radius), the look-at
/// point (5 cm) and the roll (1 degree).
pub fn arc(rig: &Rig, n: usize, width: usize, height: usize, seed: u64) -> Vec<PinholeF64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6361_6d65_7261_7300);
    let focal = 0.5 * width as f64 / (0.5 * rig.hfov_deg.to_radians()).tan();
    (0..n)
        .map(|j| {
            let u = if n > 1 {
                j as f64 / (n - 1) as f64
            } else {
                0.5
            };
            let az = (rig.azimuth_deg.0 + (rig.azimuth_deg.1 - rig.azimuth_deg.0) * u).to_radians();
            let el =
                (rig.elevation_deg + 2.5 * (std::f64::consts::TAU * 1.5 * u).sin()).to_radians();
            let mut eye = [
                rig.target[0] + rig.radius * az.sin() * el.cos(),
                rig.target[1] + rig.radius * el.sin(),
                rig.target[2] + rig.radius * az.cos() * el.cos(),
            ];
            for v in &mut eye {
                *v += rng.random_range(-0.02..0.02) * rig.radius;
            }
            let mut at = rig.target;
            for v in &mut at {
                *v += rng.random_range(-0.05..0.05);
            }
            let roll = rng.random_range(-1.0f64..1.0).to_radians();
            look_at(eye, at, roll, width, height, focal)
        })
        .collect()
}

/// Which of `n` arc positions are test views: `k` positions spread evenly along the arc
/// (so test views lie between training views).
pub fn test_positions(n: usize, k: usize) -> Vec<usize> {
    let k = k.min(n);
    let mut out: Vec<usize> = (0..k)
        .map(|i| (((i as f64 + 0.5) * n as f64 / k as f64) - 0.5).round() as usize)
        .map(|j| j.min(n - 1))
        .collect();
    out.dedup();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn look_at_centre_ray_hits_the_target_direction() {
        let cam = look_at([1.0, 2.0, 5.0], [0.0, 0.5, 0.0], 0.0, 64, 48, 50.0);
        let r = cam.ray(32.0, 24.0);
        let want = normalize(sub([0.0, 0.5, 0.0], [1.0, 2.0, 5.0]));
        for i in 0..3 {
            assert!((r.dir[i] - want[i]).abs() < 1e-12);
        }
        // the model camera agrees
        let m = cam.to_camera_model();
        let d = m.ray_direction(10.0, 7.0);
        let d64 = cam.ray(10.0, 7.0).dir;
        for i in 0..3 {
            assert!((d[i] as f64 - d64[i]).abs() < 1e-6);
        }
    }

    #[test]
    fn test_positions_are_spread_and_distinct() {
        assert_eq!(test_positions(24, 8), vec![1, 4, 7, 10, 13, 16, 19, 22]);
        assert_eq!(test_positions(10, 0), Vec::<usize>::new());
        assert_eq!(test_positions(3, 3), vec![0, 1, 2]);
    }
}
