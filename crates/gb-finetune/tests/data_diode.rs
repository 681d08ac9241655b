//! The DIODE loader on fake DIODE trees, its errors, and the normal-map convention test:
//! DIODE normals, the NeRF renderer's depth-to-normal plane fit and the procedural scenes'
//! normal maps all agree.

use burn::tensor::{Tensor, TensorData};
use gb_finetune::captions::CaptionMode;
use gb_finetune::diode::{diode_intrinsics, DiodeDataset, DiodeSplit};
use gb_finetune::normal_map::{encode_normal, masked_angular_error_deg, normals_to_map};
use gb_finetune::sample::PairSource;
use gb_nerf::render::normals::{depth_to_normals, Intrinsics, PlaneFitConfig};
use gb_nerf::scene::npy::encode_f32;
use std::path::{Path, PathBuf};

/// One fake DIODE image: RGB, depth (H, W, 1), depth mask (H, W) and normals (H, W, 3).
struct FakeImage<'a> {
    rel_dir: &'a str,
    stem: &'a str,
    w: usize,
    h: usize,
    depth: Vec<f32>,
    mask: Vec<f32>,
    /// Normals exactly as DIODE stores them.
    normal: Vec<[f32; 3]>,
}

fn write_fake(root: &Path, img: &FakeImage) -> PathBuf {
    let dir = root.join(img.rel_dir);
    std::fs::create_dir_all(&dir).unwrap();
    let (w, h) = (img.w, img.h);
    let mut rgb = gb_core::RgbImage::filled(w, h, [0.0; 3]);
    for y in 0..h {
        for x in 0..w {
            rgb.set(x, y, [x as f32 / w as f32, y as f32 / h as f32, 0.25]);
        }
    }
    let png = dir.join(format!("{}.png", img.stem));
    gb_core::write_rgb_png(&png, &rgb).unwrap();
    let put = |suffix: &str, shape: &[u64], data: &[f32]| {
        std::fs::write(
            dir.join(format!("{}{suffix}", img.stem)),
            encode_f32(shape, data).unwrap(),
        )
        .unwrap();
    };
    put("_depth.npy", &[h as u64, w as u64, 1], &img.depth);
    put("_depth_mask.npy", &[h as u64, w as u64], &img.mask);
    let flat: Vec<f32> = img.normal.iter().flatten().copied().collect();
    put("_normal.npy", &[h as u64, w as u64, 3], &flat);
    png
}

fn unit(v: [f32; 3]) -> [f32; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|x| x / l)
}

/// Camera-space z-depth of the plane `n . p = -d` (OpenGL camera axes) through each pixel
/// centre of a pinhole camera `[fx, fy, cx, cy]`.
fn plane_depth(w: usize, h: usize, k: [f32; 4], n: [f32; 3], d: f32) -> Vec<f32> {
    let mut out = Vec::with_capacity(w * h);
    for v in 0..h {
        for u in 0..w {
            let ax = (u as f32 + 0.5 - k[2]) / k[0];
            let ay = -(v as f32 + 0.5 - k[3]) / k[1];
            out.push(-d / (n[0] * ax + n[1] * ay - n[2]));
        }
    }
    out
}

/// DIODE's way of storing a normal given in OpenGL camera axes. Written out independently
/// of the loader from the source documented in `gb_finetune::normal_map`: Metric3D turns a
/// DIODE normal into its OpenCV frame (x right, y down, z forward) with `n[1:] *= -1`, so
/// DIODE = (x_cv, -y_cv, -z_cv), and OpenCV = (x_gl, -y_gl, -z_gl).
fn gl_to_diode_storage(n: [f32; 3]) -> [f32; 3] {
    let cv = [n[0], -n[1], -n[2]];
    [cv[0], -cv[1], -cv[2]]
}

fn simple_image(rel_dir: &'static str, stem: &'static str, n: [f32; 3]) -> FakeImage<'static> {
    let (w, h) = (8, 6);
    FakeImage {
        rel_dir,
        stem,
        w,
        h,
        depth: vec![2.0; w * h],
        mask: vec![1.0; w * h],
        normal: vec![n; w * h],
    }
}

