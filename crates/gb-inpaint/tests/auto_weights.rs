//! Weights each scene picks for itself ([`gb_inpaint::auto`]), on a small procedural stairs
//! scene with the committed tiny SD-inpainting fixture, on flex:
//!
//! - the pseudo-holes are seen by no training view: no trained pixel's ray and no sparse point
//!   that supervises crosses one, each stays clear of the object's masks, and masked views
//!   show each;
//! - the choice picks guidance when the guidance is the oracle's exact score of the true
//!   images, and 0 when the same pull points at noise.

use std::path::Path;

use gb_core::{BackendKind, RgbImage};
use gb_diffusion::distill::{Branch, GuidanceMethod, PriorInputMode};
use gb_inpaint::auto::{choose_weights, pseudo_hole, AutoInputs, Weight};
use gb_inpaint::{MethodConfig, PromptOverrides, SceneCaptions};
use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};
use gb_nerf::scene::{LoadOptions, Scene, Split};
use gb_nerf::train::data::TrainData;
use gb_nerf::train::{DepthSupervision, NerfConfig};

use crate::DEVICE_RNG as LOCK;

const KIND: BackendKind = BackendKind::Flex;

fn scene(dir: &Path) -> Scene {
    scene_of(dir, SceneName::Stairs, 3)
}

fn scene_of(dir: &Path, name: SceneName, seed: u64) -> Scene {
    scene_with_views(dir, name, seed, 6)
}

/// A 128x96 procedural scene of `views` views, one of them a test view.
fn scene_with_views(dir: &Path, name: SceneName, seed: u64, views: usize) -> Scene {
    let opts = ProceduralOptions {
        name,
        seed,
        width: 128,
        height: 96,
        views,
        test_views: 1,
        dilate: 1,
    };
    procedural::write(&opts, dir).unwrap();
    gb_nerf::scene::load(dir, &LoadOptions::default())
        .unwrap()
        .1
}

/// The masked training views that show the pseudo-hole (`holes`, per training view),
/// asserting that none withholds a pixel of the object's mask.
fn masked_views_showing(s: &Scene, holes: &[Option<gb_nerf::scene::Mask>]) -> usize {
    let mut shown = 0;
    for (h, v) in holes.iter().zip(s.split(Split::Train)) {
        let (Some(h), Some(m)) = (h, &v.mask) else {
            continue;
        };
        shown += 1;
        let overlap = h
            .data
            .iter()
            .zip(&m.data)
            .filter(|(a, b)| **a && **b)
            .count();
        assert_eq!(
            overlap, 0,
            "{}: view {} withholds object pixels",
            s.name, v.name
        );
    }
    shown
}

#[test]
fn the_pseudo_holes_are_seen_by_no_training_view() {
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let placed = pseudo_hole::place_holes(&s, 1.0, 2).unwrap();
    assert_eq!(placed.len(), 2);
    for p in &placed {
        let shown = masked_views_showing(&s, &pseudo_hole::withheld(&s, &p.hole));
        assert!(
            shown >= 2,
            "{shown} masked views show the pseudo-hole {p:?}"
        );
    }
    let each: Vec<_> = placed
        .iter()
        .map(|p| pseudo_hole::withheld(&s, &p.hole))
        .collect();
    let holes = pseudo_hole::union_per_view(&each);
    // a trial's training data: the pseudo-hole as the mask, the object withheld
    let mut trial = s.clone();
    let mut objects = Vec::new();
    for (v, h) in trial
        .views
        .iter_mut()
        .filter(|v| v.split == Split::Train)
        .zip(&holes)
    {
        objects.push(v.mask.clone());
        v.mask = h.clone();
    }
    let mut data = TrainData::from_scene(&trial, 1, DepthSupervision::Sparse).unwrap();
    let before = (data.pixels.len(), data.sparse.len());
    data.withhold(&objects).unwrap();
    assert!(data.pixels.len() < before.0 && data.sparse.len() < before.1);
    for p in &data.pixels {
        let c = &data.views[p.view as usize].camera;
        let d = c.ray_direction(p.x as f32 + 0.5, p.y as f32 + 0.5);
        for h in &placed {
            assert!(!h.hole.hit(c.origin(), d), "pixel {p:?} sees {h:?}");
        }
        assert!(!objects[p.view as usize]
            .as_ref()
            .is_some_and(|m| m.data[p.y as usize * m.width + p.x as usize]));
    }
    for p in &data.sparse {
        let c = &data.views[p.view as usize].camera;
        let world = c.unproject(p.x, p.y, p.depth);
        for h in &placed {
            assert!(!h.hole.contains(world), "sparse point {p:?} lies in {h:?}");
            assert!(!h.hole.hit(c.origin(), c.ray_direction(p.x, p.y)));
        }
    }
    // each hole is centred on a surface: its pixels were training pixels before
    let all = TrainData::from_scene(&s, 1, DepthSupervision::None).unwrap();
    for h in &placed {
        let seen_before = all
            .pixels
            .iter()
            .filter(|p| {
                let c = &all.views[p.view as usize].camera;
                h.hole.hit(
                    c.origin(),
                    c.ray_direction(p.x as f32 + 0.5, p.y as f32 + 0.5),
                )
            })
            .count();
        assert!(seen_before > 50, "{seen_before} for {h:?}");
    }
}

