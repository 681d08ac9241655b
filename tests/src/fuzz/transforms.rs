//! `transforms.json` scenes (`gb_nerf::scene::blender::load`): a valid file beside a 4x3 PNG
//! must give its cameras and bounds; mutated files and arbitrary bytes give `Ok` or `Err`.

use std::path::Path;

use gb_nerf::scene::blender::{load as load_scene, BlenderOptions};
use gb_nerf::scene::SceneKind;
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;

use super::mutate::{any_bytes, mutated, mutations, Mutation};
use super::{ensure, Harness};

/// Tokens for mutating a transforms file.
const JSON_TOKENS: &[&str] = &[
    "frames",
    "file_path",
    "transform_matrix",
    "camera_angle_x",
    "camera_angle_y",
    "fl_x",
    "fl_y",
    "cx",
    "cy",
    "w",
    "h",
    "near",
    "far",
    "aabb_min",
    "aabb_max",
    "\"./r_0\"",
    "\"../r_0\"",
    "\"r_0.jpg\"",
    "[[1, 0, 0, 0], [0, 1, 0, 0]]",
    "[1, 0, 0, 0]",
    "[[]]",
];

const WIDTH: usize = 4;
const HEIGHT: usize = 3;

/// A valid single-frame file.
#[derive(Debug, Clone)]
struct ValidTransforms {
    /// `camera_angle_x`, or `fl_x` with the JSON's `w` (intrinsics then scale by 4 / w).
    angle_x: Option<f64>,
    fl_x: f64,
    json_w: f64,
    c2w: [[f64; 4]; 4],
    bounds: Option<(f64, f64)>,
}

impl ValidTransforms {
    fn text(&self) -> String {
        let mut top = serde_json::Map::new();
        match self.angle_x {
            Some(a) => {
                top.insert("camera_angle_x".into(), a.into());
            }
            None => {
                top.insert("fl_x".into(), self.fl_x.into());
                top.insert("w".into(), self.json_w.into());
            }
        }
        if let Some((n, f)) = self.bounds {
            top.insert("near".into(), n.into());
            top.insert("far".into(), f.into());
        }
        let frame = serde_json::json!({ "file_path": "./r_0", "transform_matrix": self.c2w });
        top.insert("frames".into(), serde_json::Value::Array(vec![frame]));
        serde_json::to_string_pretty(&serde_json::Value::Object(top)).expect("json")
    }

    /// The focal length the loader must compute.
    fn fx(&self) -> f64 {
        match self.angle_x {
            Some(a) => 0.5 * WIDTH as f64 / (0.5 * a).tan(),
            None => self.fl_x * WIDTH as f64 / self.json_w,
        }
    }
}

fn valid() -> impl Strategy<Value = ValidTransforms> {
    (
        proptest::option::of(0.1f64..3.0),
        1.0f64..1000.0,
        1.0f64..100.0,
        proptest::array::uniform4(proptest::array::uniform4(-10.0f64..10.0)),
        proptest::option::of((0.01f64..1.0, 2.0f64..100.0)),
    )
        .prop_map(|(angle_x, fl_x, json_w, c2w, bounds)| ValidTransforms {
            angle_x,
            fl_x,
            json_w,
            c2w,
            bounds,
        })
}

#[derive(Debug, Clone)]
enum Case {
    Valid(ValidTransforms, Vec<Mutation>),
    Raw(Vec<u8>),
}

fn scene_dir(scratch: &Path) -> std::path::PathBuf {
    let dir = scratch.join("scene");
    let png = dir.join("r_0.png");
    if !png.exists() {
        std::fs::create_dir_all(&dir).expect("scratch scene folder");
        let img = gb_core::RgbImage {
            width: WIDTH,
            height: HEIGHT,
            data: vec![0.5; WIDTH * HEIGHT * 3],
        };
        gb_core::write_rgb_png(&png, &img).expect("scratch image");
    }
    dir
}

/// `blender::load` never panics; a valid file gives its camera and bounds.
pub fn load(h: &mut Harness) -> Result<(), String> {
    let case = prop_oneof![
        2 => valid().prop_map(|v| Case::Valid(v, Vec::new())),
        5 => (valid(), mutations(JSON_TOKENS)).prop_map(|(v, m)| Case::Valid(v, m)),
        1 => any_bytes(256).prop_map(Case::Raw),
    ];
    h.check(case, |case, scratch| {
        let dir = scene_dir(scratch);
        let bytes = match &case {
            Case::Valid(v, m) => mutated(v.text().as_bytes(), m),
            Case::Raw(b) => b.clone(),
        };
        std::fs::write(dir.join("transforms.json"), bytes).expect("scratch transforms.json");
        let got = load_scene(&dir, &BlenderOptions::default());
        let Case::Valid(v, m) = &case else {
            return Ok(());
        };
        if !m.is_empty() {
            return Ok(());
        }
        let scene = got.map_err(|e| TestCaseError::fail(format!("valid file rejected: {e}")))?;
        ensure(scene.views.len() == 1, || {
            format!("{} views", scene.views.len())
        })?;
        let cam = &scene.views[0].camera;
        let close = |a: f32, b: f64| (f64::from(a) - b).abs() <= 1e-5 * b.abs().max(1.0);
        ensure(
            (cam.width, cam.height) == (WIDTH, HEIGHT) && close(cam.fx, v.fx()),
            || format!("camera {cam:?}, expected fx {}", v.fx()),
        )?;
        for (r, row) in cam.c2w.iter().enumerate() {
            for (c, x) in row.iter().enumerate() {
                ensure(close(*x, v.c2w[r][c]), || format!("c2w[{r}][{c}] = {x}"))?;
            }
        }
        let (near, far) = v.bounds.unwrap_or((2.0, 6.0));
        ensure(close(scene.near, near) && close(scene.far, far), || {
            format!("near/far {} {}", scene.near, scene.far)
        })?;
        ensure(matches!(scene.kind, SceneKind::Bounded { .. }), || {
            "not bounded".into()
        })?;
        Ok(())
    })
}
