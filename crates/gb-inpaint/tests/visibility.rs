//! Visibility-aware guidance on a small procedural stairs scene (flex, committed tiny
//! SD-inpainting fixture):
//!
//! - after a short reconstruction, the observed map of each masked view agrees with the
//!   map computed from the scene's ground-truth depths (same test, exact geometry);
//! - when every other view masks everything, nothing is observed;
//! - with `condition_on_observed`, the prior's mask (and so its gradient) shrinks to the
//!   unobserved pixels, and what the prior sees there changes.
//!
//! (That the gate scales the gradient per pixel and keeps the value is a unit test of
//! `gb_inpaint::visibility`.)

use std::path::Path;
use std::sync::MutexGuard;

use burn::tensor::{Tensor, TensorData};
use gb_core::BackendKind;
use gb_inpaint::crop::{latent_mask, CropGeometry};
use gb_inpaint::guidance::Modality;
use gb_inpaint::visibility::VisibilityConfig;
use gb_inpaint::{GuidedTrainer, MethodConfig, PromptOverrides, SceneCaptions};
use gb_nerf::render::rays::{all_pixels, camera_rays};
use gb_nerf::scene::procedural::render;
use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};
use gb_nerf::scene::{LoadOptions, Mask, Scene, Split};
use gb_nerf::train::data::{TrainData, TrainView};
use gb_nerf::train::{DepthSupervision, NerfConfig};

use crate::DEVICE_RNG as LOCK;

const KIND: BackendKind = BackendKind::Flex;

fn options() -> ProceduralOptions {
    ProceduralOptions {
        name: SceneName::Stairs,
        seed: 0,
        width: 80,
        height: 60,
        views: 8,
        test_views: 1,
        dilate: 1,
    }
}

fn scene(dir: &Path) -> Scene {
    procedural::write(&options(), dir).unwrap();
    gb_nerf::scene::load(dir, &LoadOptions::default())
        .unwrap()
        .1
}

fn trainer(scene: &Scene, dir: &Path, steps: usize, observed_weight: f64) -> GuidedTrainer {
    let mut m = MethodConfig::builtin("gb-nerf").unwrap();
    m.use_lora = false;
    m.visibility = VisibilityConfig {
        observed_weight,
        refresh_every: 1000,
        resolution: 32,
        ..VisibilityConfig::default()
    };
    let prior = crate::fixture_prior();
    let prompts = m.resolve_prompts(&SceneCaptions::read(dir), &PromptOverrides::default());
    let mut c = NerfConfig::preset("fast").unwrap();
    c.train.steps = steps;
    let mut t = GuidedTrainer::new(scene, c, m, Some((prior, prompts)), KIND).unwrap();
    for _ in 0..steps {
        // reconstruction only: the map is tested, not the guidance
        gb_nerf::train::Trainer::train_step(&mut t).unwrap();
    }
    t
}

/// The test lock, the scene's folder and a visibility-aware trainer (observed weight 0) after
/// `steps` reconstruction steps on the generated scene.
fn setup(steps: usize) -> (MutexGuard<'static, ()>, tempfile::TempDir, GuidedTrainer) {
    let guard = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(dir.path());
    let t = trainer(&scene, dir.path(), steps, 0.0);
    (guard, dir, t)
}

/// The z-depths of the training views (in the trainer's order) rendered without the object:
/// the surface that the removal should reveal.
fn object_free_depths(views: &[TrainView]) -> Vec<Vec<f32>> {
    let generated = procedural::generate(&options()).unwrap();
    let train: Vec<_> = generated
        .views
        .iter()
        .filter(|v| v.split == Split::Train)
        .collect();
    assert_eq!(train.len(), views.len());
    train
        .iter()
        .zip(views)
        .map(|(g, v)| {
            let c = g.camera.to_camera_model();
            for (a, b) in c.c2w.iter().flatten().zip(v.camera.c2w.iter().flatten()) {
                assert!((a - b).abs() < 1e-4, "view order differs");
            }
            render::render(&generated.spec.world, &g.camera, false).depth
        })
        .collect()
}

