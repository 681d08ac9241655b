//! The geometry term (issue 49, `gb_inpaint::geometry`) on small procedural scenes (100x75,
//! 8 views) whose `clean/` holds the exact object-free training views: an exact reference view
//! knows the hidden surface's colour but not where it lies, and moves the depth through the
//! masked pixels away from what the field renders without it. Held by the geometry term, that
//! depth stays near the unguided field's (`stairs`), and a hidden plane stays at its true
//! depth (`wall`).

use std::path::{Path, PathBuf};

use gb_core::BackendKind;
use gb_inpaint::geometry::HiddenDepth;
use gb_inpaint::reference::load_references;
use gb_inpaint::run::probe::{write_probe, DepthError};
use gb_inpaint::run::render_test_views;
use gb_inpaint::{GuidedTrainer, MethodConfig};
use gb_nerf::scene::{load, LoadOptions, Scene};
use gb_nerf::train::NerfConfig;
use gb_tests::{assert_success, path_str as s, small_preset, workspace_root, xtask};

/// Steps of each run; the reference starts at half of them.
const STEPS: usize = 200;

/// The built-in scene `name` at 100x75, 8 views, one of them a test view.
fn procedural(dir: &Path, name: &str, seed: &str) -> (PathBuf, Scene) {
    let d = dir.join("scene");
    let out = xtask(&[
        "scene",
        "--name",
        name,
        "--width",
        "100",
        "--height",
        "75",
        "--views",
        "8",
        "--test-views",
        "1",
        "--seed",
        seed,
        "--out",
        s(&d),
    ]);
    assert_success(&out, "scene");
    let (_, scene) = load(&d, &LoadOptions::default()).unwrap();
    (d, scene)
}

/// The procedural scene `name` (seed 3) in `dir`, the small test preset, and the reference
/// pair `VIEW.png=IMAGE` of its first masked training view with that view's exact
/// object-free image.
fn with_exact_reference(dir: &Path, name: &str) -> (Scene, PathBuf, String) {
    let (d, scene) = procedural(dir, name, "3");
    let preset = small_preset(dir, None);
    let view = crate::reference::masked_view(&scene);
    let pair = format!(
        "{view}.png={}",
        s(&d.join("clean").join(format!("{view}.png")))
    );
    (scene, preset, pair)
}

fn trained(
    scene: &Scene,
    preset: &Path,
    method: MethodConfig,
    setup: impl Fn(&mut GuidedTrainer),
) -> GuidedTrainer {
    let mut config = NerfConfig::preset(s(preset)).unwrap();
    config.train.steps = STEPS;
    let mut t = GuidedTrainer::new(scene, config, method, None, BackendKind::Flex).unwrap();
    setup(&mut t);
    t.fit(&gb_inpaint::trainer::FitOptions {
        checkpoint: None,
        log: None,
        append_log: false,
        progress: false,
    })
    .unwrap();
    t
}

/// Mean of `f(profile, target depth)` over `t`'s rays through the target pixels.
fn mean_over_targets(
    t: &GuidedTrainer,
    targets: &HiddenDepth,
    f: impl Fn(&gb_nerf::render::RayProfile, f32) -> f32,
) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for view in 0..t.data.views.len() {
        let (px, want): (Vec<[f32; 2]>, Vec<f32>) = targets
            .pixels
            .iter()
            .filter(|p| p.view == view && p.depth > 0.0)
            .map(|p| (p.pixel, p.depth))
            .unzip();
        if px.is_empty() {
            continue;
        }
        let got = t.ray_profiles(&t.data.views[view].camera, &px).unwrap();
        for (g, &w) in got.iter().zip(&want) {
            sum += f(g, w) as f64;
            n += 1;
        }
    }
    assert!(n > 100, "only {n} target pixels");
    sum / n as f64
}

/// Mean `|depth - target| / target` of `t`'s render through the target pixels.
fn deviation(t: &GuidedTrainer, targets: &HiddenDepth) -> f64 {
    mean_over_targets(t, targets, |g, w| ((g.depth - w) / w).abs())
}

