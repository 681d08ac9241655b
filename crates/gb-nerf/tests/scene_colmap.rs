//! COLMAP sparse models: the binary and text forms read the same model, an image's sparse
//! depth is its points' z in that camera (and they reproject onto their keypoints), and bad
//! files are errors naming the file.

use gb_nerf::scene::colmap::{
    pose_of_camera, rotation, write_binary, write_text, Camera, Image, Model, Point3d,
};
use gb_nerf::scene::llff::{self, LlffOptions};
use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};

/// A small model: two cameras, three images looking at six points, each point seen by the
/// images it projects into, with the keypoints its pinhole projection.
fn model() -> Model {
    let mut m = Model::default();
    m.cameras.insert(
        1,
        Camera {
            model: "PINHOLE".into(),
            width: 64,
            height: 48,
            params: vec![50.0, 52.0, 32.0, 24.0],
        },
    );
    m.cameras.insert(
        2,
        Camera {
            model: "SIMPLE_RADIAL".into(),
            width: 64,
            height: 48,
            params: vec![55.0, 31.5, 23.5, 0.01],
        },
    );
    let points = [
        [0.1, 0.2, 4.0],
        [-0.5, 0.3, 5.0],
        [0.7, -0.4, 3.5],
        [0.0, 0.0, 6.0],
        [-0.9, -0.6, 4.5],
        [0.4, 0.8, 5.5],
    ];
    for (i, xyz) in points.iter().enumerate() {
        m.points.insert(
            100 + i as u64,
            Point3d {
                xyz: *xyz,
                rgb: [i as u8 * 40, 200, 17],
                error: 0.25 + i as f64 * 0.1,
                track: Vec::new(),
            },
        );
    }
    // rotations about y by 0, 10 and -15 degrees, small translations
    for (k, deg) in [0.0f64, 10.0, -15.0].into_iter().enumerate() {
        let h = deg.to_radians() / 2.0;
        let qvec = [h.cos(), 0.0, h.sin(), 0.0];
        let tvec = [0.1 * k as f64, -0.05, 0.2];
        let id = k as i32 + 1;
        let camera_id = if k == 2 { 2 } else { 1 };
        let p = &m.cameras[&camera_id].params;
        let (fx, fy, cx, cy) = if p.len() == 4 && camera_id == 1 {
            (p[0], p[1], p[2], p[3])
        } else {
            (p[0], p[0], p[1], p[2])
        };
        let r = rotation(qvec);
        let mut points2d = vec![([1.5, 2.5], -1)];
        for (pid, pt) in m.points.iter_mut() {
            let c: Vec<f64> = (0..3)
                .map(|row| (0..3).map(|j| r[row][j] * pt.xyz[j]).sum::<f64>() + tvec[row])
                .collect();
            let xy = [fx * c[0] / c[2] + cx, fy * c[1] / c[2] + cy];
            pt.track.push((id, points2d.len() as u32));
            points2d.push((xy, *pid as i64));
        }
        m.images.insert(
            id,
            Image {
                qvec,
                tvec,
                camera_id,
                name: format!("IMG_{:04}.jpg", 2707 + k),
                points2d,
            },
        );
    }
    m
}

#[test]
fn binary_and_text_models_read_the_same() {
    let d = tempfile::tempdir().unwrap();
    let m = model();
    write_text(&m, &d.path().join("txt")).unwrap();
    write_binary(&m, &d.path().join("bin")).unwrap();
    let from_text = Model::read(&d.path().join("txt")).unwrap();
    let from_binary = Model::read(&d.path().join("bin")).unwrap();
    assert_eq!(from_text, from_binary);
    assert_eq!(from_binary, m);
    assert_eq!(from_text.images[&3].points2d.len(), 7);
    assert_eq!(from_text.points[&102].track, [(1, 3), (2, 3), (3, 3)]);
}

#[test]
fn sparse_depth_is_the_points_z_in_each_camera_and_reprojects() {
    let m = model();
    for im in m.images.values() {
        let depth = m.sparse_depth(im);
        // the keypoint without a 3D point is left out
        assert_eq!(depth.len(), 6, "{}", im.name);
        let r = rotation(im.qvec);
        for (s, (_, pid)) in depth.iter().zip(&im.points2d[1..]) {
            let p = m.points[&(*pid as u64)].xyz;
            let z = (0..3).map(|j| r[2][j] * p[j]).sum::<f64>() + im.tvec[2];
            assert!((s.depth as f64 - z).abs() < 1e-5, "{} vs {z}", s.depth);
            assert!(s.depth > 3.0 && s.depth < 7.0);
            assert!((0.25..0.8).contains(&s.error));
        }
    }
    // the identity rotation: z-depth is the point's z plus tz
    let first = &m.images[&1];
    assert!((m.sparse_depth(first)[0].depth - 4.2).abs() < 1e-6);
    assert_eq!(
        m.match_stems(std::path::Path::new("sparse/0"), ["IMG_2708", "IMG_2707"])
            .unwrap()
            .iter()
            .map(|im| im.camera_id)
            .collect::<Vec<_>>(),
        [1, 1]
    );
}

