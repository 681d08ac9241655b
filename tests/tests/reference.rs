//! Reference views (`inpaint --reference VIEW=IMAGE`, `gb_inpaint::reference`) and the
//! prior's own fill (`cargo xtask fill`) on a tiny procedural stairs scene (40x30, 5 views)
//! whose `clean/` holds the exact object-free training views: the errors, each naming the
//! flag and the file; a reference that pulls its view's masked pixels to the clean image and
//! is carried to other views; an exact resume; and the fills' paste-back (the prior's, and
//! the two without weights).

use std::path::{Path, PathBuf};

use gb_core::{BackendKind, RgbImage};
use gb_inpaint::fill::{FillOptions, FillWith};
use gb_inpaint::reference::{load_references, ReferenceView};
use gb_inpaint::{GuidedTrainer, MethodConfig};
use gb_nerf::scene::{load, LoadOptions, Scene, Split};
use gb_nerf::train::NerfConfig;
use gb_tests::{assert_success, path_str as s, small_preset, small_stairs, xtask};

fn scene(dir: &Path) -> (PathBuf, Scene) {
    let d = small_stairs(dir, 40, 30, 1);
    let (_, scene) = load(&d, &LoadOptions::default()).unwrap();
    (d, scene)
}

/// The first training view with a non-empty mask.
/// The name of the first training view with a non-empty mask.
pub(crate) fn masked_view(scene: &Scene) -> String {
    scene
        .split(Split::Train)
        .find(|v| v.mask.as_ref().is_some_and(|m| m.data.iter().any(|b| *b)))
        .map(|v| v.name.clone())
        .expect("a masked training view")
}

fn err(scene: &Scene, pair: &str) -> String {
    load_references(scene, &[pair.to_string()], 1)
        .map(|_| ())
        .expect_err(pair)
        .to_string()
}

#[test]
fn reference_errors_name_the_flag_and_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let (d, mut scene) = scene(dir.path());
    let view = masked_view(&scene);
    let clean = d.join("clean").join(format!("{view}.png"));

    let e = err(&scene, &format!("view_999.png={}", s(&clean)));
    assert!(e.starts_with("--reference view_999.png="), "{e}");
    assert!(e.contains("not a training view"), "{e}");

    let missing = dir.path().join("nowhere.png");
    let e = err(&scene, &format!("{view}.png={}", s(&missing)));
    assert!(e.contains(s(&missing)) && e.contains("cannot read"), "{e}");

    let small = dir.path().join("small.png");
    gb_core::write_rgb_png(&small, &RgbImage::filled(10, 10, [0.5; 3])).unwrap();
    let e = err(&scene, &format!("{view}.png={}", s(&small)));
    assert!(
        e.contains(s(&small)) && e.contains("10x10") && e.contains("40x30"),
        "{e}"
    );

    let e = err(&scene, "no-equals-sign");
    assert!(e.contains("expected VIEW=IMAGE"), "{e}");

    let ok = load_references(&scene, &[format!("{view}={}", s(&clean))], 1).unwrap();
    let v = scene.views.iter().find(|v| v.name == view).unwrap();
    let masked = v.mask.as_ref().unwrap().data.iter().filter(|b| **b).count();
    assert_eq!(ok[0].pixels.len(), masked);
    assert_eq!(ok[0].name, view);

    let i = scene.views.iter().position(|v| v.name == view).unwrap();
    scene.views[i].mask = None;
    let e = err(&scene, &format!("{view}.png={}", s(&clean)));
    assert!(e.contains("has no mask"), "{e}");

    // the command: one line, exit 2, naming the flag
    let out = xtask(&[
        "inpaint",
        "--scene",
        s(&d),
        "--method",
        "none",
        "--reference",
        &format!("view_999.png={}", s(&clean)),
        "--out",
        s(&dir.path().join("out")),
    ]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    let last = stderr.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("error: --reference view_999.png="),
        "{stderr}"
    );
}