#[test]
fn the_geometry_term_holds_the_hidden_depth_under_an_exact_reference() {
    // trains in-process from the seeded device RNG (crate::DEVICE_RNG)
    let _rng = crate::DEVICE_RNG.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let (scene, preset, pair) = with_exact_reference(dir.path(), "stairs");
    let none = MethodConfig::builtin("none").unwrap();

    // the built-in `none`'s table: depth_weight 1 through the guided crop
    let geometry = none.geometry.clone();
    assert!(geometry.enabled());
    let unguided = trained(&scene, &preset, none.clone(), |_| {});
    let targets =
        HiddenDepth::from_field(&unguided.nerf, geometry.clone(), none.crop_margin).unwrap();
    assert!(targets.pixels.len() > 100, "{}", targets.pixels.len());
    drop(unguided);

    let references = || load_references(&scene, std::slice::from_ref(&pair), 1).unwrap();
    let free = trained(&scene, &preset, none.clone(), |t| {
        t.set_references(references())
    });
    let moved = deviation(&free, &targets);
    drop(free);
    let mut method = none;
    method.geometry = geometry;
    let held = trained(&scene, &preset, method, |t| {
        t.set_references(references());
        t.set_hidden_depth(targets.clone());
    });
    let kept = deviation(&held, &targets);
    assert!(
        kept < 0.7 * moved,
        "depth through the masked pixels off the unguided field's by {kept:.4} with the \
         geometry term, {moved:.4} without"
    );
}

/// Mean spread of `t`'s weights in depth (their standard deviation over the target depth)
/// along the rays through the target pixels.
fn spread(t: &GuidedTrainer, targets: &HiddenDepth) -> f64 {
    mean_over_targets(t, targets, |g, w| g.spread() / w)
}

/// `[geometry] distortion_weight` (mip-NeRF 360's loss on the term's rays) thins the held
/// surface: under an exact reference the term holds the crop's expected depth, and the
/// distortion loss on the same rays gathers their weight around it (issue 49: on `stairs` the
/// held surface is smeared in depth, spread 0.18 to 0.19 of the depth against 0.14 to 0.15
/// for `none`). Here, 200 steps of the small preset: spread 0.207 of the depth without it,
/// 0.141 at 0.01 (0.046 at 0.1), while the depth through the held pixels stays within 1.5% of
/// the unguided field's (1.1% without).
#[test]
fn the_distortion_weight_thins_the_held_surface() {
    // trains in-process from the seeded device RNG (crate::DEVICE_RNG)
    let _rng = crate::DEVICE_RNG.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let (scene, preset, pair) = with_exact_reference(dir.path(), "stairs");
    let none = MethodConfig::builtin("none").unwrap();
    let unguided = trained(&scene, &preset, none.clone(), |_| {});
    let targets =
        HiddenDepth::from_field(&unguided.nerf, none.geometry.clone(), none.crop_margin).unwrap();
    drop(unguided);
    let references = load_references(&scene, std::slice::from_ref(&pair), 1).unwrap();
    let held = |distortion: f64| {
        let mut method = none.clone();
        method.geometry.distortion_weight = distortion;
        let mut targets = targets.clone();
        targets.config = method.geometry.clone();
        let t = trained(&scene, &preset, method, |t| {
            t.set_references(references.clone());
            t.set_hidden_depth(targets.clone());
        });
        (spread(&t, &targets), deviation(&t, &targets))
    };
    let (plain, plain_dev) = held(0.0);
    let (thin, thin_dev) = held(DISTORTION);
    assert!(
        thin < 0.8 * plain,
        "held rays' spread {thin:.4} with distortion_weight {DISTORTION}, {plain:.4} without"
    );
    assert!(
        thin_dev < 0.02,
        "depth off the held depth by {thin_dev:.4} with distortion_weight {DISTORTION} \
         ({plain_dev:.4} without)"
    );
}

/// The distortion weight of [`the_distortion_weight_thins_the_held_surface`].
const DISTORTION: f64 = 0.01;

/// The test view's hidden depth error against the truth, through `--probe`'s measure.
fn hidden_error(dir: &Path, scene: &Scene, t: &GuidedTrainer) -> DepthError {
    let views = render_test_views(&dir.join("renders"), scene, t).unwrap();
    let report = write_probe(&dir.join("probe"), scene, t, &views.renders).unwrap();
    assert_eq!(report.views.len(), 1);
    report.views[0].hidden.clone()
}

/// The largest mean `|depth - true| / true` of the hidden wall in the test view.
const WALL_MEAN_ERROR: f64 = 0.06;
/// The smallest share of the hidden wall's pixels within 5% of the true depth.
const WALL_WITHIN_5_PERCENT: f64 = 0.4;

