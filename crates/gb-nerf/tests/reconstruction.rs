//! End-to-end reconstruction on a small synthetic scene: training raises PSNR and recovers
//! the depth, the occupancy grid saves field evaluations, checkpoints resume exactly, and
//! the depth supervision is the one chosen (sparse points, dense maps or none).

use crate::nerf_common;
use nerf_common as common;

use gb_core::BackendKind;
use gb_nerf::render::image::NormalSource;
use gb_nerf::render::PlaneFitConfig;
use gb_nerf::sampler::{OccupancyConfig, SamplerConfig};
use gb_nerf::scene::colmap::SparseDepth;
use gb_nerf::scene::Scene;
use gb_nerf::scene::Split;
use gb_nerf::train::data::TrainData;
use gb_nerf::train::{DepthSupervision, NerfConfig, RenderSettings, TrainSettings, Trainer};

fn config(steps: usize, occupancy: bool) -> NerfConfig {
    NerfConfig {
        name: "test".into(),
        field: common::tiny_hash(),
        sampler: SamplerConfig {
            samples_per_ray: 32,
            occupancy: occupancy.then_some(OccupancyConfig {
                resolution: 16,
                update_every: 10,
                warmup_steps: 60,
                decay: 0.9,
                opacity_threshold: 0.01,
                cells_per_update: 0,
                early_stop_eps: 0.0,
            }),
        },
        train: TrainSettings {
            steps,
            rays_per_batch: 256,
            lr: 2e-2,
            lr_decay: 0.1,
            lr_decay_steps: 1000,
            depth: DepthSupervision::Dense,
            depth_weight: 0.1,
            distortion_weight: 0.0,
            checkpoint_every: 0,
            image_downscale: 1,
            seed: 3,
        },
        render: RenderSettings {
            normals: NormalSource::PlaneFit(PlaneFitConfig {
                kernel: 5,
                downsample: 1,
            }),
            chunk: 1024,
        },
    }
}

fn psnr(a: &[f32], b: &[f32]) -> f64 {
    let mse: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| ((x - y) as f64).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    -10.0 * mse.log10()
}

use crate::DEVICE_RNG as SEEDED_INIT;

#[test]
fn training_fits_the_plane_depth_and_normals() {
    let _guard = SEEDED_INIT.lock().unwrap_or_else(|e| e.into_inner());
    let scene = common::plane_scene(6, 24, 18);
    let mut trainer = Trainer::new(&scene, config(200, true), BackendKind::Flex).unwrap();
    let test = scene.split(Split::Test).next().unwrap();
    let before = psnr(
        &trainer.render(&test.camera).unwrap().rgb.data,
        &test.image.data,
    );
    let summary = trainer.fit(None, false).unwrap();
    let render = trainer.render(&test.camera).unwrap();
    let grid = trainer.occupancy.as_ref().unwrap();
    eprintln!(
        "occupied {:.3}, threshold {:.3}, max density {:.3}",
        grid.occupied_fraction(),
        grid.density_threshold,
        grid.density.iter().fold(0.0f32, |m, v| m.max(*v))
    );
    let after = psnr(&render.rgb.data, &test.image.data);
    eprintln!(
        "PSNR {before:.2} -> {after:.2} dB; eval/ray render {:.1} of 32, train mean {:.1}; {:.1}s",
        render.evaluations_per_ray, summary.mean_evaluations_per_ray, summary.seconds
    );
    assert!(
        after > before + 5.0 && after > 20.0,
        "PSNR {before} -> {after}"
    );
    // depth: the plane is at z-depth 2
    let mean_err: f32 =
        render.depth.iter().map(|d| (d - 2.0).abs()).sum::<f32>() / render.depth.len() as f32;
    assert!(mean_err < 0.15, "mean depth error {mean_err}");
    // the plane is flat and faces the camera
    let facing =
        render.normals.iter().filter(|n| n[2] > 0.9).count() as f32 / render.normals.len() as f32;
    let mean_z = render.normals.iter().map(|n| n[2]).sum::<f32>() / render.normals.len() as f32;
    eprintln!("normals: {facing:.3} with n_z > 0.9, mean n_z {mean_z:.3}");
    assert!(facing > 0.8, "normals facing the camera: {facing}");
    // the occupancy grid was updated and never evaluates more than the dense budget
    assert!(grid.density.iter().any(|d| *d > 0.0));
    assert!(render.evaluations_per_ray <= 32.0);
    // early ray termination: the samples behind where each ray runs out of light are not
    // evaluated, and the colour moves by at most eps
    let opaque = render.opacity.iter().filter(|a| **a > 0.9).count();
    let mut dense = None;
    for eps in [0.0f32, 0.1] {
        trainer.occupancy.as_mut().unwrap().early_stop_eps = eps;
        let r = trainer.render(&test.camera).unwrap();
        let Some((rgb, evals)) = dense.take() else {
            dense = Some((r.rgb.data.clone(), r.evaluations_per_ray));
            continue;
        };
        let rgb: Vec<f32> = rgb;
        let moved = rgb
            .iter()
            .zip(&r.rgb.data)
            .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
        eprintln!(
            "early stop at {eps}: {:.1} -> {:.1} evaluations per ray ({opaque} of {} rays \
             over 0.9 opacity), colour moved by at most {moved:.2e}",
            evals,
            r.evaluations_per_ray,
            render.opacity.len()
        );
        assert!(moved <= eps + 1e-5, "{moved}");
        // measured: 31.7 -> 31.0 (84 of 432 rays over 0.9 opacity after 200 steps)
        assert!(
            r.evaluations_per_ray < evals - 0.5,
            "{evals} -> {}",
            r.evaluations_per_ray
        );
    }
}

