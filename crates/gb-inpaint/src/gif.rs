//! The orbit animation of a run (`orbit.gif`): the trained field rendered along a smooth,
//! closed camera path through the region the capture covers.
//!
//! Two paths, chosen from the spread of the input cameras' viewing directions:
//!
//! - **forward-facing** (every camera within [`SURROUND_DEGREES`] of the mean viewing
//!   direction; LLFF / SPIn-NeRF captures, the procedural scenes): the "spiral" of LLFF-style
//!   renders without the depth wobble. The cameras keep the mean orientation of the input
//!   cameras (rotation matrices averaged, then re-orthonormalised) and move on an ellipse
//!   centred on the mean camera centre, in the plane of the mean camera's right and up axes,
//!   with semi-axes equal to the largest offset of any input camera along each axis. The path
//!   stays inside the span of the captured views, where the field is constrained.
//! - **surrounding** (Blender-style captures): a circle around the point nearest to every
//!   camera's optical axis (least squares), at the cameras' mean height along their mean up
//!   axis and their mean horizontal distance, every frame looking at that point.
//!
//! Intrinsics are those of the first camera, scaled by `1 / downscale`.

use std::path::Path;

use gb_core::RgbImage;
use gb_nerf::scene::Camera;
use gb_nerf::train::data::downscale_camera;
use gb_report::gif::write_gif;

use crate::error::InpaintError;

fn normalize(v: [f32; 3]) -> Option<[f32; 3]> {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    (n > 1e-12 && n.is_finite()).then(|| [v[0] / n, v[1] / n, v[2] / n])
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Column `j` of a camera's rotation (the camera's axis `j` in world coordinates).
fn axis(c: &Camera, j: usize) -> [f32; 3] {
    [c.c2w[0][j], c.c2w[1][j], c.c2w[2][j]]
}

/// Captures whose viewing directions spread further than this from their mean get the
/// surrounding orbit (see the module docs).
pub const SURROUND_DEGREES: f32 = 60.0;

/// Solves the 3x3 system `a x = b` (Cramer's rule); `None` when it is singular.
fn solve3(a: [[f32; 3]; 3], b: [f32; 3]) -> Option<[f32; 3]> {
    let det = |m: [[f32; 3]; 3]| dot(m[0], cross(m[1], m[2]));
    let d = det(a);
    if d.abs() < 1e-9 || !d.is_finite() {
        return None;
    }
    let mut x = [0.0; 3];
    for (j, xj) in x.iter_mut().enumerate() {
        let mut m = a;
        for (i, row) in m.iter_mut().enumerate() {
            row[j] = b[i];
        }
        *xj = det(m) / d;
    }
    Some(x)
}

/// The surrounding orbit: a circle around the point nearest to every optical axis.
fn surround_orbit(cameras: &[Camera], base: &Camera, frames: usize, up: [f32; 3]) -> Vec<Camera> {
    let (mut a, mut b) = ([[0.0f32; 3]; 3], [0.0f32; 3]);
    for c in cameras {
        let f = axis(c, 2); // back axis: the optical axis up to its sign
        let o = c.origin();
        for i in 0..3 {
            for j in 0..3 {
                let p = f32::from(u8::from(i == j)) - f[i] * f[j];
                a[i][j] += p;
                b[i] += p * o[j];
            }
        }
    }
    let n = cameras.len() as f32;
    let mean_o = cameras.iter().fold([0.0f32; 3], |acc, c| {
        let o = c.origin();
        [acc[0] + o[0] / n, acc[1] + o[1] / n, acc[2] + o[2] / n]
    });
    let target = solve3(a, b).unwrap_or(mean_o);
    let (mut h, mut r) = (0.0f32, 0.0f32);
    for c in cameras {
        let o = c.origin();
        let d = [o[0] - target[0], o[1] - target[1], o[2] - target[2]];
        let along = dot(d, up);
        h += along / n;
        let hz = [
            d[0] - along * up[0],
            d[1] - along * up[1],
            d[2] - along * up[2],
        ];
        r += dot(hz, hz).sqrt() / n;
    }
    let o = cameras[0].origin();
    let d0 = [o[0] - target[0], o[1] - target[1], o[2] - target[2]];
    let a0 = dot(d0, up);
    let e1 = normalize([d0[0] - a0 * up[0], d0[1] - a0 * up[1], d0[2] - a0 * up[2]])
        .or_else(|| normalize(cross(up, [1.0, 0.0, 0.0])))
        .or_else(|| normalize(cross(up, [0.0, 1.0, 0.0])))
        .unwrap_or([1.0, 0.0, 0.0]);
    let e2 = cross(up, e1);
    (0..frames)
        .map(|k| {
            let (s, c) = (std::f32::consts::TAU * k as f32 / frames as f32).sin_cos();
            let pos: [f32; 3] =
                std::array::from_fn(|i| target[i] + h * up[i] + r * (c * e1[i] + s * e2[i]));
            let back = normalize([pos[0] - target[0], pos[1] - target[1], pos[2] - target[2]])
                .unwrap_or(axis(base, 2));
            let right = normalize(cross(up, back)).unwrap_or(axis(base, 0));
            let cam_up = cross(back, right);
            let mut cam = base.clone();
            for i in 0..3 {
                cam.c2w[i] = [right[i], cam_up[i], back[i], pos[i]];
            }
            cam
        })
        .collect()
}