#[test]
fn bad_models_are_errors_naming_the_file() {
    let d = tempfile::tempdir().unwrap();
    let m = model();
    let bin = d.path().join("bin");
    write_binary(&m, &bin).unwrap();
    // a truncated images.bin
    let images = bin.join("images.bin");
    let bytes = std::fs::read(&images).unwrap();
    std::fs::write(&images, &bytes[..bytes.len() - 5]).unwrap();
    let e = Model::read(&bin).unwrap_err().to_string();
    // (the last image's keypoint count no longer fits what is left)
    assert!(
        e.contains("images.bin") && e.contains("number of keypoints = 7 at byte"),
        "{e}"
    );
    // an absurd count
    let mut huge = bytes.clone();
    huge[..8].copy_from_slice(&u64::MAX.to_le_bytes());
    std::fs::write(&images, &huge).unwrap();
    let e = Model::read(&bin).unwrap_err().to_string();
    assert!(
        e.contains("number of images") && e.contains("does not fit"),
        "{e}"
    );
    std::fs::write(&images, &bytes).unwrap();
    // a name the model lacks
    let e = m
        .match_stems(&bin, ["IMG_2707", "IMG_9999"])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("images.bin") && e.contains("view IMG_9999"),
        "{e}"
    );

    let txt = d.path().join("txt");
    write_text(&m, &txt).unwrap();
    let points = txt.join("points3D.txt");
    let text = std::fs::read_to_string(&points).unwrap();
    std::fs::write(&points, text.replacen("0.25", "0.2x5", 1)).unwrap();
    let e = Model::read(&txt).unwrap_err().to_string();
    assert!(
        e.contains("points3D.txt") && e.contains("line 2") && e.contains("'0.2x5'"),
        "{e}"
    );
    std::fs::write(&points, text).unwrap();
    let cameras = txt.join("cameras.txt");
    let text = std::fs::read_to_string(&cameras).unwrap();
    std::fs::write(&cameras, text.replace("SIMPLE_RADIAL", "KANNALA")).unwrap();
    let e = Model::read(&txt).unwrap_err().to_string();
    assert!(
        e.contains("cameras.txt") && e.contains("unknown camera model 'KANNALA'"),
        "{e}"
    );
    let e = Model::read(d.path()).unwrap_err().to_string();
    assert!(e.contains("COLMAP model"), "{e}");
}

