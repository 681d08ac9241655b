//! Rendering one view: anti-aliased RGB (2x2 fixed subsamples per pixel), the exact object
//! coverage, and the pixel-centre ground truth (z-depth, world normal).
// Component loops over xyz / matrix entries read clearer with indices than with zips.
#![allow(clippy::needless_range_loop)]

use super::cameras::PinholeF64;
use super::geometry::{dot, normalize};
use super::world::{Hit, World};
use gb_core::RgbImage;

/// Subsample offsets inside a pixel (a fixed 2x2 grid).
pub const SUBSAMPLES: [(f64, f64); 4] = [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)];

/// The render of one view.
#[derive(Debug, Clone, PartialEq)]
pub struct Render {
    /// Colour, the mean of the 4 subsamples.
    pub rgb: RgbImage,
    /// Per pixel: whether any subsample of the scene WITH the object sees the object first
    /// (the exact object mask; computed whether or not the object is rendered).
    pub coverage: Vec<bool>,
    /// Per pixel: whether the pixel-centre ray sees the object (when it is rendered).
    pub center_on_object: Vec<bool>,
    /// Z-depth of the pixel-centre ray's hit (distance along the viewing axis); 0 = no hit.
    pub depth: Vec<f32>,
    /// Unit world normal at the pixel-centre hit, facing the camera; zero = no hit.
    pub normal: Vec<[f32; 3]>,
    /// Unit camera-space normal (OpenGL axes), the normalised mean over the 4 subsamples.
    pub normal_camera: Vec<[f32; 3]>,
}

/// Renders `world` through `cam`, with or without the object.
pub fn render(world: &World, cam: &PinholeF64, with_object: bool) -> Render {
    let (w, h) = (cam.width, cam.height);
    let mut rgb = RgbImage::filled(w, h, [0.0; 3]);
    let mut coverage = vec![false; w * h];
    let mut center_on_object = vec![false; w * h];
    let mut depth = vec![0.0f32; w * h];
    let mut normal = vec![[0.0f32; 3]; w * h];
    let mut normal_camera = vec![[0.0f32; 3]; w * h];
    let fwd = cam.forward();
    let pick = |s: &super::world::SplitHit| -> Option<Hit> {
        if with_object {
            s.with_object()
        } else {
            s.background
        }
    };
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let mut acc = [0.0f64; 3];
            let mut nacc = [0.0f64; 3];
            for (ox, oy) in SUBSAMPLES {
                let ray = cam.ray(x as f64 + ox, y as f64 + oy);
                let s = world.trace(&ray);
                coverage[i] |= s.sees_object();
                if let Some(hit) = pick(&s) {
                    let c = world.shade(&hit);
                    let nc = cam.to_camera(hit.normal);
                    for k in 0..3 {
                        acc[k] += c[k] / SUBSAMPLES.len() as f64;
                        nacc[k] += nc[k];
                    }
                }
            }
            rgb.set(x, y, [acc[0] as f32, acc[1] as f32, acc[2] as f32]);
            if dot(nacc, nacc) > 1e-24 {
                let n = normalize(nacc);
                normal_camera[i] = [n[0] as f32, n[1] as f32, n[2] as f32];
            }
            let ray = cam.ray(x as f64 + 0.5, y as f64 + 0.5);
            let s = world.trace(&ray);
            if let Some(hit) = pick(&s) {
                depth[i] = (hit.t * dot(ray.dir, fwd)) as f32;
                normal[i] = [
                    hit.normal[0] as f32,
                    hit.normal[1] as f32,
                    hit.normal[2] as f32,
                ];
                center_on_object[i] = hit.object;
            }
        }
    }
    Render {
        rgb,
        coverage,
        center_on_object,
        depth,
        normal,
        normal_camera,
    }
}