/// `frames` cameras on the orbit of `cameras` (see the module docs), at `1 / downscale` of the
/// first camera's resolution. Empty when `cameras` is empty or `frames` is 0.
pub fn orbit_cameras(cameras: &[Camera], frames: usize, downscale: usize) -> Vec<Camera> {
    let Some(first) = cameras.first() else {
        return Vec::new();
    };
    if frames == 0 {
        return Vec::new();
    }
    let n = cameras.len() as f32;
    let mut centre = [0.0f32; 3];
    let mut mean_axes = [[0.0f32; 3]; 3];
    for c in cameras {
        let o = c.origin();
        for i in 0..3 {
            centre[i] += o[i] / n;
            for (j, a) in mean_axes.iter_mut().enumerate() {
                a[i] += axis(c, j)[i] / n;
            }
        }
    }
    // Gram-Schmidt on the mean right and up axes; the third axis keeps the cameras' handedness
    let right = normalize(mean_axes[0]).unwrap_or(axis(first, 0));
    let up_raw = mean_axes[1];
    let d = dot(up_raw, right);
    let up = normalize([
        up_raw[0] - d * right[0],
        up_raw[1] - d * right[1],
        up_raw[2] - d * right[2],
    ])
    .unwrap_or(axis(first, 1));
    let mut back = cross(right, up);
    if dot(back, mean_axes[2]) < 0.0 {
        back = [-back[0], -back[1], -back[2]];
    }
    let base = downscale_camera(first, downscale.max(1));
    let cos_limit = SURROUND_DEGREES.to_radians().cos();
    let mean_back = normalize(mean_axes[2]);
    let surrounding =
        mean_back.is_none_or(|m| cameras.iter().any(|c| dot(axis(c, 2), m) < cos_limit));
    if surrounding {
        return surround_orbit(cameras, &base, frames, up);
    }
    let (mut ax, mut ay) = (0.0f32, 0.0f32);
    for c in cameras {
        let o = c.origin();
        let off = [o[0] - centre[0], o[1] - centre[1], o[2] - centre[2]];
        ax = ax.max(dot(off, right).abs());
        ay = ay.max(dot(off, up).abs());
    }
    (0..frames)
        .map(|k| {
            let theta = std::f32::consts::TAU * k as f32 / frames as f32;
            let (s, c) = theta.sin_cos();
            let mut cam = base.clone();
            for i in 0..3 {
                cam.c2w[i] = [
                    right[i],
                    up[i],
                    back[i],
                    centre[i] + ax * c * right[i] + ay * s * up[i],
                ];
            }
            cam
        })
        .collect()
}

/// What [`write_orbit`] wrote.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrbitInfo {
    /// Number of frames.
    pub frames: usize,
    /// Frame width in pixels.
    pub width: usize,
    /// Frame height in pixels.
    pub height: usize,
    /// Wall time of the renders and the encoding.
    pub seconds: f64,
}

/// Frames per second of `orbit.gif`.
pub const ORBIT_FPS: u32 = 12;

/// The cameras of a run's orbit: [`orbit_cameras`] of every camera of `scene` (training and
/// test) at half the training resolution. [`write_orbit`] renders them, and
/// [`crate::export`] writes them as nerfstudio's `camera_path.json`.
pub fn orbit_path(
    scene: &gb_nerf::scene::Scene,
    trainer: &crate::GuidedTrainer,
    frames: usize,
) -> Vec<Camera> {
    let cameras: Vec<Camera> = scene.views.iter().map(|v| v.camera.clone()).collect();
    orbit_cameras(
        &cameras,
        frames,
        trainer.config.train.image_downscale.max(1) * 2,
    )
}