/// The small scene in `dir`, its preset, its masked view and that view's exact reference
/// (from `clean/`) as a `VIEW=IMAGE` pair and loaded.
fn clean_reference(dir: &Path) -> (PathBuf, Scene, PathBuf, String, String, Vec<ReferenceView>) {
    let (d, scene) = scene(dir);
    let preset = small_preset(dir, None);
    let view = masked_view(&scene);
    let pair = format!("{view}={}", s(&d.join("clean").join(format!("{view}.png"))));
    let refs = load_references(&scene, std::slice::from_ref(&pair), 1).unwrap();
    (d, scene, preset, view, pair, refs)
}

/// The reference `pair`, carried from step 40 of an 80-step run, refreshed every 20 steps.
fn carry_from_step_40(m: &mut MethodConfig, pair: &str) {
    m.reference.images = vec![pair.to_string()];
    m.reference.start_step = 5000;
    m.reference.refresh_every = 20;
}

/// A `none` trainer with the reference settings of `tune`.
fn trainer(
    scene: &Scene,
    preset: &Path,
    refs: Vec<ReferenceView>,
    tune: impl Fn(&mut MethodConfig),
) -> GuidedTrainer {
    let mut config = NerfConfig::preset(s(preset)).unwrap();
    config.train.steps = 80;
    let mut method = MethodConfig::builtin("none").unwrap();
    tune(&mut method);
    let mut t = GuidedTrainer::new(scene, config, method, None, BackendKind::Flex).unwrap();
    t.set_references(refs);
    t
}

/// Mean squared error of `render` against `clean` on the masked pixels of `r`.
fn masked_mse(render: &RgbImage, clean: &RgbImage, r: &ReferenceView) -> f64 {
    let mut sum = 0.0;
    for [x, y] in &r.pixels {
        let (a, b) = (
            render.get(*x as usize, *y as usize),
            clean.get(*x as usize, *y as usize),
        );
        sum += (0..3).map(|k| ((a[k] - b[k]) as f64).powi(2)).sum::<f64>();
    }
    sum / (3 * r.pixels.len()) as f64
}