/// The COLMAP model of a loaded scene, as COLMAP would have it: one PINHOLE camera per view,
/// its pose, and a point at every 5th pixel with ground-truth depth, seen by that view.
fn model_of_scene(scene: &gb_nerf::scene::Scene) -> Model {
    let mut m = Model::default();
    let mut next_point = 1u64;
    for (k, view) in scene.views.iter().enumerate() {
        let c = &view.camera;
        let id = k as i32 + 1;
        m.cameras.insert(
            id,
            Camera {
                model: "PINHOLE".into(),
                width: c.width as u64,
                height: c.height as u64,
                params: vec![c.fx as f64, c.fy as f64, c.cx as f64, c.cy as f64],
            },
        );
        let (qvec, tvec) = pose_of_camera(&c.c2w.map(|row| row.map(f64::from)));
        let depth = view.depth.as_ref().expect("procedural scenes have depth");
        let forward = [-c.c2w[0][2], -c.c2w[1][2], -c.c2w[2][2]];
        let origin = c.origin();
        let mut points2d = Vec::new();
        for y in (0..c.height).step_by(5) {
            for x in (0..c.width).step_by(5) {
                let d = depth[y * c.width + x];
                if d <= 0.0 {
                    continue;
                }
                let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
                let dir = c.ray_direction(px, py);
                let t = d / (0..3).map(|i| dir[i] * forward[i]).sum::<f32>();
                let xyz = std::array::from_fn(|i| (origin[i] + dir[i] * t) as f64);
                m.points.insert(
                    next_point,
                    Point3d {
                        xyz,
                        rgb: [128; 3],
                        error: 0.5,
                        track: vec![(id, points2d.len() as u32)],
                    },
                );
                points2d.push(([px as f64, py as f64], next_point as i64));
                next_point += 1;
            }
        }
        m.images.insert(
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
    m
}

#[test]
fn a_scene_with_a_colmap_model_gets_each_views_sparse_depth_on_its_surface() {
    let d = tempfile::tempdir().unwrap();
    let o = ProceduralOptions {
        name: SceneName::Stairs,
        seed: 3,
        width: 40,
        height: 30,
        views: 5,
        test_views: 1,
        dilate: 0,
    };
    procedural::write(&o, d.path()).unwrap();
    // without the generator's noisy model: an exact one is built below
    std::fs::remove_dir_all(d.path().join("sparse")).unwrap();
    let plain = llff::load(d.path(), &LlffOptions::default()).unwrap();
    assert!(plain.sparse_depth.is_empty());
    let mut model = model_of_scene(&plain);
    write_binary(&model, &d.path().join("sparse/0")).unwrap();
    let s = llff::load(d.path(), &LlffOptions::default()).unwrap();
    assert_eq!(s.sparse_depth.len(), 5);
    let mut checked = 0;
    for view in &s.views {
        let depth = view.depth.as_ref().unwrap();
        let points = &s.sparse_depth[&view.name];
        assert!(points.len() > 10, "{}: {}", view.name, points.len());
        for p in points {
            let (x, y) = ((p.x - 0.5) as usize, (p.y - 0.5) as usize);
            let want = depth[y * view.camera.width + x];
            // the pose went through a quaternion and back: the depth survives to 1e-4
            assert!(
                (p.depth - want).abs() <= 1e-4 * want.max(1.0),
                "{} ({x}, {y}): {} vs {want}",
                view.name,
                p.depth
            );
            checked += 1;
        }
    }
    assert!(checked > 100, "{checked}");
    // a view the model lacks is an error naming the model's images file and the view
    let last = *model.images.keys().last().unwrap();
    model.images.remove(&last);
    write_binary(&model, &d.path().join("sparse/0")).unwrap();
    let e = llff::load(d.path(), &LlffOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("sparse/0/images.bin") && e.contains("no registered image for view view_004"),
        "{e}"
    );
}

#[test]
fn a_generated_scene_ships_sparse_points_on_its_surface_within_their_noise() {
    use gb_nerf::scene::procedural::sparse::KEYPOINT_NOISE_PX;
    use gb_nerf::scene::Split;
    let d = tempfile::tempdir().unwrap();
    let o = ProceduralOptions {
        name: SceneName::Stairs,
        seed: 1,
        width: 64,
        height: 48,
        views: 6,
        test_views: 2,
        dilate: 0,
    };
    procedural::write(&o, d.path()).unwrap();
    let model = Model::read(&d.path().join("sparse/0")).unwrap();
    let s = llff::load(d.path(), &LlffOptions::default()).unwrap();
    let train_ids: Vec<i32> = model
        .images
        .iter()
        .filter(|(_, im)| {
            let stem = im.name.trim_end_matches(".png");
            s.views
                .iter()
                .any(|v| v.name == stem && v.split == Split::Train)
        })
        .map(|(id, _)| *id)
        .collect();
    assert_eq!(train_ids.len(), 4);
    // every point is seen by at least two training views, and only by training views
    assert!(model.points.len() > 100, "{}", model.points.len());
    for p in model.points.values() {
        assert!(p.track.len() >= 2, "{:?}", p.track);
        assert!(p.track.iter().all(|(i, _)| train_ids.contains(i)));
    }
    // the depth error in units of the noise's depth scale (0.5 px at the point's depth)
    let mut errors = Vec::new();
    for view in &s.views {
        let points = &s.sparse_depth[&view.name];
        if view.split == Split::Test {
            assert!(points.is_empty(), "{}", view.name);
            continue;
        }
        assert!(points.len() > 20, "{}: {}", view.name, points.len());
        let depth = view.depth.as_ref().unwrap();
        for p in points {
            let (x, y) = (p.x as usize, p.y as usize);
            let gt = depth[y * view.camera.width + x];
            let sigma = KEYPOINT_NOISE_PX as f32 * gt / view.camera.fx;
            errors.push((p.depth - gt).abs() / sigma);
        }
    }
    errors.sort_by(f32::total_cmp);
    let at = |q: f32| errors[((errors.len() - 1) as f32 * q) as usize];
    eprintln!(
        "depth error / sigma: median {}, 90% {}, 99% {}, max {}",
        at(0.5),
        at(0.9),
        at(0.99),
        at(1.0)
    );
    assert!(at(0.5) > 0.05, "the points carry noise: median {}", at(0.5));
    assert!(at(0.5) < 1.5, "median {}", at(0.5));
    assert!(at(0.9) < 4.0, "90th percentile {}", at(0.9));
}