#[test]
fn fake_tree_loads_sorted_with_captions_and_round_trips_normals() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let n = unit([0.2, -0.3, 0.9]);
    // written out of order; outdoor after indoors, scenes and scans sorted
    let mut b = simple_image(
        "val/outdoor/scene_00022/scan_00193",
        "00022_00193_outdoor_000_000",
        n,
    );
    b.mask[0] = 0.0; // a pixel without sensor return
    b.normal[1] = [0.0; 3]; // an invalid normal
    write_fake(root, &b);
    write_fake(
        root,
        &simple_image(
            "val/indoors/scene_00020/scan_00186",
            "00020_00186_indoors_010_020",
            n,
        ),
    );
    write_fake(
        root,
        &simple_image(
            "val/indoors/scene_00019/scan_00183",
            "00019_00183_indoors_000_010",
            n,
        ),
    );
    // a train image that the val split must not see
    write_fake(
        root,
        &simple_image(
            "train/indoors/scene_00001/scan_00001",
            "00001_00001_indoors_000_000",
            n,
        ),
    );
    let captions = root.join("captions.jsonl");
    std::fs::write(
        &captions,
        "{\"image\": \"val/indoors/scene_00019/scan_00183/00019_00183_indoors_000_010.png\", \"caption\": \"a kitchen\"}\n\
         {\"name\": \"00022_00193_outdoor_000_000\", \"text\": \"a parking lot\"}\n",
    )
    .unwrap();
    let ds = DiodeDataset::open(root, DiodeSplit::Val, Some(&captions)).unwrap();
    assert_eq!(ds.len(), 3);
    let rel: Vec<&str> = ds.entries().iter().map(|e| e.relative.as_str()).collect();
    assert_eq!(
        rel,
        [
            "val/indoors/scene_00019/scan_00183/00019_00183_indoors_000_010.png",
            "val/indoors/scene_00020/scan_00186/00020_00186_indoors_010_020.png",
            "val/outdoor/scene_00022/scan_00193/00022_00193_outdoor_000_000.png",
        ]
    );
    let s0 = ds.load(0).unwrap();
    assert_eq!((s0.width, s0.height), (8, 6));
    assert_eq!(s0.name, "00019_00183_indoors_000_010");
    assert_eq!(s0.caption, "a kitchen");
    assert_eq!(ds.load(1).unwrap().caption, "");
    // RGB round trip through the 8-bit PNG
    let x = 5;
    assert!((s0.rgb[x * 3] - 5.0 / 8.0).abs() < 1.0 / 255.0);
    assert!((s0.rgb[x * 3 + 2] - 0.25).abs() < 1.0 / 255.0);
    // the npy normal comes back as the expected normal-map pixel, (n + 1) / 2
    let want = [(n[0] + 1.0) / 2.0, (n[1] + 1.0) / 2.0, (n[2] + 1.0) / 2.0];
    let got = s0.normal.as_ref().unwrap();
    for px in got.chunks(3) {
        for c in 0..3 {
            assert!((px[c] - want[c]).abs() < 1e-6, "{px:?} vs {want:?}");
        }
    }
    assert!(s0.normal_valid.iter().all(|&v| v == 1.0));
    let s2 = ds.load(2).unwrap();
    assert_eq!(s2.caption, "a parking lot");
    let nm = s2.normal.as_ref().unwrap();
    assert_eq!(s2.normal_valid[0], 0.0, "depth mask 0 -> invalid");
    assert_eq!(s2.normal_valid[1], 0.0, "zero normal -> invalid");
    assert_eq!(s2.normal_valid[2], 1.0);
    assert_eq!(&nm[0..6], &[0.5; 6], "invalid pixels are the neutral value");
    // a normal stored facing away from the camera is flipped towards it
    let mut away = simple_image(
        "val/indoors/scene_00030/scan_00001",
        "00030_00001_indoors_000_000",
        [0.0, 0.0, -1.0],
    );
    away.normal[0] = [0.0, 0.0, -1.0];
    write_fake(root, &away);
    let ds = DiodeDataset::open(root, DiodeSplit::Val, None).unwrap();
    let s = ds.load(2).unwrap();
    assert_eq!(s.name, "00030_00001_indoors_000_000");
    assert_eq!(&s.normal.unwrap()[0..3], &[0.5, 0.5, 1.0]);
    // depth is readable too
    let d = ds.load_depth(0).unwrap();
    assert_eq!((d.width, d.height), (8, 6));
    assert!(d.depth.iter().all(|&z| z == 2.0));
    // the train split sees only its own image
    assert_eq!(
        DiodeDataset::open(root, DiodeSplit::Train, None)
            .unwrap()
            .len(),
        1
    );
    // (the mode names parse as the CLI spells them)
    assert_eq!(
        "normal-only".parse::<CaptionMode>().unwrap(),
        CaptionMode::NormalOnly
    );
}