/// The observed flags of view `index`'s crop grid from ground-truth geometry: each masked
/// crop pixel is lifted with the object-free depth and tested against the other views'
/// masks and their depths with the object (what they actually see).
fn ground_truth_map(
    views: &[TrainView],
    free: &[Vec<f32>],
    index: usize,
    res: usize,
    tol: f32,
) -> Vec<bool> {
    let g = CropGeometry::new(&views[index], 0.25, res).unwrap();
    let camera = g.camera(res);
    let grid = all_pixels(res, res);
    let view_camera = &views[index].camera;
    let mut out = vec![false; res * res];
    for &i in &g.masked {
        let d = camera.ray_direction(grid[i][0], grid[i][1]);
        // z-depth of the crop pixel from the view's own ground truth (nearest pixel)
        let ([px, py], _) = view_camera
            .project([
                camera.origin()[0] + d[0],
                camera.origin()[1] + d[1],
                camera.origin()[2] + d[2],
            ])
            .unwrap();
        let (x, y) = (px as usize, py as usize);
        let w = views[index].image.width;
        let z = free[index][y * w + x];
        if z <= 0.0 {
            continue;
        }
        let rays = camera_rays(
            &camera,
            &[grid[i]],
            &gb_nerf::sampler::SceneSpace::Aabb {
                min: [-1e9; 3],
                max: [1e9; 3],
            },
            0.0,
            1e9,
        );
        let (o, dir) = (rays.origins[0], rays.dirs[0]);
        let p = [0, 1, 2].map(|k| o[k] + z * dir[k]);
        for (j, other) in views.iter().enumerate() {
            if j == index {
                continue;
            }
            let Some(([qx, qy], zq)) = other.camera.project(p) else {
                continue;
            };
            let (cw, ch) = (other.camera.width as f32, other.camera.height as f32);
            if !(qx >= 0.0 && qy >= 0.0 && qx < cw && qy < ch) {
                continue;
            }
            let k = qy as usize * other.image.width + qx as usize;
            if other.mask.as_ref().is_some_and(|m| m.data[k]) {
                continue;
            }
            let seen = other.depth.as_ref().unwrap()[k];
            if (seen - zq).abs() <= tol * zq {
                out[i] = true;
                break;
            }
        }
    }
    out
}

#[test]
fn observed_maps_agree_with_ground_truth_visibility() {
    let (_guard, dir, mut t) = setup(300);
    let views: Vec<usize> = (0..t.data.views.len())
        .filter(|&v| t.data.views[v].mask.is_some())
        .collect();
    assert!(views.len() >= 4);
    let free = object_free_depths(&t.data.views);
    // the training views with their ground-truth depth (the trainer's keep only what
    // supervises them: sparse points by default)
    let scene = gb_nerf::scene::load(dir.path(), &LoadOptions::default())
        .unwrap()
        .1;
    let downscale = t.nerf.config.train.image_downscale;
    let truth_views = TrainData::from_scene(&scene, downscale, DepthSupervision::Dense)
        .unwrap()
        .views;
    let (mut agree, mut total, mut obs_ours, mut obs_gt) = (0usize, 0usize, 0usize, 0usize);
    for &v in &views {
        let map = t
            .observed_map(v)
            .unwrap()
            .expect("visibility is on")
            .clone();
        let gt = ground_truth_map(&truth_views, &free, v, 32, 0.05);
        let g = CropGeometry::new(&t.data.views[v], 0.25, 32).unwrap();
        for &i in &g.masked {
            total += 1;
            agree += usize::from(map.observed[i] == gt[i]);
            obs_ours += usize::from(map.observed[i]);
            obs_gt += usize::from(gt[i]);
        }
    }
    let agreement = agree as f64 / total as f64;
    let (ours, truth) = (obs_ours as f64 / total as f64, obs_gt as f64 / total as f64);
    eprintln!("agreement {agreement:.3}, observed: ours {ours:.3}, ground truth {truth:.3}");
    assert!(truth > 0.2 && truth < 0.95, "ground-truth share {truth}");
    assert!(agreement >= 0.8, "agreement {agreement}");
    assert!((ours - truth).abs() < 0.15, "ours {ours} vs {truth}");
}