/// Issue 49's test: on `wall` (a flat brick wall behind a vase), an exact reference view leaves
/// the hidden wall, as the test view sees it, at its true depth within [`WALL_MEAN_ERROR`] and
/// [`WALL_WITHIN_5_PERCENT`]. Without the geometry term the same reference moved it (scene
/// seed 3, 200 steps: mean error 7.7%, 25% of its pixels within 5%; held: 5.1% and 53%; the
/// unguided field: 4.9% and 53%; scene seed 5: 7.4% / 23%, held 6.0% / 48%, unguided 6.5% /
/// 38%; seed 4, where the reference hardly moves it: 5.5% / 49%, 5.3% / 52%, 5.6% / 46%).
#[test]
fn an_exact_reference_leaves_the_hidden_wall_at_its_true_depth() {
    let _rng = crate::DEVICE_RNG.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let (scene, preset, pair) = with_exact_reference(dir.path(), "wall");
    // the built-in `none`'s table: depth_weight 1 through the guided crop
    let none = MethodConfig::builtin("none").unwrap();
    let unguided = trained(&scene, &preset, none.clone(), |_| {});
    let targets =
        HiddenDepth::from_field(&unguided.nerf, none.geometry.clone(), none.crop_margin).unwrap();
    drop(unguided);
    let references = load_references(&scene, std::slice::from_ref(&pair), 1).unwrap();
    let held = trained(&scene, &preset, none, |t| {
        t.set_references(references.clone());
        t.set_hidden_depth(targets.clone());
    });
    let wall = hidden_error(&dir.path().join("held"), &scene, &held);
    assert!(
        wall.mean_abs < WALL_MEAN_ERROR && wall.within_tolerance > WALL_WITHIN_5_PERCENT,
        "the hidden wall under an exact reference: mean depth error {:.2}% (at most {:.0}%), \
         {:.0}% of its pixels within 5% of the truth (at least {:.0}%)",
        100.0 * wall.mean_abs,
        100.0 * WALL_MEAN_ERROR,
        100.0 * wall.within_tolerance,
        100.0 * WALL_WITHIN_5_PERCENT
    );
}

/// A 40-step run of `method` on the scene `d` with `preset`, seed 0, into `dir/out`, with
/// `dir/baseline` as its `--baseline` when given; no export, no orbit.
fn short_run(
    dir: &Path,
    d: &Path,
    preset: &Path,
    method: &str,
    out: &str,
    baseline: Option<&str>,
) -> gb_inpaint::RunSpec {
    gb_inpaint::RunSpec {
        scene: Some(d.to_path_buf()),
        method: Some(method.into()),
        preset: s(preset).into(),
        device: BackendKind::Flex,
        steps: Some(40),
        seed: Some(0),
        baseline: baseline.map(|b| dir.join(b)),
        export: gb_inpaint::export::ExportMode::None,
        orbit_frames: 0,
        out: dir.join(out),
        ..gb_inpaint::RunSpec::default()
    }
}

/// A run that holds the geometry term, given a finished `none` run of the same configuration
/// as `--baseline`, reads that run's field for its unguided pass instead of training it
/// (`metrics.json`'s `unguided_from`), and ends exactly where the run that trained it ends;
/// a `none` baseline of another seed is not that field, and is not read.
#[test]
fn a_matching_none_baseline_is_read_as_the_unguided_field() {
    // trains in-process from the seeded device RNG (crate::DEVICE_RNG)
    let _rng = crate::DEVICE_RNG.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let (d, scene) = procedural(dir.path(), "stairs", "3");
    let preset = small_preset(dir.path(), None);
    let view = crate::reference::masked_view(&scene);
    let pair = format!(
        "{view}.png={}",
        s(&d.join("clean").join(format!("{view}.png")))
    );
    let run = |out: &str, seed: u64, references: Vec<String>, baseline: Option<&str>| {
        gb_inpaint::run::run(&gb_inpaint::RunSpec {
            seed: Some(seed),
            references,
            ..short_run(dir.path(), &d, &preset, "none", out, baseline)
        })
        .unwrap()
    };
    let plain = run("none", 0, vec![], None);
    assert_eq!(
        (plain.unguided_seconds, &plain.unguided_from),
        (None, &None)
    );
    run("none-seed-1", 1, vec![], None);

    let trained = run("held", 0, vec![pair.clone()], None);
    assert!(trained.unguided_seconds.is_some());
    assert_eq!(trained.unguided_from, None);
    let reused = run("held-from-none", 0, vec![pair.clone()], Some("none"));
    assert_eq!(
        reused.unguided_from,
        Some(dir.path().join("none").join("checkpoint.bin"))
    );
    assert_eq!(reused.mean, trained.mean);
    assert_eq!(reused.views, trained.views);
    // the log records the term of every step (its rays and value), the same on both paths,
    // and nothing in a run that holds no term
    let held = geometry_log(&dir.path().join("held"));
    assert_eq!(held.len(), 40);
    assert!(
        held.iter().all(|(rays, loss)| *rays == 256 && *loss >= 0.0),
        "{held:?}"
    );
    assert!(held.iter().any(|(_, loss)| *loss > 0.0), "{held:?}");
    assert_eq!(geometry_log(&dir.path().join("held-from-none")), held);
    assert!(geometry_log(&dir.path().join("none")).is_empty());

    let other = run(
        "held-other-seed",
        0,
        vec![pair],
        Some("none-seed-1/renders"),
    );
    assert_eq!(other.unguided_from, None);
    assert_eq!(other.mean, trained.mean);
}