/// 80 steps with the reference of one view from `clean/` against 80 without: inside that
/// view's mask the render is much closer to the clean image; the term starts at step 40 with
/// its depth anchors and reaches pixels of other views; the log records it; and a run
/// resumed from the checkpoint of step 60 continues with the same losses, bit for bit.
#[test]
fn a_reference_pulls_its_view_to_the_clean_image_and_a_resumed_run_continues_exactly() {
    // trains in-process from the seeded device RNG (crate::DEVICE_RNG)
    let _rng = crate::DEVICE_RNG.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let (d, scene, preset, view, pair, refs) = clean_reference(dir.path());
    let tune = |m: &mut MethodConfig| carry_from_step_40(m, &pair);
    let mut plain = trainer(&scene, &preset, Vec::new(), tune);
    let mut with = trainer(&scene, &preset, refs.clone(), tune);
    for _ in 0..50 {
        let p = plain.train_step().unwrap();
        assert!(p.reference.is_none());
        let r = with.train_step().unwrap();
        if r.step < 40 {
            assert!(r.reference.is_none(), "the term starts at step 40");
            continue;
        }
        let term = r
            .reference
            .expect("a reference term every step from step 40");
        assert_eq!(term.direct_rays + term.carried_rays, 256);
        assert!(term.loss.unwrap().is_finite());
        assert!(
            term.carried_pixels > 0,
            "nothing carried at step {}",
            r.step
        );
        assert_eq!(term.carried_rays, 128);
    }
    let ref_index = refs[0].view;
    let carried = with.reference.as_ref().unwrap().carried.clone().unwrap();
    assert!(carried.pixels.iter().all(|p| p.view as usize != ref_index));
    assert_eq!(carried.step, 40);
    // the depth anchors: one per masked pixel of the reference view, rendered at step 40
    assert_eq!(carried.anchors.len(), 1);
    assert_eq!(carried.anchors[0].len(), refs[0].pixels.len());
    assert!(carried.anchors[0].iter().all(|d| d.is_finite() && *d > 0.0));
    assert!(carried.pixels.iter().all(|p| p.depth > 0.0));

    // the resume: the guided trainer's own checkpoint (its state holds the carried pixels)
    let state_ckpt = dir.path().join("guided.bin");
    let opts = gb_inpaint::FitOptions {
        checkpoint: Some(state_ckpt.clone()),
        ..Default::default()
    };
    with.nerf.config.train.steps = 60;
    with.nerf.config.train.checkpoint_every = 60;
    with.fit(&opts).unwrap();
    let mut method = MethodConfig::builtin("none").unwrap();
    tune(&mut method);
    let mut resumed = GuidedTrainer::resume(
        &scene,
        &state_ckpt,
        method,
        None,
        BackendKind::Flex,
        Some(80),
    )
    .unwrap();
    resumed.set_references(refs.clone());
    assert_eq!(resumed.step, 60);
    assert_eq!(
        resumed.reference.as_ref().unwrap().carried,
        with.reference.as_ref().unwrap().carried
    );
    with.nerf.config.train.steps = 80;
    for _ in 60..80 {
        let a = with.train_step().unwrap();
        let b = resumed.train_step().unwrap();
        assert_eq!(a.loss, b.loss, "step {}", a.step);
        assert_eq!(
            a.reference.as_ref().map(|r| r.loss),
            b.reference.as_ref().map(|r| r.loss)
        );
    }
    for _ in 50..80 {
        plain.train_step().unwrap();
    }

    let clean = gb_core::read_rgb(&d.join("clean").join(format!("{view}.png")), None).unwrap();
    let cam = &with.data.views[ref_index].camera;
    let mse_with = masked_mse(&with.render(cam).unwrap().rgb, &clean, &refs[0]);
    let mse_plain = masked_mse(&plain.render(cam).unwrap().rgb, &clean, &refs[0]);
    assert!(
        mse_with < 0.5 * mse_plain,
        "masked MSE with the reference {mse_with:.5}, without {mse_plain:.5}"
    );
}

/// `[reference] skip_observed`: from the same field (both runs are identical until the term
/// starts at step 40), the carried set records which masked pixels of the reference another
/// view observes (some are, some are not, on this scene), and what is carried is the plain
/// run's carried pixels less those that come from observed reference pixels.
#[test]
fn skip_observed_leaves_out_the_reference_pixels_that_other_views_see() {
    let _rng = crate::DEVICE_RNG.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let (_, scene, preset, _, pair, refs) = clean_reference(dir.path());
    let base = |m: &mut MethodConfig| carry_from_step_40(m, &pair);
    // each trainer seeds the device and draws its MLP at its first step: both before the
    // other trainer draws
    let mut plain = trainer(&scene, &preset, refs.clone(), base);
    let first = plain.train_step().unwrap();
    let mut skip = trainer(&scene, &preset, refs.clone(), |m| {
        base(m);
        m.reference.skip_observed = true;
    });
    assert_eq!(skip.train_step().unwrap().loss, first.loss);
    for _ in 1..41 {
        let a = plain.train_step().unwrap();
        let b = skip.train_step().unwrap();
        if a.step < 40 {
            assert_eq!(a.loss, b.loss, "step {}", a.step);
        }
    }
    let all = plain.reference.as_ref().unwrap().carried.clone().unwrap();
    let kept = skip.reference.as_ref().unwrap().carried.clone().unwrap();
    assert_eq!((all.step, kept.step), (40, 40));
    assert!(all.observed.is_empty());
    assert_eq!(kept.observed.len(), 1);
    assert_eq!(kept.observed[0].len(), refs[0].pixels.len());
    let observed = kept.observed[0].iter().filter(|o| **o).count();
    assert!(
        observed > 0 && observed < refs[0].pixels.len(),
        "{observed} of {} reference pixels observed",
        refs[0].pixels.len()
    );
    assert!(!kept.pixels.is_empty(), "nothing carried");
    assert!(
        kept.pixels.len() < all.pixels.len(),
        "{} carried with skip_observed, {} without",
        kept.pixels.len(),
        all.pixels.len()
    );
    // each pixel of the plain set is kept exactly when the reference pixel it was carried
    // from (its surface point projected into the reference view) is not observed
    let rc = &plain.data.views[refs[0].view].camera;
    for p in &all.pixels {
        let cam = &plain.data.views[p.view as usize].camera;
        let point = cam.unproject(p.x as f32 + 0.5, p.y as f32 + 0.5, p.depth);
        let ([u, v], _) = rc.project(point).unwrap();
        let source = refs[0]
            .pixels
            .iter()
            .position(|q| *q == [u as u32, v as u32])
            .unwrap();
        assert_eq!(
            kept.pixels.contains(p),
            !kept.observed[0][source],
            "{p:?} from reference pixel {:?}",
            refs[0].pixels[source]
        );
    }
}

