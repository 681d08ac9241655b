//! Pixel sets and the rays through them: random pixels, masked pixels, whole images and the
//! mask's bounding-box crop resampled to a fixed size.

use rand::Rng;

use crate::sampler::{RayBatch, SceneSpace};
use crate::scene::{Camera, Mask};

/// Continuous pixel coordinates of every pixel centre, row-major.
pub fn all_pixels(width: usize, height: usize) -> Vec<[f32; 2]> {
    let mut out = Vec::with_capacity(width * height);
    for y in 0..height {
        for x in 0..width {
            out.push([x as f32 + 0.5, y as f32 + 0.5]);
        }
    }
    out
}

/// The centres of the pixels inside `mask`, row-major.
pub fn masked_pixels(mask: &Mask) -> Vec<[f32; 2]> {
    let mut out = Vec::new();
    for y in 0..mask.height {
        for x in 0..mask.width {
            if mask.data[y * mask.width + x] {
                out.push([x as f32 + 0.5, y as f32 + 0.5]);
            }
        }
    }
    out
}

/// `n` uniformly random pixel centres.
pub fn random_pixels<R: Rng>(width: usize, height: usize, n: usize, rng: &mut R) -> Vec<[f32; 2]> {
    (0..n)
        .map(|_| {
            [
                rng.random_range(0..width) as f32 + 0.5,
                rng.random_range(0..height) as f32 + 0.5,
            ]
        })
        .collect()
}

/// The camera whose `out_w x out_h` image is the box `(x0, y0, x1, y1)` (exclusive ends, in
/// pixels of `camera`) resampled: rendering it renders the crop.
pub fn crop_camera(
    camera: &Camera,
    bbox: (usize, usize, usize, usize),
    out_w: usize,
    out_h: usize,
) -> Camera {
    let (x0, y0, x1, y1) = bbox;
    let sx = out_w as f32 / (x1.saturating_sub(x0)).max(1) as f32;
    let sy = out_h as f32 / (y1.saturating_sub(y0)).max(1) as f32;
    Camera {
        width: out_w,
        height: out_h,
        fx: camera.fx * sx,
        fy: camera.fy * sy,
        cx: (camera.cx - x0 as f32) * sx,
        cy: (camera.cy - y0 as f32) * sy,
        c2w: camera.c2w,
    }
}

/// Pixel centres of `camera`'s image of the crop `bbox` resampled to `out_w x out_h`,
/// expressed in `camera`'s own pixel coordinates.
pub fn crop_pixels(
    bbox: (usize, usize, usize, usize),
    out_w: usize,
    out_h: usize,
) -> Vec<[f32; 2]> {
    let (x0, y0, x1, y1) = bbox;
    let (bw, bh) = ((x1 - x0) as f32, (y1 - y0) as f32);
    let mut out = Vec::with_capacity(out_w * out_h);
    for j in 0..out_h {
        for i in 0..out_w {
            out.push([
                x0 as f32 + (i as f32 + 0.5) * bw / out_w as f32,
                y0 as f32 + (j as f32 + 0.5) * bh / out_h as f32,
            ]);
        }
    }
    out
}

/// The rays of `camera` through continuous pixel coordinates, bounded by the scene's
/// `[near, far]` and the parameterisation's volume. Directions have camera-space z = -1.
pub fn camera_rays(
    camera: &Camera,
    pixels: &[[f32; 2]],
    space: &SceneSpace,
    near: f32,
    far: f32,
) -> RayBatch {
    let o = camera.origin();
    let r = &camera.c2w;
    let mut batch = RayBatch::default();
    for p in pixels {
        let dc = [
            (p[0] - camera.cx) / camera.fx,
            -(p[1] - camera.cy) / camera.fy,
            -1.0,
        ];
        let d = [0, 1, 2].map(|i| r[i][0] * dc[0] + r[i][1] * dc[1] + r[i][2] * dc[2]);
        let (t0, t1) = space.ray_bounds(o, d, near, far);
        batch.origins.push(o);
        batch.dirs.push(d);
        batch.near.push(t0);
        batch.far.push(t1);
    }
    batch
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crop_camera_agrees_with_crop_pixels() {
        let cam = Camera {
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 52.0,
            cx: 31.0,
            cy: 25.0,
            c2w: [
                [1.0, 0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 0.0],
            ],
        };
        let bbox = (10, 5, 30, 45);
        let crop = crop_camera(&cam, bbox, 8, 16);
        let px = crop_pixels(bbox, 8, 16);
        let space = SceneSpace::Aabb {
            min: [-9.0; 3],
            max: [9.0; 3],
        };
        let a = camera_rays(&cam, &px, &space, 0.1, 5.0);
        let b = camera_rays(&crop, &all_pixels(8, 16), &space, 0.1, 5.0);
        for (da, db) in a.dirs.iter().zip(&b.dirs) {
            for i in 0..3 {
                assert!((da[i] - db[i]).abs() < 1e-5);
            }
        }
    }
}