#[test]
fn missing_and_partial_trees_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let n = [0.0, 0.0, 1.0];
    // no root
    let e = DiodeDataset::open(&root.join("nope"), DiodeSplit::Val, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("nope") && e.contains("DIODE root folder"), "{e}");
    // no split folder
    write_fake(
        root,
        &simple_image(
            "train/indoors/scene_00001/scan_00001",
            "00001_00001_indoors_000_000",
            n,
        ),
    );
    let e = DiodeDataset::open(root, DiodeSplit::Val, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("val") && e.contains("split folder"), "{e}");
    // split without scene types
    std::fs::create_dir_all(root.join("val/other")).unwrap();
    let e = DiodeDataset::open(root, DiodeSplit::Val, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("indoors/") && e.contains("outdoor/"), "{e}");
    // scene types without images
    std::fs::create_dir_all(root.join("val/indoors/scene_00019/scan_00183")).unwrap();
    let e = DiodeDataset::open(root, DiodeSplit::Val, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("*.png"), "{e}");
    // an image without its _normal.npy (the depth release alone)
    write_fake(
        root,
        &simple_image(
            "val/indoors/scene_00019/scan_00183",
            "00019_00183_indoors_000_010",
            n,
        ),
    );
    write_fake(
        root,
        &simple_image(
            "val/indoors/scene_00019/scan_00183",
            "00019_00183_indoors_000_020",
            n,
        ),
    );
    let scan = root.join("val/indoors/scene_00019/scan_00183");
    std::fs::remove_file(scan.join("00019_00183_indoors_000_020_normal.npy")).unwrap();
    let e = DiodeDataset::open(root, DiodeSplit::Val, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("00019_00183_indoors_000_020_normal.npy"), "{e}");
    assert!(
        e.contains("val_normals.tar.gz") && e.contains("1 of 2"),
        "{e}"
    );
    // a wrongly shaped normal npy: (H, W) instead of (H, W, 3)
    std::fs::write(
        scan.join("00019_00183_indoors_000_020_normal.npy"),
        encode_f32(&[6, 8], &[0.0; 48]).unwrap(),
    )
    .unwrap();
    let ds = DiodeDataset::open(root, DiodeSplit::Val, None).unwrap();
    assert!(ds.load(0).is_ok());
    let e = ds.load(1).unwrap_err().to_string();
    assert!(e.contains("00019_00183_indoors_000_020_normal.npy"), "{e}");
    assert!(e.contains("(6, 8, 3)"), "{e}");
    // a normal npy of another image size
    std::fs::write(
        scan.join("00019_00183_indoors_000_020_normal.npy"),
        encode_f32(&[4, 8, 3], &[0.0; 96]).unwrap(),
    )
    .unwrap();
    let e = ds.load(1).unwrap_err().to_string();
    assert!(
        e.contains("_020_normal.npy") && e.contains("[4, 8, 3]"),
        "{e}"
    );
    // a wrongly shaped depth mask
    std::fs::write(
        scan.join("00019_00183_indoors_000_010_depth_mask.npy"),
        encode_f32(&[6, 8, 2], &[1.0; 96]).unwrap(),
    )
    .unwrap();
    let e = ds.load(0).unwrap_err().to_string();
    assert!(
        e.contains("_010_depth_mask.npy") && e.contains("(6, 8)"),
        "{e}"
    );
    // garbage in an npy
    std::fs::write(
        scan.join("00019_00183_indoors_000_010_depth.npy"),
        b"nonsense",
    )
    .unwrap();
    let e = ds.load_depth(0).unwrap_err().to_string();
    assert!(e.contains("_010_depth.npy"), "{e}");
    // a missing depth mask is found at open time
    std::fs::remove_file(scan.join("00019_00183_indoors_000_010_depth_mask.npy")).unwrap();
    let e = DiodeDataset::open(root, DiodeSplit::Val, None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("00019_00183_indoors_000_010_depth_mask.npy"),
        "{e}"
    );
    // a bad caption file names its line
    let cap = root.join("c.jsonl");
    std::fs::write(&cap, "{\"image\": \"a.png\", \"caption\": \"x\"}\n{oops\n").unwrap();
    std::fs::write(
        scan.join("00019_00183_indoors_000_010_depth_mask.npy"),
        encode_f32(&[6, 8], &[1.0; 48]).unwrap(),
    )
    .unwrap();
    let e = DiodeDataset::open(root, DiodeSplit::Val, Some(&cap))
        .unwrap_err()
        .to_string();
    assert!(e.contains("c.jsonl") && e.contains("line 2"), "{e}");
}