/// Renders `frames` views of the trained field along the orbit of every camera of `scene`
/// (training and test), at half the training resolution, into `OUT/orbit.gif`. `None` when
/// `frames` is 0.
pub fn write_orbit(
    out: &Path,
    scene: &gb_nerf::scene::Scene,
    trainer: &crate::GuidedTrainer,
    frames: usize,
) -> Result<Option<OrbitInfo>, InpaintError> {
    if frames == 0 {
        return Ok(None);
    }
    let start = std::time::Instant::now();
    let path = orbit_path(scene, trainer, frames);
    let images = path
        .iter()
        .map(|c| trainer.render(c).map(|r| r.rgb))
        .collect::<Result<Vec<RgbImage>, _>>()?;
    let Some(first) = images.first() else {
        return Ok(None);
    };
    let (width, height) = (first.width, first.height);
    write_gif(&out.join("orbit.gif"), &images, ORBIT_FPS)?;
    Ok(Some(OrbitInfo {
        frames: images.len(),
        width,
        height,
        seconds: start.elapsed().as_secs_f64(),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(x: f32, y: f32) -> Camera {
        Camera {
            width: 40,
            height: 30,
            fx: 30.0,
            fy: 30.0,
            cx: 20.0,
            cy: 15.0,
            c2w: [[1.0, 0.0, 0.0, x], [0.0, 1.0, 0.0, y], [0.0, 0.0, 1.0, 4.0]],
        }
    }

    #[test]
    fn orbit_spans_the_cameras_and_is_closed() {
        let cams = [cam(-1.0, 0.0), cam(1.0, 0.5), cam(0.0, -0.5)];
        let orbit = orbit_cameras(&cams, 24, 2);
        assert_eq!(orbit.len(), 24);
        assert_eq!((orbit[0].width, orbit[0].height), (20, 15));
        assert!((orbit[0].fx - 15.0).abs() < 1e-5);
        // mean centre (0, 0, 4); semi-axes 1 (x) and 0.5 (y)
        let o0 = orbit[0].origin();
        assert!((o0[0] - 1.0).abs() < 1e-5 && o0[1].abs() < 1e-5 && (o0[2] - 4.0).abs() < 1e-5);
        let o6 = orbit[6].origin();
        assert!(o6[0].abs() < 1e-5 && (o6[1] - 0.5).abs() < 1e-5, "{o6:?}");
        // orientation kept
        assert_eq!(orbit[3].c2w[2][2], 1.0);
        assert!(orbit_cameras(&[], 24, 1).is_empty());
    }

    /// A camera at `pos` looking at the origin with world z up.
    fn look_at(pos: [f32; 3]) -> Camera {
        let back = normalize(pos).unwrap();
        let right = normalize(cross([0.0, 0.0, 1.0], back)).unwrap();
        let up = cross(back, right);
        let mut c = cam(0.0, 0.0);
        for i in 0..3 {
            c.c2w[i] = [right[i], up[i], back[i], pos[i]];
        }
        c
    }

    #[test]
    fn surrounding_captures_get_a_circle_looking_at_the_centre() {
        let cams: Vec<Camera> = (0..6)
            .map(|k| {
                let t = std::f32::consts::TAU * k as f32 / 6.0;
                look_at([4.0 * t.cos(), 4.0 * t.sin(), 2.0])
            })
            .collect();
        let orbit = orbit_cameras(&cams, 8, 1);
        assert_eq!(orbit.len(), 8);
        for c in &orbit {
            let o = c.origin();
            assert!((o[2] - 2.0).abs() < 1e-3, "height {o:?}");
            assert!(
                ((o[0] * o[0] + o[1] * o[1]).sqrt() - 4.0).abs() < 1e-3,
                "radius {o:?}"
            );
            // the origin projects to the principal point
            let (px, z) = c
                .project([0.0, 0.0, 0.0])
                .expect("target behind the camera");
            assert!(
                (px[0] - c.cx).abs() < 1e-3 && (px[1] - c.cy).abs() < 1e-3,
                "{px:?}"
            );
            assert!(z > 0.0);
        }
    }
}
