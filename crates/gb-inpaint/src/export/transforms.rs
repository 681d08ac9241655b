//! nerfstudio's `transforms.json` for a set of posed images (the format the project's
//! Blender / nerfstudio loader, `gb_nerf::scene::blender`, reads back).
//!
//! - `camera_model: "OPENCV"` with zero distortion (`k1, k2, p1, p2`): the cameras are
//!   pinholes;
//! - intrinsics `fl_x, fl_y, cx, cy, w, h` in pixels at the exported resolution: at the top
//!   level when every frame shares them, else per frame;
//! - per frame: `file_path` (`images/NAME.png`), `depth_file_path` (`depth/NAME.png`) and
//!   `transform_matrix`, the 4x4 camera-to-world matrix with OpenGL camera axes (x right,
//!   y up, looking along -z), which is how the project stores cameras: no axis change;
//! - `depth_unit_scale_factor`: scene units per step of the 16-bit depth PNGs;
//! - `near`, `far` and, for a bounded scene, `aabb_min` / `aabb_max`: the bounds the run
//!   used (read by the project's loader, ignored by nerfstudio).
//!
//! Numbers are written from `f32` with the shortest text that reads back to the same `f32`,
//! so a camera read back is bit-identical.

use gb_nerf::scene::{Camera, Scene, SceneKind};
use serde::Serialize;

/// Intrinsics in nerfstudio's keys.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
struct Intrinsics {
    fl_x: f32,
    fl_y: f32,
    cx: f32,
    cy: f32,
    w: usize,
    h: usize,
}

impl Intrinsics {
    fn of(c: &Camera) -> Self {
        Self {
            fl_x: c.fx,
            fl_y: c.fy,
            cx: c.cx,
            cy: c.cy,
            w: c.width,
            h: c.height,
        }
    }
}

#[derive(Serialize)]
struct Frame {
    file_path: String,
    depth_file_path: String,
    transform_matrix: [[f32; 4]; 4],
    #[serde(flatten)]
    intrinsics: Option<Intrinsics>,
}

#[derive(Serialize)]
struct Transforms {
    camera_model: &'static str,
    #[serde(flatten)]
    intrinsics: Option<Intrinsics>,
    k1: f32,
    k2: f32,
    p1: f32,
    p2: f32,
    depth_unit_scale_factor: f64,
    near: f32,
    far: f32,
    #[serde(skip_serializing_if = "Option::is_none")]
    aabb_min: Option<[f32; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    aabb_max: Option<[f32; 3]>,
    frames: Vec<Frame>,
}

/// A camera's 3x4 `c2w` as the 4x4 homogeneous matrix.
pub fn homogeneous(c2w: &[[f32; 4]; 3]) -> [[f32; 4]; 4] {
    [c2w[0], c2w[1], c2w[2], [0.0, 0.0, 0.0, 1.0]]
}

/// The relative image path of view `name` (`images/NAME.png`).
pub fn image_path(name: &str) -> String {
    format!("images/{name}.png")
}

/// The relative depth path of view `name` (`depth/NAME.png`).
pub fn depth_path(name: &str) -> String {
    format!("depth/{name}.png")
}

/// The text of `transforms.json` for `views` (name and camera at the exported resolution, in
/// order), with depth PNGs in steps of `depth_unit` and the bounds of `scene` (see the
/// module docs).
pub fn transforms_json(
    views: &[(String, Camera)],
    depth_unit: f64,
    scene: &Scene,
) -> serde_json::Result<String> {
    let shared = views
        .first()
        .map(|(_, c)| Intrinsics::of(c))
        .filter(|first| views.iter().all(|(_, c)| Intrinsics::of(c) == *first));
    let frames = views
        .iter()
        .map(|(name, c)| Frame {
            file_path: image_path(name),
            depth_file_path: depth_path(name),
            transform_matrix: homogeneous(&c.c2w),
            intrinsics: shared.is_none().then(|| Intrinsics::of(c)),
        })
        .collect();
    let (aabb_min, aabb_max) = match &scene.kind {
        SceneKind::Bounded { aabb_min, aabb_max } => (Some(*aabb_min), Some(*aabb_max)),
        SceneKind::ForwardFacing => (None, None),
    };
    let t = Transforms {
        camera_model: "OPENCV",
        intrinsics: shared,
        k1: 0.0,
        k2: 0.0,
        p1: 0.0,
        p2: 0.0,
        depth_unit_scale_factor: depth_unit,
        near: scene.near,
        far: scene.far,
        aabb_min,
        aabb_max,
        frames,
    };
    // straight to text: `serde_json::Value` would widen every f32 to f64 first
    serde_json::to_string_pretty(&t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(fx: f32, x: f32) -> Camera {
        Camera {
            width: 40,
            height: 30,
            fx,
            fy: fx,
            cx: 20.0,
            cy: 15.0,
            c2w: [
                [1.0, 0.0, 0.0, x],
                [0.0, 1.0, 0.0, 0.1],
                [0.0, 0.0, 1.0, 4.0],
            ],
        }
    }

    fn scene() -> Scene {
        Scene {
            name: "s".into(),
            kind: SceneKind::ForwardFacing,
            views: Vec::new(),
            near: 0.5,
            far: 9.0,
            background: [1.0; 3],
            warnings: Vec::new(),
            sparse_depth: Default::default(),
        }
    }

    #[test]
    fn shared_intrinsics_go_to_the_top_level() {
        let views = vec![
            ("a".to_string(), cam(30.0, 0.0)),
            ("b".into(), cam(30.0, 1.0)),
        ];
        let text = transforms_json(&views, 1e-3, &scene()).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["camera_model"], "OPENCV");
        assert_eq!(v["fl_x"], 30.0);
        assert_eq!(v["w"], 40);
        assert!(v["frames"][0].get("fl_x").is_none());
        assert_eq!(v["frames"][1]["file_path"], "images/b.png");
        assert_eq!(v["frames"][1]["depth_file_path"], "depth/b.png");
        assert_eq!(v["frames"][1]["transform_matrix"][0][3], 1.0);
        assert_eq!(v["frames"][1]["transform_matrix"][3][3], 1.0);
        // 0.1f32 is written as 0.1, not 0.10000000149011612
        let compact: String = text.split_whitespace().collect();
        assert!(compact.contains("[0.0,1.0,0.0,0.1]"), "{text}");
        assert!(v.get("aabb_min").is_none());
        assert_eq!(v["far"], 9.0);
    }

    #[test]
    fn differing_intrinsics_go_to_each_frame() {
        let views = vec![
            ("a".to_string(), cam(30.0, 0.0)),
            ("b".into(), cam(31.0, 1.0)),
        ];
        let text = transforms_json(&views, 1e-3, &scene()).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert!(v.get("fl_x").is_none());
        assert_eq!(v["frames"][0]["fl_x"], 30.0);
        assert_eq!(v["frames"][1]["fl_y"], 31.0);
        assert_eq!(v["frames"][1]["h"], 30);
    }
}