fn tensor_normals(
    depth: Vec<f32>,
    w: usize,
    h: usize,
    k: Intrinsics,
    cfg: PlaneFitConfig,
) -> Vec<[f32; 3]> {
    let device = gb_core::BackendKind::Flex.device();
    let t = Tensor::<2>::from_data(TensorData::new(depth, [h, w]), &device);
    let v: Vec<f32> = depth_to_normals(t, k, cfg)
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    v.chunks(3).map(|c| [c[0], c[1], c[2]]).collect()
}

fn interior(w: usize, h: usize, border: usize) -> Vec<f32> {
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let inside = x >= border && y >= border && x + border < w && y + border < h;
            if inside {
                1.0
            } else {
                0.0
            }
        })
        .collect()
}

/// The convention test of the issue: a tilted plane seen by a pinhole camera. Its depth map
/// through the renderer's plane fit, and its analytic normal stored the DIODE way and loaded
/// by the DIODE loader, give the same normal-map image.
#[test]
fn diode_normals_and_renderer_plane_fit_agree() {
    let (w, h) = (64, 48);
    let k = diode_intrinsics(w, h);
    let dir = tempfile::tempdir().unwrap();
    for n_true in [
        unit([0.3, 0.4, 0.866]),
        unit([-0.5, 0.1, 0.7]),
        unit([0.1, -0.6, 0.5]),
    ] {
        let depth = plane_depth(w, h, k, n_true, 3.0);
        assert!(depth.iter().all(|&z| z > 0.0 && z.is_finite()));
        // renderer: depth -> plane fit -> normal-map image
        let intr = Intrinsics {
            fx: k[0],
            fy: k[1],
            cx: k[2],
            cy: k[3],
        };
        let cfg = PlaneFitConfig {
            kernel: 5,
            downsample: 1,
        };
        let fitted = tensor_normals(depth.clone(), w, h, intr, cfg);
        let (render_map, _) = normals_to_map(&fitted, None);
        // DIODE: the analytic normal stored DIODE's way, loaded by the loader
        let img = FakeImage {
            rel_dir: "val/indoors/scene_00001/scan_00001",
            stem: "00001_00001_indoors_000_000",
            w,
            h,
            depth: depth.clone(),
            mask: vec![1.0; w * h],
            normal: vec![gl_to_diode_storage(n_true); w * h],
        };
        write_fake(dir.path(), &img);
        let ds = DiodeDataset::open(dir.path(), DiodeSplit::Val, None).unwrap();
        let s = ds.load(0).unwrap();
        let diode_map = s.normal.unwrap();
        let weight = interior(w, h, 4);
        let err = masked_angular_error_deg(&render_map, &diode_map, &weight, w, h).unwrap();
        println!("{n_true:?}: renderer plane fit vs DIODE loader {err:.4} deg");
        assert!(err < 1.0, "renderer vs DIODE for {n_true:?}: {err} degrees");
        // and the loader's depth through the plane fit agrees as well
        let d = ds.load_depth(0).unwrap();
        let refit = tensor_normals(d.depth, w, h, intr, cfg);
        let (refit_map, _) = normals_to_map(&refit, None);
        let err = masked_angular_error_deg(&refit_map, &diode_map, &weight, w, h).unwrap();
        assert!(err < 1.0, "{err}");
        // a convention flip would be caught: y flipped gives a large error
        let flipped: Vec<f32> =
            vec![encode_normal([n_true[0], -n_true[1], n_true[2]]).0; w * h].concat();
        let bad = masked_angular_error_deg(&flipped, &render_map, &weight, w, h).unwrap();
        assert!(bad > 10.0, "{bad}");
    }
}