#[test]
fn a_pseudo_hole_fits_every_procedural_scene_clear_of_its_masks() {
    // fence's mask spans much of each view: its pseudo-hole is a smaller cube
    for (name, seed) in [
        (SceneName::Stairs, 100),
        (SceneName::Fence, 100),
        (SceneName::Alcove, 100),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let s = scene_of(dir.path(), name, seed);
        let hole = pseudo_hole::place(&s, 1.0).unwrap_or_else(|e| panic!("{name:?}: {e}"));
        let shown = masked_views_showing(&s, &pseudo_hole::withheld(&s, &hole));
        assert!(shown >= 2, "{name:?}: {shown} masked views show it");
    }
}

/// The RGB-only SDS method (guidance scale 1) whose prompt and unconditional branches the
/// oracle answers from `clean`: its pull is exactly toward `clean`'s latents.
fn oracle_method(clean: &Path) -> MethodConfig {
    let mut m = MethodConfig::builtin("bsd").unwrap();
    m.normal = None;
    m.lambda_normal = Weight::Fixed(0.0);
    m.lambda_rgb = Weight::Auto;
    m.auto.rgb = vec![0.0, 1.0];
    m.auto.trial_steps = 1.0;
    m.prior_input = PriorInputMode::PasteOnGroundTruth;
    m.rgb.as_mut().unwrap().guidance = GuidanceMethod::Sds {
        guidance_scale: 1.0,
    };
    m.oracle.clean = Some(clean.to_path_buf());
    m.oracle.branches = vec![Branch::Text, Branch::Unconditional];
    m.validate().unwrap();
    m
}

fn config() -> NerfConfig {
    let mut c = NerfConfig::preset("fast").unwrap();
    c.train.rays_per_batch = 256;
    c.train.steps = 80;
    c.sampler.samples_per_ray = 24;
    c
}

fn choose(s: &Scene, dir: &Path, clean: &Path, out: &Path) -> gb_inpaint::auto::AutoReport {
    choose_with(s, dir, oracle_method(clean), clean, out)
}

fn choose_with(
    s: &Scene,
    dir: &Path,
    method: MethodConfig,
    clean: &Path,
    out: &Path,
) -> gb_inpaint::auto::AutoReport {
    let config = config();
    let images = gb_inpaint::oracle::load_object_free(s, clean, 1, "[oracle] clean").unwrap();
    let prompts = method.resolve_prompts(&SceneCaptions::read(dir), &PromptOverrides::default());
    let mut prior = Some(crate::fixture_prior());
    let inputs = AutoInputs {
        scene: s,
        method: &method,
        config: &config,
        prompts: &prompts,
        oracle: Some(&images),
        devices: KIND.into(),
        weights: gb_eval::default_weights_dir(),
        out,
        progress: false,
    };
    let report = choose_weights(&inputs, &mut prior).unwrap();
    assert!(prior.is_some(), "the prior is handed back");
    // the second call reads the cache
    let again = choose_weights(&inputs, &mut prior).unwrap();
    assert!(again.cached && !report.cached);
    assert_eq!(again.trials, report.trials);
    report
}