#[test]
fn nothing_is_observed_when_every_other_view_masks_everything() {
    let (_guard, _dir, mut t) = setup(20);
    let v = (0..t.data.views.len())
        .find(|&v| t.data.views[v].mask.is_some())
        .unwrap();
    for (j, view) in t.data.views.iter_mut().enumerate() {
        if j != v {
            let (w, h) = (view.image.width, view.image.height);
            view.mask = Some(Mask {
                width: w,
                height: h,
                data: vec![true; w * h],
            });
        }
    }
    let map = t.observed_map(v).unwrap().unwrap();
    assert!(map.masked > 0);
    assert_eq!(map.observed_share(), 0.0);
}

#[test]
fn conditioning_on_observed_pixels_leaves_only_unobserved_ones_to_the_prior() {
    let (_guard, _dir, mut t) = setup(150);
    let views = t.guidance.as_ref().unwrap().views.clone();
    // a view whose crop has both observed and unobserved masked pixels
    let view = views
        .into_iter()
        .find(|&v| {
            let share = t.observed_map(v).unwrap().unwrap().observed_share();
            share > 0.1 && share < 0.9
        })
        .expect("a view with a partly observed hole");
    let r = t.guidance.as_ref().unwrap().prior.info.resolution;
    let dims = r / 4;
    let noise: Vec<f32> = (0..4 * dims * dims)
        .map(|i| ((i * 7919) % 1000) as f32 / 500.0 - 1.0)
        .collect();
    let latent_gradient = |t: &mut GuidedTrainer| -> Vec<f32> {
        let (image, _) = t.rgb_prior_input(view).unwrap();
        let n = Tensor::<4>::from_data(
            TensorData::new(noise.clone(), [1, 4, dims, dims]),
            &KIND.device(),
        );
        let out = t
            .term(Modality::Rgb, view, image, 0, Some((400, n)))
            .unwrap();
        out.gradient.into_data().try_to_vec::<f32>().unwrap()
    };
    let plain = latent_gradient(&mut t);
    t.method.visibility.condition_on_observed = true;
    let conditioned = latent_gradient(&mut t);

    // the expected latent masks: the crop's mask, and the crop's mask less observed pixels
    let device = KIND.device();
    let crop_mask = CropGeometry::new(&t.data.views[view], 0.25, r)
        .unwrap()
        .mask_tensor(&device);
    let unobserved = t
        .observed_map(view)
        .unwrap()
        .unwrap()
        .weights(r, 0.0, &device);
    let flags = |m: Tensor<4>| -> Vec<bool> {
        let v = latent_mask(m, 4).into_data().try_to_vec::<f32>().unwrap();
        v.iter().map(|x| *x > 0.5).collect()
    };
    let whole = flags(crop_mask.clone());
    let hidden = flags(crop_mask * unobserved);
    let per_pixel =
        |g: &[f32], p: usize| -> f32 { (0..4).map(|c| g[c * dims * dims + p].abs()).sum() };
    let (mut shrunk, mut changed) = (0usize, 0usize);
    for p in 0..dims * dims {
        if !hidden[p] {
            assert_eq!(
                per_pixel(&conditioned, p),
                0.0,
                "latent pixel {p} is observed"
            );
        }
        if whole[p] && !hidden[p] && per_pixel(&plain, p) > 0.0 {
            shrunk += 1;
        }
        if hidden[p] {
            let d: f32 = (0..4)
                .map(|c| (conditioned[c * dims * dims + p] - plain[c * dims * dims + p]).abs())
                .sum();
            changed += usize::from(d > 1e-6);
        }
    }
    let n_hidden = hidden.iter().filter(|h| **h).count();
    eprintln!(
        "latent pixels: mask {}, unobserved {n_hidden}, shrunk {shrunk}, changed {changed}",
        whole.iter().filter(|h| **h).count()
    );
    assert!(n_hidden > 0 && hidden.iter().zip(&whole).all(|(h, w)| !h || *w));
    assert!(shrunk > 0, "the prior's mask lost no observed pixel");
    assert!(
        changed * 2 > n_hidden,
        "the conditioning changed the prior's answer on {changed} of {n_hidden} pixels"
    );
}
