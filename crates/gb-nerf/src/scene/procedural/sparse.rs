//! Sparse points the way COLMAP gives them for a real capture, so that a procedural scene
//! can be supervised with sparse depth instead of its exact depth maps: surface points of
//! the training views that at least two training views see, with a keypoint noise of about
//! [`KEYPOINT_NOISE_PX`] pixels. Written as the scene's `sparse/0` COLMAP model, where the
//! test views are registered without keypoints (no point comes from them).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::cameras::PinholeF64;
use super::geometry::{add_scaled, dot, sub, V3};
use super::{GeneratedScene, GeneratedView};
use crate::scene::colmap::{pose_of_camera, Camera, Image, Model, Point3d};
use crate::scene::Split;

/// Points drawn per training view (before the two-view check).
pub const POINTS_PER_VIEW: usize = 200;

/// The standard deviation of the points' noise, in pixels of the view they were drawn in.
pub const KEYPOINT_NOISE_PX: f64 = 0.5;

/// Relative depth agreement for a view to count as seeing a point.
const SEEN_TOLERANCE: f64 = 0.01;

/// Where `p` lands in `camera`: pixel `(x, y)` (pixel centres at `.5`) and z-depth, when in
/// front of it and inside the image.
fn project(camera: &PinholeF64, p: V3) -> Option<([f64; 2], f64)> {
    let c = camera.to_camera(sub(p, camera.origin()));
    let z = -c[2];
    if z <= 1e-9 {
        return None;
    }
    let x = camera.width as f64 / 2.0 + camera.focal * c[0] / z;
    let y = camera.height as f64 / 2.0 - camera.focal * c[1] / z;
    let inside = x >= 0.0 && y >= 0.0 && x < camera.width as f64 && y < camera.height as f64;
    inside.then_some(([x, y], z))
}

/// Whether `view` sees `p`: it projects inside and the view's depth there agrees.
fn sees(view: &GeneratedView, p: V3) -> Option<[f64; 2]> {
    let ([x, y], z) = project(&view.camera, p)?;
    let d = view.render.depth[y as usize * view.camera.width + x as usize] as f64;
    (d > 0.0 && (d - z).abs() <= SEEN_TOLERANCE * z).then_some([x, y])
}

/// A standard normal draw (Box-Muller).
fn normal(rng: &mut ChaCha8Rng) -> f64 {
    let u: f64 = rng.random::<f64>().max(1e-12);
    let v: f64 = rng.random();
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

/// The sparse model of `scene` (see the module docs), reproducible from `seed`.
pub fn sparse_model(scene: &GeneratedScene, seed: u64) -> Model {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5ba5_e000);
    let mut model = Model::default();
    let train: Vec<usize> = (0..scene.views.len())
        .filter(|&i| scene.views[i].split == Split::Train)
        .collect();
    let mut keypoints: Vec<Vec<([f64; 2], i64)>> = vec![Vec::new(); scene.views.len()];
    let mut next = 1u64;
    for &a in &train {
        let view = &scene.views[a];
        let (w, h) = (view.camera.width, view.camera.height);
        for _ in 0..POINTS_PER_VIEW {
            let (px, py) = (rng.random_range(0..w), rng.random_range(0..h));
            let d = view.render.depth[py * w + px] as f64;
            if d <= 0.0 {
                continue;
            }
            let ray = view.camera.ray(px as f64 + 0.5, py as f64 + 0.5);
            let surface = add_scaled(ray.origin, ray.dir, d / dot(ray.dir, view.camera.forward()));
            let sigma = KEYPOINT_NOISE_PX * d / view.camera.focal;
            let p: V3 = std::array::from_fn(|k| surface[k] + sigma * normal(&mut rng));
            let seen: Vec<(usize, [f64; 2])> = train
                .iter()
                .filter_map(|&b| sees(&scene.views[b], surface).map(|_| b))
                .filter_map(|b| project(&scene.views[b].camera, p).map(|(xy, _)| (b, xy)))
                .collect();
            if seen.len() < 2 {
                continue;
            }
            let mut track = Vec::with_capacity(seen.len());
            for (b, xy) in seen {
                track.push((b as i32 + 1, keypoints[b].len() as u32));
                keypoints[b].push((xy, next as i64));
            }
            let rgb = view
                .render
                .rgb
                .get(px, py)
                .map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8);
            model.points.insert(
                next,
                Point3d {
                    xyz: p,
                    rgb,
                    error: KEYPOINT_NOISE_PX,
                    track,
                },
            );
            next += 1;
        }
    }
    for (i, (view, points2d)) in scene.views.iter().zip(keypoints).enumerate() {
        let c = &view.camera;
        let id = i as i32 + 1;
        model.cameras.insert(
            id,
            Camera {
                model: "SIMPLE_PINHOLE".into(),
                width: c.width as u64,
                height: c.height as u64,
                params: vec![c.focal, c.width as f64 / 2.0, c.height as f64 / 2.0],
            },
        );
        let (qvec, tvec) = pose_of_camera(&c.c2w);
        model.images.insert(
            id,
            Image {
                qvec,
                tvec,
                camera_id: id,
                name: format!("{}.png", view.name),
                points2d,
            },
        );
    }
    model
}
