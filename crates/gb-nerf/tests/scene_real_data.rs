//! The loaders on the real scenes in `$GB_TEST_DATA/data`: counts, resolution, intrinsics
//! and poses against values computed here directly from the files.
// Component loops over xyz / matrix entries read clearer with indices than with zips.
#![allow(clippy::needless_range_loop)]

use gb_nerf::scene::blender::{self, BlenderOptions};
use gb_nerf::scene::llff::{self, LlffOptions};
use gb_nerf::scene::{load, LoadOptions, SceneFormat, SceneKind, Split};
use std::path::{Path, PathBuf};

fn data(name: &str) -> PathBuf {
    gb_core::test_data_dir().join("data").join(name)
}

/// `poses_bounds.npy` read independently of the loader (npyz, float64, C order).
fn raw_poses(dir: &Path) -> (Vec<u64>, Vec<f64>) {
    let bytes = std::fs::read(dir.join("poses_bounds.npy")).unwrap();
    let npy = npyz::NpyFile::new(&bytes[..]).unwrap();
    let shape = npy.shape().to_vec();
    (shape, npy.into_vec::<f64>().unwrap())
}

fn assert_close(a: f32, b: f64, tol: f64, what: &str) {
    assert!((a as f64 - b).abs() <= tol, "{what}: {a} vs {b}");
}

/// Checks every view's camera against the raw rows: f / factor, centre principal point, and
/// the LLFF -> OpenGL column mapping `[c1, -c0, c2, t]`.
fn check_llff_cameras(scene: &gb_nerf::scene::Scene, raw: &[f64], factor: f64) {
    for (v, row) in scene.views.iter().zip(raw.chunks_exact(17)) {
        let m = |i: usize, j: usize| row[i * 5 + j];
        assert_eq!(
            (v.camera.width as f64, v.camera.height as f64),
            (m(1, 4) / factor, m(0, 4) / factor)
        );
        assert_close(v.camera.fx, m(2, 4) / factor, 1e-3, "fx");
        assert_close(v.camera.fy, m(2, 4) / factor, 1e-3, "fy");
        assert_close(v.camera.cx, v.camera.width as f64 / 2.0, 0.0, "cx");
        assert_close(v.camera.cy, v.camera.height as f64 / 2.0, 0.0, "cy");
        for i in 0..3 {
            assert_close(v.camera.c2w[i][0], m(i, 1), 1e-6, "right");
            assert_close(v.camera.c2w[i][1], -m(i, 0), 1e-6, "up");
            assert_close(v.camera.c2w[i][2], m(i, 2), 1e-6, "back");
            assert_close(v.camera.c2w[i][3], m(i, 3), 1e-5, "t");
        }
    }
    let min_near = raw
        .chunks_exact(17)
        .map(|r| r[15])
        .fold(f64::INFINITY, f64::min);
    let max_far = raw.chunks_exact(17).map(|r| r[16]).fold(0.0, f64::max);
    assert_close(scene.near, 0.9 * min_near, 1e-3, "near");
    assert_close(scene.far, max_far, 1e-3, "far");
}

// fails when the shared data appeared after this crate was built without it
gb_core::shared_data_guard!();

#[test]
#[cfg_attr(
    gb_no_shared_data,
    ignore = "needs the shared test data (../shared or GB_TEST_DATA): data/statue"
)]
fn statue_has_29_masked_training_views_at_504x378() {
    let dir = data("statue");
    let (format, scene) = load(&dir, &LoadOptions::default()).unwrap();
    assert_eq!(format, SceneFormat::Llff);
    assert_eq!(scene.kind, SceneKind::ForwardFacing);
    assert_eq!(scene.views.len(), 29);
    assert_eq!(scene.split(Split::Train).count(), 29);
    assert!(scene
        .views
        .iter()
        .all(|v| (v.image.width, v.image.height) == (504, 378)));
    let (shape, raw) = raw_poses(&dir);
    assert_eq!(shape, vec![29, 17]);
    check_llff_cameras(&scene, &raw, 2.0);
    assert_close(scene.views[0].camera.fx, 370.162_406, 1e-3, "statue focal");
    // every view has its 0/1 mask, with a plausible object size
    for v in &scene.views {
        let m = v.mask.as_ref().expect("statue views have masks");
        assert_eq!((m.width, m.height), (504, 378));
        let c = m.coverage();
        assert!(c > 0.01 && c < 0.5, "{}: coverage {c}", v.name);
    }
    // first mask: 9.118% of pixels are 1 in the file (computed with numpy)
    assert_close(
        scene.views[0].mask.as_ref().unwrap().coverage(),
        0.091_180_6,
        1e-5,
        "coverage",
    );
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    assert_eq!(scene.views[0].name, "IMG_2707");
}