#[test]
fn auto_weights_choose_the_oracles_guidance_and_refuse_a_pull_toward_noise() {
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let truth = choose(
        &s,
        dir.path(),
        &dir.path().join("clean"),
        &dir.path().join("truth"),
    );
    // the same pull, toward noise images
    let noise_dir = dir.path().join("noise");
    std::fs::create_dir_all(&noise_dir).unwrap();
    let mut state = 12345u64;
    for v in s.split(Split::Train) {
        let (w, h) = (v.image.width, v.image.height);
        let data = (0..w * h * 3)
            .map(|_| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (state >> 40) as f32 / (1u64 << 24) as f32
            })
            .collect();
        let img = RgbImage {
            width: w,
            height: h,
            data,
        };
        gb_core::write_rgb_png(&noise_dir.join(format!("{}.png", v.name)), &img).unwrap();
    }
    let noise = choose(&s, dir.path(), &noise_dir, &dir.path().join("noise-run"));
    for (name, r) in [("truth", &truth), ("noise", &noise)] {
        println!("{name}: chose lambda_rgb {} from", r.lambda_rgb);
        for t in &r.trials {
            println!(
                "  {} : ssim {:?} lpips {:?} d_psnr {:?} rank {}",
                t.lambda_rgb, t.ssim_bbox, t.lpips_bbox, t.d_psnr_bbox, t.rank_sum
            );
        }
    }
    assert_eq!(truth.trials.len(), 2);
    assert!(truth.withheld_views >= 2 && truth.withheld_pixels > 50);
    // the trials continue from one unguided prefix: 0.75 of their 80 steps
    assert_eq!((truth.trial_steps, truth.prefix_steps), (80, 60));
    assert_eq!(truth.holes.len(), 2);
    assert!(truth.trials.iter().all(|t| t.per_hole.len() == 2));
    // the pooled score lies between the holes' own (a mean over both holes' boxes)
    for t in &truth.trials {
        let own: Vec<f64> = t.per_hole.iter().map(|h| h.ssim_bbox.unwrap()).collect();
        let pooled = t.ssim_bbox.unwrap();
        assert!(
            own[0].min(own[1]) <= pooled && pooled <= own[0].max(own[1]),
            "{t:?}"
        );
    }
    // the prefix's checkpoint is gone once the trials are done
    assert!(!dir.path().join("truth/auto/prefix.bin").exists());
    // the true pull improves the hidden colour; the noise pull ruins it
    let ssim = |r: &gb_inpaint::auto::AutoReport, k: usize| r.trials[k].ssim_bbox.unwrap();
    assert!(ssim(&truth, 1) > ssim(&truth, 0), "{truth:?}");
    assert!(ssim(&noise, 1) < ssim(&noise, 0), "{noise:?}");
    assert_eq!(truth.lambda_rgb, 1.0);
    assert_eq!(noise.lambda_rgb, 0.0);
    // the unguided trial is the same in both (the oracle only acts through the guidance)
    assert_eq!(truth.trials[0].ssim_bbox, noise.trials[0].ssim_bbox);

    // with the default's geometry term, the guided trial holds its pseudo-holes' depth to the
    // shared unguided prefix: it trains otherwise, and the true pull still wins
    let clean = dir.path().join("clean");
    let mut held = oracle_method(&clean);
    held.geometry = MethodConfig::builtin("gb-nerf-unseen").unwrap().geometry;
    assert!(held.holds_geometry(false));
    let held = choose_with(&s, dir.path(), held, &clean, &dir.path().join("held"));
    println!("held: {:?}", held.trials);
    assert_eq!(held.trials[0].ssim_bbox, truth.trials[0].ssim_bbox);
    assert_ne!(held.trials[1].d_psnr_bbox, truth.trials[1].d_psnr_bbox);
    assert_eq!(held.lambda_rgb, 1.0);
}

