//! SPIn-NeRF conventions of the LLFF loader on small generated fixtures: test views come
//! from `test_label/`, masks of another size are cropped with a warning, the optional
//! inpainting folders are found, and the hold-out option only applies without test masks.

use gb_nerf::scene::llff::{self, spin_extras, LlffOptions};
use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};
use gb_nerf::scene::Split;
use std::path::Path;

fn fixture(dir: &Path) {
    let o = ProceduralOptions {
        name: SceneName::Fence,
        seed: 9,
        width: 32,
        height: 24,
        views: 6,
        test_views: 2,
        dilate: 0,
    };
    procedural::write(&o, dir).unwrap();
}

#[test]
fn test_masks_define_the_test_views_and_out_of_order_ones_warn() {
    let d = tempfile::tempdir().unwrap();
    fixture(d.path());
    let s = llff::load(
        d.path(),
        &LlffOptions {
            holdout_every: Some(2),
            ..Default::default()
        },
    )
    .unwrap();
    // with test masks present the hold-out option is ignored
    let splits: Vec<Split> = s.views.iter().map(|v| v.split).collect();
    assert_eq!(
        splits,
        [
            Split::Test,
            Split::Test,
            Split::Train,
            Split::Train,
            Split::Train,
            Split::Train
        ]
    );
    assert!(s.warnings.is_empty());

    // move view_001's test mask to view_004: the test views are now 000 and 004
    let tl = d.path().join("images_1/test_label");
    std::fs::rename(tl.join("view_001.png"), tl.join("view_004.png")).unwrap();
    let s = llff::load(d.path(), &LlffOptions::default()).unwrap();
    let test: Vec<&str> = s.split(Split::Test).map(|v| v.name.as_str()).collect();
    assert_eq!(test, ["view_000", "view_004"]);
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("not the first 2 sorted views")),
        "{:?}",
        s.warnings
    );
    // view_001 is now a training view without a mask
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("1 training views have no mask")),
        "{:?}",
        s.warnings
    );
}

#[test]
fn spin_nerf_test_masks_named_out_nnnnn_pair_with_the_unmasked_views_in_order() {
    let d = tempfile::tempdir().unwrap();
    fixture(d.path());
    let before = llff::load(d.path(), &LlffOptions::default()).unwrap();
    // SPIn-NeRF's naming: out_00001.png, out_00002.png in the test views' sorted order
    let tl = d.path().join("images_1/test_label");
    std::fs::rename(tl.join("view_000.png"), tl.join("out_00001.png")).unwrap();
    std::fs::rename(tl.join("view_001.png"), tl.join("out_00002.png")).unwrap();
    let s = llff::load(d.path(), &LlffOptions::default()).unwrap();
    let test: Vec<&str> = s.split(Split::Test).map(|v| v.name.as_str()).collect();
    assert_eq!(test, ["view_000", "view_001"]);
    for (a, b) in s.views.iter().zip(&before.views) {
        assert_eq!((a.split, &a.mask), (b.split, &b.mask), "{}", a.name);
    }
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    assert!(
        s.warnings[0].contains("paired in sorted order with the 2 views")
            && s.warnings[0].contains("view_000 .. view_001"),
        "{}",
        s.warnings[0]
    );
    // a third mask: the counts no longer match, and the error names a mask file
    std::fs::copy(tl.join("out_00002.png"), tl.join("out_00003.png")).unwrap();
    let err = llff::load(d.path(), &LlffOptions::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains("out_0000"), "{err}");
}

#[test]
fn without_test_masks_every_nth_view_is_held_out() {
    let d = tempfile::tempdir().unwrap();
    fixture(d.path());
    std::fs::remove_dir_all(d.path().join("images_1/test_label")).unwrap();
    let s = llff::load(
        d.path(),
        &LlffOptions {
            holdout_every: Some(4),
            ..Default::default()
        },
    )
    .unwrap();
    let test: Vec<&str> = s.split(Split::Test).map(|v| v.name.as_str()).collect();
    assert_eq!(test, ["view_000", "view_004"]);
}

#[test]
fn a_taller_mask_is_cropped_with_a_warning_naming_it() {
    let d = tempfile::tempdir().unwrap();
    fixture(d.path());
    let p = d.path().join("images_1/label/view_003.png");
    let (w, h, v) = gb_core::read_gray(&p).unwrap();
    let mut taller = v.clone();
    taller.extend(std::iter::repeat_n(1.0, w * 3));
    gb_core::write_gray_png(&p, w, h + 3, &taller).unwrap();
    let s = llff::load(d.path(), &LlffOptions::default()).unwrap();
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    assert!(
        s.warnings[0].contains("view_003.png") && s.warnings[0].contains("32x27"),
        "{}",
        s.warnings[0]
    );
    let m = s.views[3].mask.as_ref().unwrap();
    assert_eq!((m.width, m.height), (32, 24));
    let orig: Vec<bool> = v.iter().map(|&x| x > 0.5).collect();
    assert_eq!(m.data, orig);
}