#[test]
#[cfg_attr(
    gb_no_shared_data,
    ignore = "needs the shared test data (../shared or GB_TEST_DATA): data/fern"
)]
fn fern_has_20_views_and_every_8th_held_out() {
    let dir = data("fern");
    let scene = llff::load(&dir, &LlffOptions::default()).unwrap();
    assert_eq!(scene.views.len(), 20);
    assert!(scene
        .views
        .iter()
        .all(|v| v.split == Split::Train && v.mask.is_none()));
    assert!(scene
        .views
        .iter()
        .all(|v| (v.image.width, v.image.height) == (504, 378)));
    let (shape, raw) = raw_poses(&dir);
    assert_eq!(shape, vec![20, 17]);
    check_llff_cameras(&scene, &raw, 8.0);
    assert_close(scene.views[0].camera.fx, 407.565_79, 1e-3, "fern focal");

    let held = llff::load(
        &dir,
        &LlffOptions {
            holdout_every: Some(8),
            ..Default::default()
        },
    )
    .unwrap();
    let test: Vec<usize> = (0..20)
        .filter(|&i| held.views[i].split == Split::Test)
        .collect();
    assert_eq!(test, vec![0, 8, 16]);
}

#[test]
#[cfg_attr(
    gb_no_shared_data,
    ignore = "needs the shared test data (../shared or GB_TEST_DATA): data/fern"
)]
fn fern_normalisation_makes_the_average_pose_identity_and_min_near_four_thirds() {
    let dir = data("fern");
    let scene = llff::load(
        &dir,
        &LlffOptions {
            normalize: true,
            ..Default::default()
        },
    )
    .unwrap();
    // near = 0.9 * (4/3) after scaling the smallest near bound to 4/3
    assert_close(scene.near, 0.9 * 4.0 / 3.0, 1e-4, "near");
    let n = scene.views.len() as f32;
    let mut centre = [0.0f32; 3];
    let mut back = [0.0f32; 3];
    for v in &scene.views {
        for i in 0..3 {
            centre[i] += v.camera.c2w[i][3] / n;
            back[i] += v.camera.c2w[i][2] / n;
        }
    }
    for i in 0..3 {
        assert!(centre[i].abs() < 1e-4, "{centre:?}");
    }
    let len = (back[0] * back[0] + back[1] * back[1] + back[2] * back[2]).sqrt();
    assert!(
        back[0].abs() / len < 1e-4 && back[1].abs() / len < 1e-4,
        "{back:?}"
    );
    // rotations stay orthonormal
    for v in &scene.views {
        let c = &v.camera.c2w;
        for a in 0..3 {
            for b in 0..3 {
                let d: f32 = (0..3).map(|i| c[i][a] * c[i][b]).sum();
                assert!((d - if a == b { 1.0 } else { 0.0 }).abs() < 1e-4);
            }
        }
    }
}

#[test]
#[cfg_attr(
    gb_no_shared_data,
    ignore = "needs the shared test data (../shared or GB_TEST_DATA): data/lego_small"
)]
fn lego_small_has_100_train_and_25_test_views_with_camera_angle_focal() {
    let dir = data("lego_small");
    let bg = [0.0, 1.0, 0.0];
    let scene = blender::load(
        &dir,
        &BlenderOptions {
            background: bg,
            holdout_every: None,
        },
    )
    .unwrap();
    assert_eq!(scene.split(Split::Train).count(), 100);
    assert_eq!(scene.split(Split::Test).count(), 25);
    assert!(matches!(scene.kind, SceneKind::Bounded { .. }));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("transforms_train.json")).unwrap())
            .unwrap();
    let angle = json["camera_angle_x"].as_f64().unwrap();
    let f = 0.5 * 200.0 / (0.5 * angle).tan();
    assert!((f - 277.777_76).abs() < 1e-3);
    for v in &scene.views {
        assert_eq!((v.camera.width, v.camera.height), (200, 200));
        assert_close(v.camera.fx, f, 1e-3, "fx");
        assert_close(v.camera.fy, f, 1e-3, "fy");
        assert_close(v.camera.cx, 100.0, 0.0, "cx");
    }
    // first frame's pose is the JSON's transform_matrix
    let m = &json["frames"][0]["transform_matrix"];
    for i in 0..3 {
        for j in 0..4 {
            assert_close(
                scene.views[0].camera.c2w[i][j],
                m[i][j].as_f64().unwrap(),
                1e-6,
                "c2w",
            );
        }
    }
    assert_eq!(scene.views[0].name, "r_0");
    // RGBA composited on the chosen background: a fully transparent corner pixel is green
    let raw = image::open(dir.join("train/r_0.png")).unwrap().to_rgba8();
    let px = raw.get_pixel(0, 0).0;
    assert_eq!(px[3], 0, "corner of r_0 is transparent");
    assert_eq!(scene.views[0].image.get(0, 0), bg);
    // and a partly covered pixel is the alpha blend
    let (x, y) = (0..200 * 200)
        .map(|i| (i % 200, i / 200))
        .find(|&(x, y)| {
            let a = raw.get_pixel(x as u32, y as u32).0[3];
            a > 20 && a < 235
        })
        .expect("an anti-aliased edge pixel");
    let p = raw.get_pixel(x as u32, y as u32).0;
    let a = p[3] as f32 / 255.0;
    let got = scene.views[0].image.get(x, y);
    for c in 0..3 {
        let want = p[c] as f32 / 255.0 * a + bg[c] * (1.0 - a);
        assert!((got[c] - want).abs() < 1e-5);
    }
}
