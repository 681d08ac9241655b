//! nerfstudio's `camera_path.json` (what `ns-render camera-path --camera-path-filename` and
//! the viewer's "load path" read) for a list of cameras played at a fixed frame rate.
//!
//! - `camera_path`: one entry per frame, `camera_to_world` the 4x4 camera-to-world matrix
//!   (OpenGL camera axes) flattened row-major, `fov` the vertical field of view in degrees
//!   and `aspect` = width / height. nerfstudio rebuilds each camera with
//!   `fx = fy = (render_height / 2) / tan(fov / 2)` and the principal point at the image
//!   centre;
//! - `keyframes`: the same cameras as the viewer's keyframes (`matrix`, `fov`, `aspect`), so
//!   that the viewer shows and can edit the path;
//! - `render_width`, `render_height`, `fps`, `seconds` (frames / fps), `is_cycle` (the
//!   orbit is closed), `camera_type: "perspective"`.

use gb_nerf::scene::Camera;
use serde::Serialize;

use super::transforms::homogeneous;

#[derive(Serialize)]
struct PathCamera {
    camera_to_world: [f32; 16],
    fov: f64,
    aspect: f64,
}

#[derive(Serialize)]
struct Keyframe {
    matrix: [f32; 16],
    fov: f64,
    aspect: f64,
    override_transition_enabled: bool,
    override_transition_sec: Option<f64>,
}

#[derive(Serialize)]
struct CameraPath {
    camera_type: &'static str,
    render_width: usize,
    render_height: usize,
    fps: u32,
    seconds: f64,
    is_cycle: bool,
    smoothness_value: f64,
    default_fov: f64,
    default_transition_sec: f64,
    keyframes: Vec<Keyframe>,
    camera_path: Vec<PathCamera>,
}

/// The vertical field of view of `camera` in degrees, `2 atan(h / (2 fy))`.
pub fn vertical_fov_degrees(camera: &Camera) -> f64 {
    (2.0 * (camera.height as f64 / (2.0 * f64::from(camera.fy))).atan()).to_degrees()
}

/// A camera's pose as nerfstudio's flattened row-major 4x4 `camera_to_world`.
pub fn flattened_c2w(camera: &Camera) -> [f32; 16] {
    let m = homogeneous(&camera.c2w);
    std::array::from_fn(|i| m[i / 4][i % 4])
}

/// The text of `camera_path.json` for `cameras` played at `fps` frames per second as a
/// closed loop (see the module docs); the render size is the first camera's. `None` when
/// `cameras` is empty.
pub fn camera_path_json(cameras: &[Camera], fps: u32) -> Option<serde_json::Result<String>> {
    let first = cameras.first()?;
    let fps = fps.max(1);
    let seconds = cameras.len() as f64 / f64::from(fps);
    let path: Vec<PathCamera> = cameras
        .iter()
        .map(|c| PathCamera {
            camera_to_world: flattened_c2w(c),
            fov: vertical_fov_degrees(c),
            aspect: c.width as f64 / c.height as f64,
        })
        .collect();
    let keyframes = path
        .iter()
        .map(|p| Keyframe {
            matrix: p.camera_to_world,
            fov: p.fov,
            aspect: p.aspect,
            override_transition_enabled: false,
            override_transition_sec: None,
        })
        .collect();
    let doc = CameraPath {
        camera_type: "perspective",
        render_width: first.width,
        render_height: first.height,
        fps,
        seconds,
        is_cycle: true,
        smoothness_value: 0.0,
        default_fov: vertical_fov_degrees(first),
        default_transition_sec: 1.0 / f64::from(fps),
        keyframes,
        camera_path: path,
    };
    Some(serde_json::to_string_pretty(&doc))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn path_entries_rebuild_the_cameras() {
        let cams: Vec<Camera> = (0..3)
            .map(|k| Camera {
                width: 40,
                height: 30,
                fx: 25.0,
                fy: 25.0,
                cx: 20.0,
                cy: 15.0,
                c2w: [
                    [0.0, 0.0, 1.0, k as f32],
                    [0.0, 1.0, 0.0, 2.0],
                    [-1.0, 0.0, 0.0, 3.0],
                ],
            })
            .collect();
        let text = camera_path_json(&cams, 12).unwrap().unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["render_width"], 40);
        assert_eq!(v["render_height"], 30);
        assert_eq!(v["seconds"], 0.25);
        let path = v["camera_path"].as_array().unwrap();
        assert_eq!(path.len(), 3);
        assert_eq!(v["keyframes"].as_array().unwrap().len(), 3);
        let m: Vec<f64> = path[2]["camera_to_world"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        // row-major: translation in entries 3, 7, 11; last row 0 0 0 1
        assert_eq!((m[3], m[7], m[11]), (2.0, 2.0, 3.0));
        assert_eq!((m[2], m[8]), (1.0, -1.0));
        assert_eq!(&m[12..], &[0.0, 0.0, 0.0, 1.0]);
        // nerfstudio's focal from the fov: (h / 2) / tan(fov / 2)
        let fov = path[0]["fov"].as_f64().unwrap();
        let f = 15.0 / (fov.to_radians() / 2.0).tan();
        assert!((f - 25.0).abs() < 1e-9, "{f}");
        assert!((path[0]["aspect"].as_f64().unwrap() - 4.0 / 3.0).abs() < 1e-12);
        assert!(camera_path_json(&[], 12).is_none());
    }
}
