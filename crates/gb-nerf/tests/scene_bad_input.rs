//! Bad scene folders: each gives an error that names the file and the problem.

use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};
use gb_nerf::scene::{load, LoadOptions, SceneError};
use std::path::Path;

/// A small valid LLFF scene (6 views, 2 test) to corrupt.
fn fixture(dir: &Path) {
    let o = ProceduralOptions {
        name: SceneName::Stairs,
        seed: 0,
        width: 32,
        height: 24,
        views: 6,
        test_views: 2,
        dilate: 0,
    };
    procedural::write(&o, dir).unwrap();
}

fn npy_f64(shape: &[u64], data: &[f64]) -> Vec<u8> {
    gb_nerf::scene::npy::encode_f64(shape, data).unwrap()
}

fn err(dir: &Path) -> (SceneError, String) {
    let e = load(dir, &LoadOptions::default()).unwrap_err();
    let s = e.to_string();
    assert_eq!(s.lines().count(), 1, "one line: {s}");
    (e, s)
}

#[test]
fn missing_poses_bounds() {
    let d = tempfile::tempdir().unwrap();
    fixture(d.path());
    std::fs::remove_file(d.path().join("poses_bounds.npy")).unwrap();
    let (e, s) = err(d.path());
    assert!(matches!(e, SceneError::Missing { .. }), "{e:?}");
    assert!(
        s.contains("poses_bounds.npy") && s.contains("missing"),
        "{s}"
    );
}

#[test]
fn wrong_pose_shape() {
    let d = tempfile::tempdir().unwrap();
    fixture(d.path());
    std::fs::write(
        d.path().join("poses_bounds.npy"),
        npy_f64(&[100, 15], &vec![0.5; 1500]),
    )
    .unwrap();
    let (e, s) = err(d.path());
    assert!(
        matches!(e, SceneError::PoseShape { ref shape, .. } if shape == &vec![100, 15]),
        "{e:?}"
    );
    assert!(
        s.contains("poses_bounds.npy") && s.contains("[100, 15]") && s.contains("N x 17"),
        "{s}"
    );
}

#[test]
fn nan_in_a_pose() {
    let d = tempfile::tempdir().unwrap();
    fixture(d.path());
    let p = d.path().join("poses_bounds.npy");
    let mut a = gb_nerf::scene::npy::read_float_array(&p).unwrap();
    a.data[17 * 3 + 7] = f64::NAN;
    std::fs::write(&p, npy_f64(&a.shape, &a.data)).unwrap();
    let (e, s) = err(d.path());
    assert!(
        matches!(e, SceneError::NonFinitePose { row: 3, col: 7, .. }),
        "{e:?}"
    );
    assert!(
        s.contains("poses_bounds.npy") && s.contains("NaN") && s.contains("row 3"),
        "{s}"
    );
}

#[test]
fn image_count_differs_from_pose_count() {
    let d = tempfile::tempdir().unwrap();
    fixture(d.path());
    std::fs::remove_file(d.path().join("images_1/view_005.png")).unwrap();
    std::fs::remove_file(d.path().join("images_1/label/view_005.png")).unwrap();
    let (e, s) = err(d.path());
    assert!(
        matches!(
            e,
            SceneError::CountMismatch {
                images: 5,
                poses: 6,
                ..
            }
        ),
        "{e:?}"
    );
    assert!(
        s.contains("images_1") && s.contains("5 images but 6 poses"),
        "{s}"
    );
}

#[test]
fn unreadable_png() {
    let d = tempfile::tempdir().unwrap();
    fixture(d.path());
    std::fs::write(d.path().join("images_1/view_003.png"), b"this is not a png").unwrap();
    let (e, s) = err(d.path());
    assert!(matches!(e, SceneError::Image(_)), "{e:?}");
    assert!(
        s.contains("view_003.png") && s.contains("cannot read image"),
        "{s}"
    );
}