/// `fill` with the fixture prior: the view at full size, every pixel outside its mask the
/// input's, the masked ones changed; an unknown view and a view without a mask are errors
/// naming `--view`; the command writes the PNG.
#[test]
fn fill_pastes_the_prior_s_sample_into_the_mask_only() {
    let dir = tempfile::tempdir().unwrap();
    let (d, mut scene) = scene(dir.path());
    let view = masked_view(&scene);
    let prior = gb_tests::workspace_root().join(gb_tests::FIXTURE_PRIOR);
    let opts = gb_inpaint::fill::FillOptions {
        with: FillWith::Prior,
        prior: s(&prior).into(),
        lora: Some(Vec::new()),
        steps: 2,
        device: BackendKind::Flex,
        ..Default::default()
    };
    let filled = gb_inpaint::fill::fill_view(&scene, &d, &view, &opts).unwrap();
    let v = scene.views.iter().find(|v| v.name == view).unwrap();
    let mask = v.mask.as_ref().unwrap();
    assert_eq!(
        (filled.image.width, filled.image.height),
        (v.image.width, v.image.height)
    );
    let mut changed = 0;
    for i in 0..mask.data.len() {
        let (a, b) = (
            &filled.image.data[3 * i..3 * i + 3],
            &v.image.data[3 * i..3 * i + 3],
        );
        if mask.data[i] {
            changed += usize::from(a != b);
        } else {
            assert_eq!(a, b, "pixel {i} outside the mask changed");
        }
    }
    let masked = mask.data.iter().filter(|b| **b).count();
    assert_eq!(filled.filled_pixels, masked);
    assert!(
        changed * 2 > masked,
        "{changed} of {masked} masked pixels changed"
    );
    let prompts = &filled.prior.as_ref().unwrap().prompts;
    assert!(prompts.0.starts_with("RGB image, "), "{prompts:?}");

    let e = gb_inpaint::fill::fill_view(&scene, &d, "view_999", &opts).unwrap_err();
    assert!(e.to_string().starts_with("--view view_999"), "{e}");
    let i = scene.views.iter().position(|v| v.name == view).unwrap();
    scene.views[i].mask = None;
    let e = gb_inpaint::fill::fill_view(&scene, &d, &view, &opts).unwrap_err();
    assert!(e.to_string().contains("has no mask"), "{e}");

    let png = dir.path().join("fill.png");
    let out = xtask(&[
        "fill",
        "--scene",
        s(&d),
        "--view",
        &format!("{view}.png"),
        "--with",
        "prior",
        "--prior",
        s(&prior),
        "--steps",
        "2",
        "--out",
        s(&png),
    ]);
    assert_success(&out, "fill");
    let back = gb_core::read_rgb(&png, None).unwrap();
    assert_eq!((back.width, back.height), (40, 30));
}