/// The procedural scenes' normal maps (the renderer's ray-traced ground truth) agree with
/// the plane fit on their own depth, on interior pixels of flat regions.
#[test]
fn procedural_normal_maps_agree_with_plane_fit_on_their_depth() {
    use gb_nerf::scene::procedural::{generate, normal_map_image, ProceduralOptions, SceneName};
    for name in [SceneName::Stairs, SceneName::Fence] {
        let opts = ProceduralOptions {
            name,
            seed: 1,
            width: 96,
            height: 72,
            views: 3,
            test_views: 1,
            dilate: 0,
        };
        let scene = generate(&opts).unwrap();
        let view = &scene.views[1];
        let (w, h) = (opts.width, opts.height);
        let cam = view.camera.to_camera_model();
        let fitted = tensor_normals(
            view.render.depth.clone(),
            w,
            h,
            Intrinsics::of(&cam),
            PlaneFitConfig {
                kernel: 3,
                downsample: 1,
            },
        );
        let (fit_map, _) = normals_to_map(&fitted, None);
        let truth = normal_map_image(&view.render);
        // interior pixels of flat regions: the ground-truth normal is the same over a 5x5
        // window, every pixel of it has a hit, and the inverse depth (affine in the pixel
        // coordinates on a plane) has no kink in it (no step onto a parallel surface behind)
        let nc = &view.render.normal_camera;
        let inv = |x: usize, y: usize| 1.0 / view.render.depth[y * w + x];
        let mut weight = vec![0.0f32; w * h];
        let mut count = 0;
        for y in 3..h - 3 {
            for x in 3..w - 3 {
                let c = nc[y * w + x];
                let flat = (0..25).all(|j| {
                    let (xx, yy) = (x + j % 5 - 2, y + j / 5 - 2);
                    let q = nc[yy * w + xx];
                    if view.render.depth[yy * w + xx] <= 0.0
                        || c[0] * q[0] + c[1] * q[1] + c[2] * q[2] < 0.99999
                    {
                        return false;
                    }
                    let tol = 1e-3 * inv(xx, yy);
                    let ddx = inv(xx - 1, yy) - 2.0 * inv(xx, yy) + inv(xx + 1, yy);
                    let ddy = inv(xx, yy - 1) - 2.0 * inv(xx, yy) + inv(xx, yy + 1);
                    ddx.abs() < tol && ddy.abs() < tol
                });
                if flat {
                    weight[y * w + x] = 1.0;
                    count += 1;
                }
            }
        }
        assert!(
            count > w * h / 5,
            "{name}: only {count} flat interior pixels"
        );
        let err = masked_angular_error_deg(&fit_map, &truth.data, &weight, w, h).unwrap();
        println!("{name}: {count} flat interior pixels, plane fit vs normal map {err:.4} deg");
        assert!(
            err < 0.5,
            "{name}: plane fit vs procedural normal map: {err} degrees"
        );
    }
}
