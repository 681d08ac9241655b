//! The nerfstudio export of a run (`gb_inpaint::export`), read back with the project's own
//! loader: a two-step run without a prior on a small procedural stairs scene trained at half
//! resolution, exported, then loaded with `gb_nerf::scene::load`:
//!
//! - one frame per training view, same names, image size and intrinsics at the training
//!   resolution, same camera-to-world (within 1e-4), the run's bounds;
//! - the images are the field's renders (8-bit) and the depth PNGs its z-depths within half
//!   a quantisation step;
//! - `camera_path.json` holds the orbit of `orbit.gif`, frame for frame.

use std::path::Path;

use gb_core::BackendKind;
use gb_inpaint::export::{read_depth_png, vertical_fov_degrees, write_export};
use gb_inpaint::gif::orbit_path;
use gb_inpaint::{GuidedTrainer, MethodConfig};
use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};
use gb_nerf::scene::{Camera, LoadOptions, SceneFormat, SceneKind, Split};
use gb_nerf::train::data::downscale_camera;
use gb_nerf::train::NerfConfig;

const ORBIT_FRAMES: usize = 5;

fn assert_cameras_match(got: &Camera, want: &Camera, what: &str) {
    assert_eq!((got.width, got.height), (want.width, want.height), "{what}");
    let (g, w) = (
        [got.fx, got.fy, got.cx, got.cy],
        [want.fx, want.fy, want.cx, want.cy],
    );
    for (a, b) in g.iter().zip(&w) {
        assert!((a - b).abs() < 1e-4, "{what}: intrinsics {g:?} vs {w:?}");
    }
    for (a, b) in got.c2w.iter().flatten().zip(want.c2w.iter().flatten()) {
        assert!(
            (a - b).abs() < 1e-4,
            "{what}: c2w {:?} vs {:?}",
            got.c2w,
            want.c2w
        );
    }
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn export_reads_back_with_the_same_cameras_renders_and_orbit() {
    // draws from Burn's process-global device RNG (crate::DEVICE_RNG)
    let _rng = crate::DEVICE_RNG.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let scene_dir = dir.path().join("scene");
    let opts = ProceduralOptions {
        name: SceneName::Stairs,
        seed: 0,
        width: 64,
        height: 48,
        views: 5,
        test_views: 1,
        dilate: 1,
    };
    procedural::write(&opts, &scene_dir).unwrap();
    let (_, scene) = gb_nerf::scene::load(&scene_dir, &LoadOptions::default()).unwrap();
    let mut config = NerfConfig::preset("fast").unwrap();
    config.train.steps = 2;
    config.train.image_downscale = 2;
    let method = MethodConfig::builtin("none").unwrap();
    let mut trainer = GuidedTrainer::new(&scene, config, method, None, BackendKind::Flex).unwrap();
    for _ in 0..2 {
        gb_nerf::train::Trainer::train_step(&mut trainer).unwrap();
    }

    let out = dir.path().join("export");
    let info = write_export(&out, &scene, &trainer, ORBIT_FRAMES).unwrap();
    let train: Vec<_> = scene.split(Split::Train).collect();
    assert_eq!(info.views, train.len());
    assert_eq!((info.width, info.height), (32, 24));
    assert_eq!(info.camera_path_frames, ORBIT_FRAMES);

    // the project's loader reads the export as a nerfstudio scene
    let (format, back) = gb_nerf::scene::load(&out, &LoadOptions::default()).unwrap();
    assert_eq!(format, SceneFormat::Blender);
    assert_eq!(back.views.len(), train.len(), "image count");
    assert_eq!((back.near, back.far), (scene.near, scene.far));
    match (&back.kind, &scene.kind) {
        (
            SceneKind::Bounded { aabb_min, aabb_max },
            SceneKind::Bounded {
                aabb_min: lo,
                aabb_max: hi,
            },
        ) => {
            assert_eq!((aabb_min, aabb_max), (lo, hi));
        }
        other => panic!("scene kinds {other:?}"),
    }
    let transforms = json(&out.join("transforms.json"));
    assert_eq!(transforms["camera_model"], "OPENCV");
    let unit = transforms["depth_unit_scale_factor"].as_f64().unwrap();
    assert_eq!(unit, info.depth_unit_scale_factor);

    for (view, got) in train.iter().zip(&back.views) {
        assert_eq!(got.name, view.name);
        assert_eq!(got.split, Split::Train);
        let camera = downscale_camera(&view.camera, 2);
        assert_cameras_match(&got.camera, &camera, &view.name);
        let render = trainer.render(&camera).unwrap();
        assert_eq!((got.image.width, got.image.height), (32, 24));
        for (a, b) in got.image.data.iter().zip(&render.rgb.data) {
            assert!(
                (a - b.clamp(0.0, 1.0)).abs() <= 0.5 / 255.0 + 1e-5,
                "{}: rgb {a} vs {b}",
                view.name
            );
        }
        let (w, h, depth) =
            read_depth_png(&out.join(format!("depth/{}.png", view.name)), unit).unwrap();
        assert_eq!((w, h), (32, 24));
        for (a, b) in depth.iter().zip(&render.depth) {
            assert!(
                *b > 0.0 && b.is_finite(),
                "{}: rendered depth {b}",
                view.name
            );
            let tol = 0.5 * unit as f32 + 1e-5 * b;
            assert!(
                (a - b).abs() <= tol,
                "{}: depth {a} vs {b} (unit {unit})",
                view.name
            );
        }
    }

    // the orbit of orbit.gif, frame for frame
    let path = json(&out.join("camera_path.json"));
    let orbit = orbit_path(&scene, &trainer, ORBIT_FRAMES);
    let frames = path["camera_path"].as_array().unwrap();
    assert_eq!(frames.len(), ORBIT_FRAMES);
    assert_eq!(path["render_width"], orbit[0].width);
    assert_eq!(path["render_height"], orbit[0].height);
    assert_eq!(
        path["seconds"].as_f64().unwrap(),
        ORBIT_FRAMES as f64 / gb_inpaint::gif::ORBIT_FPS as f64
    );
    for (f, cam) in frames.iter().zip(&orbit) {
        let m: Vec<f32> = f["camera_to_world"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap() as f32)
            .collect();
        for i in 0..3 {
            for j in 0..4 {
                assert!(
                    (m[i * 4 + j] - cam.c2w[i][j]).abs() < 1e-5,
                    "orbit pose {m:?}"
                );
            }
        }
        assert!((f["fov"].as_f64().unwrap() - vertical_fov_degrees(cam)).abs() < 1e-9);
    }

    // without orbit frames no camera path is written, and an old one is removed
    let info = write_export(&out, &scene, &trainer, 0).unwrap();
    assert_eq!(info.camera_path_frames, 0);
    assert!(!out.join("camera_path.json").exists());
}