/// The run with `--reference` and `--export none`, end to end through the library: the
/// reference is logged every step, `config.toml` records it with an absolute image path (the
/// reproducing command finds it from any folder), and no export is written or reported.
#[test]
fn a_run_with_a_reference_records_it_and_export_none_writes_no_export() {
    // trains in-process from the seeded device RNG (crate::DEVICE_RNG)
    let _rng = crate::DEVICE_RNG.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let (d, scene) = scene(dir.path());
    let preset = small_preset(dir.path(), None);
    let view = masked_view(&scene);
    let out = dir.path().join("out");
    let spec = gb_inpaint::RunSpec {
        scene: Some(d.clone()),
        method: Some("none".into()),
        preset: s(&preset).into(),
        device: BackendKind::Flex,
        steps: Some(3),
        references: vec![format!(
            "{view}.png={}",
            s(&d.join("clean").join(format!("{view}.png")))
        )],
        export: gb_inpaint::export::ExportMode::None,
        orbit_frames: 0,
        out: out.clone(),
        ..gb_inpaint::RunSpec::default()
    };
    let summary = gb_inpaint::run::run(&spec).unwrap();
    assert!(summary.export.is_none());
    assert!(!out.join("export").exists());
    let metrics = std::fs::read_to_string(out.join("metrics.json")).unwrap();
    assert!(!metrics.contains("\"export\""), "{metrics}");
    let log = std::fs::read_to_string(out.join("train_log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), 3);
    for (i, line) in log.lines().enumerate() {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        let r = &v["reference"];
        // 3 steps: the term starts at step 1 (5000 of 10000 reference steps, scaled)
        if i == 0 {
            assert!(r.is_null(), "{v}");
            continue;
        }
        assert_eq!(r["direct_rays"], 128, "{v}");
        assert_eq!(r["carried_rays"], 128, "{v}");
        assert!(r["loss"].as_f64().unwrap() > 0.0, "{v}");
    }
    let cfg: toml::Table = std::fs::read_to_string(out.join("config.toml"))
        .unwrap()
        .parse()
        .unwrap();
    let images = cfg["method"]["reference"]["images"].as_array().unwrap();
    let pair = images[0].as_str().unwrap();
    let (v, image) = pair.split_once('=').unwrap();
    assert_eq!(v, format!("{view}.png"));
    assert!(
        Path::new(image).is_absolute() && Path::new(image).is_file(),
        "{pair}"
    );
    // the reference is held by the geometry term, after an unguided pass; resuming the
    // finished run makes no second one, and scores the same field
    assert!(summary.unguided_seconds.is_some());
    let again = gb_inpaint::run::run(&gb_inpaint::RunSpec {
        resume: true,
        ..spec
    })
    .unwrap();
    assert_eq!(again.unguided_seconds, None);
    assert_eq!(again.steps, 3);
    assert_eq!(again.mean.ssim_bbox, summary.mean.ssim_bbox);
    assert_eq!(again.mean.d_psnr, summary.mean.d_psnr);
}

/// `--reference auto`: the run fills the middle masked training view by `fsr` into OUT, uses
/// it as its reference and records the fill in its config.
#[test]
fn reference_auto_fills_the_middle_masked_view() {
    // trains in-process from the seeded device RNG (crate::DEVICE_RNG)
    let _rng = crate::DEVICE_RNG.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let (d, scene) = scene(dir.path());
    let view = &gb_inpaint::reference::middle_masked_view(&scene)
        .unwrap()
        .name;
    let out = dir.path().join("out");
    let spec = gb_inpaint::RunSpec {
        scene: Some(d.clone()),
        method: Some("none".into()),
        preset: s(&small_preset(dir.path(), None)).into(),
        device: BackendKind::Flex,
        steps: Some(2),
        references: vec!["auto".into()],
        export: gb_inpaint::export::ExportMode::None,
        orbit_frames: 0,
        out: out.clone(),
        ..gb_inpaint::RunSpec::default()
    };
    gb_inpaint::run::run(&spec).unwrap();
    let png = out.join(format!("reference-auto-{view}.png"));
    let filled = gb_core::read_rgb(&png, None).unwrap();
    let cfg: toml::Table = std::fs::read_to_string(out.join("config.toml"))
        .unwrap()
        .parse()
        .unwrap();
    let reference = &cfg["method"]["reference"];
    let pair = reference["images"][0].as_str().unwrap();
    assert_eq!(
        pair,
        format!("{view}.png={}", s(&std::path::absolute(&png).unwrap()))
    );
    assert_eq!(reference["auto"]["view"].as_str(), Some(view.as_str()));
    assert_eq!(reference["auto"]["with"].as_str(), Some("fsr"));
    assert_eq!(reference["auto"]["fsr"]["block"].as_integer(), Some(16));
    // the fill removed the object
    let v = scene.views.iter().find(|v| &v.name == view).unwrap();
    let mask = &v.mask.as_ref().unwrap().data;
    let clean = gb_core::read_rgb(&d.join("clean").join(format!("{view}.png")), None).unwrap();
    assert!(masked_psnr(&filled, &clean, mask) > masked_psnr(&v.image, &clean, mask) + 3.0);
}

/// Masked PSNR (dB) of `a` against `b`.
fn masked_psnr(a: &RgbImage, b: &RgbImage, mask: &[bool]) -> f64 {
    gb_eval::psnr(a, b, &gb_eval::Region::Mask(mask.to_vec())).unwrap()
}

/// `fill --with fsr` and `--with smooth` need no prior: they keep every pixel outside the mask
/// and bring the masked ones nearer the scene's clean view than the object was; an empty
/// mask is an error naming `--view`; the command writes the PNG.
#[test]
fn the_fills_without_weights_remove_the_object() {
    let dir = tempfile::tempdir().unwrap();
    let (d, mut scene) = scene(dir.path());
    let view = masked_view(&scene);
    let v = scene.views.iter().find(|v| v.name == view).unwrap().clone();
    let mask = v.mask.as_ref().unwrap();
    let clean = gb_core::read_rgb(&d.join("clean").join(format!("{view}.png")), None).unwrap();
    let object = masked_psnr(&v.image, &clean, &mask.data);
    for with in [FillWith::Fsr, FillWith::Smooth] {
        let opts = FillOptions {
            with,
            ..Default::default()
        };
        let filled = gb_inpaint::fill::fill_view(&scene, &d, &view, &opts).unwrap();
        assert!(filled.prior.is_none());
        for (i, m) in mask.data.iter().enumerate() {
            if !m {
                assert_eq!(
                    filled.image.data[3 * i..3 * i + 3],
                    v.image.data[3 * i..3 * i + 3]
                );
            }
        }
        let p = masked_psnr(&filled.image, &clean, &mask.data);
        assert!(
            p > object + 3.0,
            "{}: masked PSNR {p:.2} dB, the object's {object:.2} dB",
            with.name()
        );
    }
    let i = scene.views.iter().position(|v| v.name == view).unwrap();
    scene.views[i].mask.as_mut().unwrap().data.fill(false);
    let opts = FillOptions {
        with: FillWith::Fsr,
        ..Default::default()
    };
    let e = gb_inpaint::fill::fill_view(&scene, &d, &view, &opts).unwrap_err();
    assert!(e.to_string().starts_with(&format!("--view {view}")), "{e}");
    assert!(e.to_string().contains("the mask is empty"), "{e}");

    let png = dir.path().join("fsr.png");
    let out = xtask(&[
        "fill",
        "--scene",
        s(&d),
        "--view",
        &view,
        "--with",
        "fsr",
        "--out",
        s(&png),
    ]);
    assert_success(&out, "fill --with fsr");
    assert!(String::from_utf8_lossy(&out.stdout).contains("filled by fsr"));
    let back = gb_core::read_rgb(&png, None).unwrap();
    assert_eq!((back.width, back.height), (40, 30));
}