#[test]
fn checkpoint_resume_restores_the_state() {
    let _guard = SEEDED_INIT.lock().unwrap_or_else(|e| e.into_inner());
    let scene = common::plane_scene(3, 12, 10);
    let dir = tempfile::tempdir().unwrap();
    let ckpt = dir.path().join("ckpt.bin");
    let mut cfg = config(12, true);
    cfg.sampler.occupancy.as_mut().unwrap().warmup_steps = 5;
    cfg.sampler.occupancy.as_mut().unwrap().update_every = 5;
    cfg.train.checkpoint_every = 6;
    let mut a = Trainer::new(&scene, cfg, BackendKind::Flex).unwrap();
    a.fit(Some(&ckpt), false).unwrap();
    assert_eq!(a.step, 12);
    let b = Trainer::resume(&scene, &ckpt, BackendKind::Flex).unwrap();
    assert_eq!(b.step, 12);
    assert_eq!(b.occupancy, a.occupancy);
    let cam = &scene.views[0].camera;
    assert_eq!(
        a.render(cam).unwrap().rgb.data,
        b.render(cam).unwrap().rgb.data
    );
    // resume continues to a longer schedule
    let mut cfg = b.config.clone();
    cfg.train.steps = 15;
    let mut c = Trainer::resume(&scene, &ckpt, BackendKind::Flex).unwrap();
    c.config = cfg;
    let s = c.fit(Some(&ckpt), false).unwrap();
    assert_eq!((s.steps_run, c.step), (3, 15));
    // a damaged file is a clear error naming it
    std::fs::write(&ckpt, b"garbage").unwrap();
    let err = Trainer::resume(&scene, &ckpt, BackendKind::Flex)
        .err()
        .unwrap();
    assert!(err.to_string().contains("ckpt.bin"), "{err}");
}

/// `scene` with sparse points on every view (test views too): a keypoint every `step`
/// pixels at the plane's z-depth `depth`, plus two that must never supervise (outside the
/// image, behind the camera).
fn with_sparse_points(mut scene: Scene, step: usize, depth: f32) -> Scene {
    for v in &scene.views {
        let (w, h) = (v.camera.width, v.camera.height);
        let mut points = vec![
            SparseDepth {
                x: -1.0,
                y: 1.5,
                depth,
                error: 0.3,
            },
            SparseDepth {
                x: 1.5,
                y: 1.5,
                depth: -1.0,
                error: 0.3,
            },
        ];
        for y in (0..h).step_by(step) {
            for x in (0..w).step_by(step) {
                points.push(SparseDepth {
                    x: x as f32 + 0.5,
                    y: y as f32 + 0.5,
                    depth,
                    error: 0.3,
                });
            }
        }
        scene.sparse_depth.insert(v.name.clone(), points);
    }
    scene
}

#[test]
fn training_data_keeps_only_the_chosen_depth() {
    let (w, h) = (24, 18);
    let scene = with_sparse_points(common::plane_scene(3, w, h), 3, 2.0);
    let sparse = TrainData::from_scene(&scene, 2, DepthSupervision::Sparse).unwrap();
    assert!(sparse.views.iter().all(|v| v.depth.is_none()));
    // the points outside the mask (rows h/3..h/2, columns w/3..w/2 at full resolution,
    // dilated to whole 2x2 blocks by the downscale), at half the coordinates
    let masked_block = |x: usize, y: usize| {
        (0..2).any(|dy| {
            (0..2).any(|dx| {
                let (fx, fy) = (2 * (x / 2) + dx, 2 * (y / 2) + dy);
                (h / 3..h / 2).contains(&fy) && (w / 3..w / 2).contains(&fx)
            })
        })
    };
    let mut expected = Vec::new();
    for view in 0..3u32 {
        for y in (0..h).step_by(3) {
            for x in (0..w).step_by(3) {
                if !masked_block(x, y) {
                    expected.push((view, (x as f32 + 0.5) / 2.0, (y as f32 + 0.5) / 2.0));
                }
            }
        }
    }
    let got: Vec<(u32, f32, f32)> = sparse.sparse.iter().map(|p| (p.view, p.x, p.y)).collect();
    assert_eq!(got, expected);
    assert!(expected.len() < 3 * 8 * 6, "the mask removes some points");
    assert!(sparse.sparse.iter().all(|p| p.depth == 2.0));

    let dense = TrainData::from_scene(&scene, 2, DepthSupervision::Dense).unwrap();
    assert!(dense.sparse.is_empty());
    assert!(dense
        .views
        .iter()
        .all(|v| v.depth.as_ref().unwrap().len() == 12 * 9));
    let none = TrainData::from_scene(&scene, 2, DepthSupervision::None).unwrap();
    assert!(none.sparse.is_empty() && none.views.iter().all(|v| v.depth.is_none()));
    // the three train on the same pixels, and each resumes only its own checkpoints
    assert_eq!(sparse.pixels, dense.pixels);
    let fingerprints: std::collections::BTreeSet<u64> = [&sparse, &dense, &none]
        .iter()
        .map(|d| gb_nerf::train::checkpoint::data_fingerprint(d))
        .collect();
    assert_eq!(fingerprints.len(), 3);
}