/// Issue 45: on `alcove` the hole hides the recess, so a pseudo-hole on the flat plaster of
/// the wall's face (where the nearest-first rule of before put it on tuning seed 101) tests
/// the guidance on the wrong surface. The pseudo-hole most like the hole lies in the recess:
/// behind the wall's face (z = -2), on its inner sides, whose rings show the tiles (at this
/// size no cube on the tiles themselves clears the vase's margin in every view). The second
/// lies on another surface.
#[test]
fn the_pseudo_hole_most_like_the_alcove_s_hole_lies_in_the_recess() {
    for seed in [100, 101] {
        let dir = tempfile::tempdir().unwrap();
        let s = scene_of(dir.path(), SceneName::Alcove, seed);
        let holes = pseudo_hole::place_holes(&s, 1.0, 2).unwrap();
        assert_eq!(holes.len(), 2, "seed {seed}");
        let centre_z = |h: &gb_inpaint::auto::PlacedHole| 0.5 * (h.hole.min[2] + h.hole.max[2]);
        assert!(
            centre_z(&holes[0]) < -2.1,
            "seed {seed}: the first pseudo-hole is centred at z = {} (the wall's face is at -2)",
            centre_z(&holes[0])
        );
        assert!(holes[0].resemblance < holes[1].resemblance);
        assert!(holes[0].appearance.distance(&holes[1].appearance) >= 0.05);
        let shown = masked_views_showing(&s, &pseudo_hole::withheld(&s, &holes[1].hole));
        assert!(
            shown >= 2,
            "seed {seed}: {shown} masked views show the second"
        );
    }
}

/// A capture with neither COLMAP points nor depth maps (SPIn-NeRF's `statue`) cannot place a
/// pseudo-hole from its own data; a short unguided scout field's depth stands in. Its points
/// lie near the true surfaces (colour alone leaves them loose), and the pseudo-holes placed on
/// them are clear of the masks and shown by the masked views.
#[test]
fn a_capture_without_points_or_depth_places_its_pseudo_holes_on_a_scout_field() {
    use gb_inpaint::auto::scout;
    const SCOUT_STEPS: usize = 300;
    let _lock = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    // a capture's many views (statue has 29): colour alone pins the surface down
    let truth = scene_with_views(dir.path(), SceneName::Stairs, 100, 17);
    let mut bare = truth.clone();
    bare.sparse_depth.clear();
    bare.views.iter_mut().for_each(|v| v.depth = None);
    assert!(scout::has_surface(&truth) && !scout::has_surface(&bare));
    let err = pseudo_hole::place(&bare, 1.0).unwrap_err();
    assert!(err.contains("no surface points"), "{err}");

    let (scouted, source) =
        scout::scouted(&bare, &config(), &KIND.into(), SCOUT_STEPS, false).unwrap();
    let mut errors = Vec::new();
    for v in truth.split(Split::Train) {
        let depth = v.depth.as_ref().unwrap();
        for p in &scouted.sparse_depth[&v.name] {
            let z = depth[p.y as usize * v.image.width + p.x as usize];
            errors.push((p.depth - z).abs() / z);
        }
    }
    let scout::SurfaceSource::Scout { steps, points, .. } = source else {
        panic!("{source:?}")
    };
    assert_eq!((steps, points), (SCOUT_STEPS, errors.len()));
    errors.sort_by(f32::total_cmp);
    let median = errors[errors.len() / 2];
    let within = errors.iter().filter(|e| **e <= 0.25).count() as f32 / errors.len() as f32;
    eprintln!(
        "scout: {} points, median relative depth error {median:.4}, {:.1}% within 25%",
        errors.len(),
        100.0 * within
    );
    // measured: median 0.066, 66% within 25% (colour alone leaves floaters: a long tail); the
    // rendered depth, which adds the missing opacity at the far bound, gave a median of 0.23
    assert!(errors.len() >= 1000, "{} points", errors.len());
    assert!(median <= 0.1, "median relative depth error {median}");
    assert!(within >= 0.6, "{within} of the points within 25%");

    let placed = pseudo_hole::place_holes(&scouted, 1.0, 2).unwrap();
    for p in &placed {
        let shown = masked_views_showing(&truth, &pseudo_hole::withheld(&truth, &p.hole));
        assert!(
            shown >= 2,
            "{shown} masked views show the pseudo-hole {p:?}"
        );
    }
}