/// The `geometry` records of a run's `train_log.jsonl`: (rays, loss) of each step that has one.
fn geometry_log(run: &Path) -> Vec<(u64, f64)> {
    let log = std::fs::read_to_string(run.join("train_log.jsonl")).unwrap();
    log.lines()
        .filter_map(|line| {
            let v: serde_json::Value = serde_json::from_str(line).unwrap();
            let g = v.get("geometry")?;
            Some((g["rays"].as_u64().unwrap(), g["loss"].as_f64().unwrap()))
        })
        .collect()
}

/// An `auto` choice of zero weights trains exactly as `none`: given a matching finished `none`
/// run as `--baseline`, the run reads that field instead of training it (`field_from`), copies
/// its log, writes its own checkpoint, and ends exactly where the run that trained ends.
#[test]
fn an_auto_choice_of_no_guidance_reads_a_matching_none_baseline() {
    // trains in-process from the seeded device RNG (crate::DEVICE_RNG)
    let _rng = crate::DEVICE_RNG.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let (d, _) = procedural(dir.path(), "stairs", "3");
    let preset = small_preset(dir.path(), None);
    // the built-in auto method with one candidate pair, (0, 0): the choice is no guidance
    let auto = dir.path().join("auto-zero.toml");
    let builtin =
        std::fs::read_to_string(workspace_root().join("configs/methods/gb-nerf-auto.toml"))
            .unwrap();
    let zero = builtin
        .replace("rgb = [0.0, 1e-5]", "rgb = [0.0]")
        .replace("normal = [0.0, 1e-5]", "normal = [0.0]");
    assert!(zero.contains("rgb = [0.0]\nnormal = [0.0]"), "{zero}");
    std::fs::write(&auto, zero).unwrap();
    let spec = |out: &str, method: &Path, baseline: Option<&str>| {
        short_run(dir.path(), &d, &preset, s(method), out, baseline)
    };
    let run = |spec: &gb_inpaint::RunSpec| gb_inpaint::run::run(spec).unwrap();
    run(&spec("none", Path::new("none"), None));
    let trained = run(&spec("auto", &auto, None));
    assert_eq!(trained.field_from, None);
    let choice = |r: &gb_inpaint::RunSummary| {
        let a = r.auto.as_ref().expect("an auto report");
        (a.lambda_rgb, a.lambda_normal)
    };
    assert_eq!(choice(&trained), (0.0, 0.0));

    let from_none = spec("auto-from-none", &auto, Some("none"));
    let read = run(&from_none);
    assert_eq!(
        read.field_from,
        Some(dir.path().join("none").join("checkpoint.bin"))
    );
    assert_eq!(choice(&read), (0.0, 0.0));
    assert_eq!(
        (read.steps, read.mean.clone()),
        (trained.steps, trained.mean.clone())
    );
    assert_eq!(read.views, trained.views);
    let out = dir.path().join("auto-from-none");
    let log = std::fs::read_to_string(out.join("train_log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), 40);
    // its own checkpoint: resuming the finished run trains nothing and scores the same field
    let again = run(&gb_inpaint::RunSpec {
        resume: true,
        ..from_none
    });
    assert_eq!((again.steps, again.mean), (40, trained.mean));
}