#[test]
fn mask_without_image() {
    let d = tempfile::tempdir().unwrap();
    fixture(d.path());
    std::fs::copy(
        d.path().join("images_1/label/view_003.png"),
        d.path().join("images_1/label/stray.png"),
    )
    .unwrap();
    let (e, s) = err(d.path());
    assert!(matches!(e, SceneError::OrphanMask { .. }), "{e:?}");
    assert!(s.contains("stray.png") && s.contains("no image"), "{s}");
}

#[test]
fn empty_folder() {
    let d = tempfile::tempdir().unwrap();
    let (e, s) = err(d.path());
    assert!(matches!(e, SceneError::EmptyFolder { .. }), "{e:?}");
    assert!(s.contains("empty folder"), "{s}");
}

#[test]
fn missing_folder_and_unknown_layout() {
    let d = tempfile::tempdir().unwrap();
    let (e, _) = err(&d.path().join("nope"));
    assert!(matches!(e, SceneError::NotAFolder { .. }), "{e:?}");
    std::fs::write(d.path().join("notes.txt"), b"hello").unwrap();
    let (e, s) = err(d.path());
    assert!(matches!(e, SceneError::UnknownLayout { .. }), "{e:?}");
    assert!(s.contains("unknown scene layout"), "{s}");
}

#[test]
fn blender_frame_without_transform_names_the_json() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(
        d.path().join("transforms_train.json"),
        br#"{"camera_angle_x": 0.7, "frames": [{"file_path": "./a"}]}"#,
    )
    .unwrap();
    gb_core::write_rgb_png(
        &d.path().join("a.png"),
        &gb_core::RgbImage::filled(4, 4, [0.5; 3]),
    )
    .unwrap();
    let (_, s) = err(d.path());
    assert!(
        s.contains("transforms_train.json")
            && s.contains("frame 0")
            && s.contains("transform_matrix"),
        "{s}"
    );
}

#[test]
fn nan_or_infinity_in_a_depth_map_names_the_file_and_pixel() {
    let d = tempfile::tempdir().unwrap();
    fixture(d.path());
    let p = d.path().join("depth_1/view_004.npy");
    let mut a = gb_nerf::scene::npy::read_float_array(&p).unwrap();
    assert_eq!(a.shape, vec![24, 32]);
    a.data[32 * 5 + 7] = f64::INFINITY;
    let shape = a.shape.clone();
    let f32s: Vec<f32> = a.data.iter().map(|&v| v as f32).collect();
    std::fs::write(&p, gb_nerf::scene::npy::encode_f32(&shape, &f32s).unwrap()).unwrap();
    let (e, s) = err(d.path());
    assert!(
        matches!(e, SceneError::NonFiniteArray { x: 7, y: 5, .. }),
        "{e:?}"
    );
    assert!(s.contains("view_004.npy") && s.contains("inf"), "{s}");
}

#[test]
fn a_mask_with_grey_levels_is_refused() {
    let d = tempfile::tempdir().unwrap();
    fixture(d.path());
    let p = d.path().join("images_1/label/view_003.png");
    let (w, h, mut v) = gb_core::read_gray(&p).unwrap();
    v[0] = 0.25;
    gb_core::write_gray_png(&p, w, h, &v).unwrap();
    let (e, s) = err(d.path());
    assert!(
        matches!(e, SceneError::MaskNotBinary { pixels: 1, .. }),
        "{e:?}"
    );
    assert!(
        s.contains("view_003.png") && s.contains("not binary"),
        "{s}"
    );
}

#[test]
fn blender_frame_naming_a_missing_image_names_the_json_and_the_file() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(
        d.path().join("transforms.json"),
        br#"{"camera_angle_x": 0.7, "frames": [{"file_path": "./gone",
            "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,4],[0,0,0,1]]}]}"#,
    )
    .unwrap();
    let (_, s) = err(d.path());
    assert!(
        s.contains("transforms.json")
            && s.contains("frame 0")
            && s.contains("gone.png")
            && s.contains("does not exist"),
        "{s}"
    );
}