#[test]
fn the_depth_setting_parses_and_names_the_choices() {
    for d in DepthSupervision::ALL {
        assert_eq!(d.name().parse::<DepthSupervision>().unwrap(), d);
    }
    let e = "colmap".parse::<DepthSupervision>().unwrap_err();
    assert!(
        e.contains("\"colmap\"") && e.contains("sparse, dense or none"),
        "{e}"
    );
    // the presets default to sparse; a config without the key reads as sparse
    for p in ["fast", "balanced", "paper"] {
        assert_eq!(
            NerfConfig::preset(p).unwrap().train.depth,
            DepthSupervision::Sparse
        );
    }
    let mut text = toml::to_string(&config(1, false)).unwrap();
    text = text.replace("depth = \"dense\"\n", "");
    let parsed = NerfConfig::from_toml(&text, std::path::Path::new("t.toml")).unwrap();
    assert_eq!(parsed.train.depth, DepthSupervision::Sparse);
    let bad = text.replace("depth_weight", "depth = \"lidar\"\ndepth_weight");
    let e = NerfConfig::from_toml(&bad, std::path::Path::new("t.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("t.toml") && e.contains("lidar"), "{e}");
}

/// Mean absolute z-depth error of a test view's render after `steps` of training.
fn depth_error_after(scene: &Scene, depth: DepthSupervision, steps: usize) -> f32 {
    let mut cfg = config(steps, false);
    cfg.train.depth = depth;
    let mut trainer = Trainer::new(scene, cfg, BackendKind::Flex).unwrap();
    trainer.fit(None, false).unwrap();
    let test = scene.split(Split::Test).next().unwrap();
    let render = trainer.render(&test.camera).unwrap();
    render.depth.iter().map(|d| (d - 2.0).abs()).sum::<f32>() / render.depth.len() as f32
}

#[test]
fn sparse_points_supervise_the_depth() {
    let _guard = SEEDED_INIT.lock().unwrap_or_else(|e| e.into_inner());
    let scene = with_sparse_points(common::plane_scene(4, 24, 18), 2, 2.0);
    let none = depth_error_after(&scene, DepthSupervision::None, 60);
    let sparse = depth_error_after(&scene, DepthSupervision::Sparse, 60);
    let dense = depth_error_after(&scene, DepthSupervision::Dense, 60);
    eprintln!(
        "mean depth error after 60 steps: none {none:.3}, sparse {sparse:.3}, dense {dense:.3}"
    );
    // measured: none 0.183, sparse 0.128, dense 0.116
    assert!(sparse < 0.8 * none, "sparse {sparse} vs none {none}");
    assert!(sparse < 1.25 * dense, "sparse {sparse} vs dense {dense}");
}

#[test]
fn a_training_step_reads_the_device_once() {
    let _guard = SEEDED_INIT.lock().unwrap_or_else(|e| e.into_inner());
    let scene = common::plane_scene(3, 12, 10);
    let mut cfg = config(30, true);
    let occ = cfg.sampler.occupancy.as_mut().unwrap();
    (occ.warmup_steps, occ.update_every) = (4, 4);
    let mut trainer = Trainer::new(&scene, cfg, BackendKind::Flex).unwrap();
    let mut per_step = Vec::new();
    for _ in 0..8 {
        let before = gb_core::device_reads();
        trainer.train_step().unwrap();
        per_step.push(gb_core::device_reads() - before);
    }
    // one read for the loss and the RGB MSE; the occupancy grid reads its densities on its
    // update steps (after steps 4 and 8: 16^3 cells in one chunk)
    assert_eq!(per_step, [1, 1, 1, 2, 1, 1, 1, 2]);
    // with early termination, the density pass adds one read per step
    trainer.occupancy.as_mut().unwrap().early_stop_eps = 1e-4;
    let before = gb_core::device_reads();
    trainer.train_step().unwrap();
    assert_eq!(gb_core::device_reads() - before, 2);
}