#[test]
fn inpainting_folders_are_found() {
    let d = tempfile::tempdir().unwrap();
    fixture(d.path());
    assert_eq!(spin_extras(d.path(), None), Default::default());
    std::fs::create_dir_all(d.path().join("images_1/RGB_inpainted")).unwrap();
    std::fs::create_dir_all(d.path().join("Depth_inpainted")).unwrap();
    let e = spin_extras(d.path(), None);
    assert_eq!(
        e.rgb_inpainted.unwrap(),
        d.path().join("images_1/RGB_inpainted")
    );
    assert_eq!(e.depth_inpainted.unwrap(), d.path().join("Depth_inpainted"));
    // and the loader ignores them (they hold no extra images in images_1/ itself)
    assert_eq!(
        llff::load(d.path(), &LlffOptions::default())
            .unwrap()
            .views
            .len(),
        6
    );
}

#[test]
fn normalisation_scales_depth_and_keeps_reprojection() {
    let d = tempfile::tempdir().unwrap();
    fixture(d.path());
    let raw = llff::load(d.path(), &LlffOptions::default()).unwrap();
    let norm = llff::load(
        d.path(),
        &LlffOptions {
            normalize: true,
            ..Default::default()
        },
    )
    .unwrap();
    let min_near = norm.near / 0.9;
    assert!((min_near - 4.0 / 3.0).abs() < 1e-4, "{}", norm.near);
    let scale = norm.near / raw.near;
    for (a, b) in raw.views.iter().zip(&norm.views) {
        let (da, db) = (a.depth.as_ref().unwrap(), b.depth.as_ref().unwrap());
        assert!(da
            .iter()
            .zip(db)
            .all(|(x, y)| (x * scale - y).abs() <= 1e-4 * y));
        // a pixel's 3D point still projects back to that pixel
        let i = 12 * 32 + 16;
        let dir = b.camera.ray_direction(16.5, 12.5);
        let fwd = [
            -b.camera.c2w[0][2],
            -b.camera.c2w[1][2],
            -b.camera.c2w[2][2],
        ];
        let t = db[i] / (dir[0] * fwd[0] + dir[1] * fwd[1] + dir[2] * fwd[2]);
        let o = b.camera.origin();
        let (px, z) = b
            .camera
            .project([o[0] + t * dir[0], o[1] + t * dir[1], o[2] + t * dir[2]])
            .unwrap();
        assert!(
            (px[0] - 16.5).abs() < 1e-3
                && (px[1] - 12.5).abs() < 1e-3
                && (z - db[i]).abs() < 1e-4 * z
        );
        // normals are rotated with the scene: still unit length
        let n = b.normal.as_ref().unwrap()[i];
        assert!(((n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt() - 1.0).abs() < 1e-5);
    }
}

#[test]
fn bounds_do_not_change_when_the_test_views_are_removed() {
    use gb_nerf::scene::npy::{encode_f64, read_float_array};
    let d = tempfile::tempdir().unwrap();
    fixture(d.path());
    // the test views (the first two rows, as the views sort) see nearer and farther than
    // any training view: their rows must not widen the scene's bounds
    let poses = d.path().join("poses_bounds.npy");
    let mut rows = read_float_array(&poses).unwrap().data;
    let train_near = rows[2 * 17..]
        .chunks(17)
        .map(|r| r[15])
        .fold(f64::INFINITY, f64::min);
    let train_far = rows[2 * 17..].chunks(17).map(|r| r[16]).fold(0.0, f64::max);
    for r in rows[..2 * 17].chunks_mut(17) {
        (r[15], r[16]) = (0.5 * train_near, 2.0 * train_far);
    }
    std::fs::write(&poses, encode_f64(&[6, 17], &rows).unwrap()).unwrap();
    let with_tests = llff::load(d.path(), &LlffOptions::default()).unwrap();
    let test: Vec<String> = with_tests
        .split(Split::Test)
        .map(|v| v.name.clone())
        .collect();
    assert_eq!(test, ["view_000", "view_001"]);
    assert_eq!(with_tests.near, (0.9 * train_near) as f32);
    assert_eq!(with_tests.far, train_far as f32);
    // delete the test views: images, masks, depth and normals, and their pose rows
    for name in &test {
        for f in [
            format!("images_1/{name}.png"),
            format!("images_1/test_label/{name}.png"),
            format!("depth_1/{name}.npy"),
            format!("normal_1/{name}.npy"),
        ] {
            std::fs::remove_file(d.path().join(f)).unwrap();
        }
    }
    std::fs::write(&poses, encode_f64(&[4, 17], &rows[2 * 17..]).unwrap()).unwrap();
    let without = llff::load(d.path(), &LlffOptions::default()).unwrap();
    assert_eq!(without.views.len(), 4);
    assert!(without.split(Split::Test).next().is_none());
    assert_eq!(
        (without.near, without.far, &without.kind),
        (with_tests.near, with_tests.far, &with_tests.kind)
    );
}
