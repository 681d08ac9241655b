//! `cargo xtask inpaint` end to end with every method of `configs/methods/`, on a tiny
//! procedural stairs scene (40x30, 5 views) and the committed tiny SD-inpainting fixture
//! (crates/gb-diffusion/tests/fixtures/sd_image/pipeline, resolution 32; the gb-nerf and csd
//! methods get the fixture U-Net LoRA with `--lora`): a few steps each, the files written,
//! the guidance terms logged per step (modalities, U-Net batch), `--resume`, the
//! non-finite-loss policy through its test hook, and the one-line errors (exit 2, naming the
//! file) of a bad prior, a bad LoRA, a missing LoRA and a scene without masks.

use std::path::{Path, PathBuf};
use std::process::Output;

use gb_tests::{workspace_root, xtask};

use gb_tests::{assert_success as check, path_str as s, small_preset, small_stairs};
use gb_tests::{FIXTURE_LORA as LORA, FIXTURE_PRIOR as PRIOR};

/// A tiny stairs scene (40x30, mask grown by 1 pixel) and a small preset (fast with fewer
/// rays and samples, a checkpoint every step) in `dir`.
fn setup(dir: &Path) -> (PathBuf, PathBuf) {
    (small_stairs(dir, 40, 30, 1), small_preset(dir, Some(1)))
}

fn inpaint(scene: &Path, preset: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "inpaint",
        "--scene",
        s(scene),
        "--preset",
        s(preset),
        "--out",
        s(out),
        "--device",
        "flex",
    ];
    args.extend_from_slice(extra);
    xtask(&args)
}

fn log_lines(out: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(out.join("train_log.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

fn metrics(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap()
}

/// Runs `method` for 3 steps through the library (`gb_inpaint::run::run`, what `cargo xtask
/// inpaint` calls) with the fixture prior and LoRA when given, and checks the outputs;
/// `terms` are the expected guidance terms of every step: (modality, U-Net batch).
fn runs(
    method: &str,
    (prior, lora): (Option<&str>, Option<&str>),
    terms: &[(&str, u64)],
    prepare: impl Fn(&Path),
) {
    let dir = tempfile::tempdir().unwrap();
    let (scene, preset) = setup(dir.path());
    prepare(&scene);
    let out = dir.path().join("out");
    let root = workspace_root();
    let spec = gb_inpaint::RunSpec {
        scene: Some(scene.clone()),
        method: Some(method.into()),
        preset: s(&preset).into(),
        prior: prior.map(|p| s(&root.join(p)).to_string()),
        lora: lora.map(|l| root.join(l)),
        device: gb_core::BackendKind::Flex,
        steps: Some(3),
        out: out.clone(),
        ..gb_inpaint::RunSpec::default()
    };
    let summary = {
        // trains in-process from the seeded device RNG (crate::DEVICE_RNG)
        let _rng = crate::DEVICE_RNG.lock().unwrap_or_else(|e| e.into_inner());
        gb_inpaint::run::run(&spec).unwrap_or_else(|e| panic!("{method}: {e}"))
    };

    let m = metrics(&out);
    // metrics.json is the returned summary, byte for byte (parsing it back may move a float
    // by an ulp, so the text is compared)
    let written = std::fs::read_to_string(out.join("metrics.json")).unwrap();
    assert_eq!(written, serde_json::to_string_pretty(&summary).unwrap());
    assert_eq!(m["method"], method);
    assert_eq!(m["steps"], 3);
    let g = &m["guidance"];
    let guided = if terms.is_empty() { 0 } else { 3 };
    assert_eq!(g["guided_steps"], guided, "{g}");
    assert_eq!(g["unguided_steps"], 3 - guided, "{g}");
    assert_eq!(g["unet_calls"], guided * terms.len() as u64, "{g}");
    assert_eq!(g["skipped_steps"], 0);
    assert!(m["mean"]["psnr"].as_f64().unwrap() > 5.0, "{}", m["mean"]);

    let lines = log_lines(&out);
    assert_eq!(lines.len(), 3);
    for (i, l) in lines.iter().enumerate() {
        assert_eq!(l["step"], i as u64);
        assert_eq!(l["skipped"], false);
        assert!(l["loss"].as_f64().unwrap().is_finite());
        let got: Vec<(String, u64)> = l["guidance"]
            .as_array()
            .unwrap()
            .iter()
            .map(|t| {
                assert_eq!(t["unet_calls"], 1);
                assert!(t["grad_norm"].as_f64().unwrap().is_finite());
                assert!(t["scale"].as_f64().unwrap() > 0.0);
                assert!(t["rays"].as_u64().unwrap() > 0);
                (
                    t["modality"].as_str().unwrap().to_string(),
                    t["unet_batch"].as_u64().unwrap(),
                )
            })
            .collect();
        let want: Vec<(String, u64)> = terms.iter().map(|(m, b)| (m.to_string(), *b)).collect();
        assert_eq!(got, want, "step {i} of {method}");
    }

    let cfg = std::fs::read_to_string(out.join("config.toml")).unwrap();
    for key in ["[run]", "reproduce = ", "[prompts]", "[preset]", "[method]"] {
        assert!(cfg.contains(key), "config.toml lacks {key}:\n{cfg}");
    }
    assert!(cfg.contains(&format!("name = \"{method}\"")), "{cfg}");
    if prior.is_some() {
        // flex's default precision, in the prior's table and in the reproducing command
        assert!(cfg.contains("precision = \"f32\""), "{cfg}");
        assert!(cfg.contains(" --precision f32"), "{cfg}");
    }
    assert!(out.join("checkpoint.bin").is_file());
    assert!(out.join("renders/view_000_rgb.png").is_file());
}

#[test]
fn gb_nerf_runs_with_bsd_on_rgb_and_normals_and_the_lora() {
    runs(
        "gb-nerf",
        (Some(PRIOR), Some(LORA)),
        &[("rgb", 2), ("normal", 2)],
        |_| {},
    );
}

#[test]
fn gb_nerf_unseen_runs_with_visibility_aware_guidance() {
    // 3 steps: the maps start at step 2000 * 3 / 10000 = 0, so every step is guided
    runs(
        "gb-nerf-unseen",
        (Some(PRIOR), Some(LORA)),
        &[("rgb", 2), ("normal", 2)],
        |_| {},
    );
}

#[test]
fn bsd_runs_without_the_lora() {
    runs(
        "bsd",
        (Some(PRIOR), None),
        &[("rgb", 2), ("normal", 2)],
        |_| {},
    );
}

#[test]
fn mvip_nerf_runs_with_sds_on_rgb_and_normals() {
    runs(
        "mvip-nerf",
        (Some(PRIOR), None),
        &[("rgb", 2), ("normal", 2)],
        |_| {},
    );
}

#[test]
fn spin_nerf_sds_runs_with_sds_on_rgb_only() {
    runs("spin-nerf-sds", (Some(PRIOR), None), &[("rgb", 2)], |_| {});
}

#[test]
fn csd_runs_with_three_branches() {
    runs(
        "csd",
        (Some(PRIOR), Some(LORA)),
        &[("rgb", 3), ("normal", 3)],
        |_| {},
    );
}

#[test]
fn none_runs_without_a_prior() {
    runs("none", (None, None), &[], |_| {});
}

#[test]
fn pre_inpainted_trains_on_the_inpainted_images() {
    // a stand-in for LaMa's output: the training images themselves, named after the views
    runs("pre-inpainted", (None, None), &[], |scene| {
        let inpainted = scene.join("RGB_inpainted");
        std::fs::create_dir_all(&inpainted).unwrap();
        for e in std::fs::read_dir(scene.join("images_1/label")).unwrap() {
            let name = e.unwrap().file_name();
            std::fs::copy(scene.join("images_1").join(&name), inpainted.join(&name)).unwrap();
        }
    });
}

#[test]
fn resume_continues_the_log_and_the_guidance_schedule() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, preset) = setup(dir.path());
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let base = ["--method", "bsd", "--prior", PRIOR];
    check(
        &inpaint(
            &scene,
            &preset,
            &a,
            &[&base[..], &["--steps", "2"]].concat(),
        ),
        "a",
    );
    check(
        &inpaint(
            &scene,
            &preset,
            &a,
            &[&base[..], &["--steps", "4", "--resume"]].concat(),
        ),
        "a resumed",
    );
    check(
        &inpaint(
            &scene,
            &preset,
            &b,
            &[&base[..], &["--steps", "4"]].concat(),
        ),
        "b",
    );
    let (la, lb) = (log_lines(&a), log_lines(&b));
    let steps: Vec<u64> = la.iter().map(|l| l["step"].as_u64().unwrap()).collect();
    assert_eq!(steps, [0, 1, 2, 3]);
    for (x, y) in la.iter().zip(&lb) {
        for (tx, ty) in x["guidance"]
            .as_array()
            .unwrap()
            .iter()
            .zip(y["guidance"].as_array().unwrap())
        {
            assert_eq!(tx["view"], ty["view"], "step {}", x["step"]);
            assert_eq!(tx["timestep"], ty["timestep"], "step {}", x["step"]);
        }
    }
    assert!(std::fs::read_to_string(a.join("config.toml"))
        .unwrap()
        .contains("resumed_from_step = 2"));
}

#[test]
fn repeated_non_finite_losses_skip_then_stop_naming_the_last_good_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, preset) = setup(dir.path());
    let bsd = std::fs::read_to_string(workspace_root().join("configs/methods/bsd.toml")).unwrap();
    let method = bsd
        .replace("name = \"bsd\"", "name = \"bsd-nan\"")
        .replace("max_consecutive_nan = 10", "max_consecutive_nan = 2");
    let method_path = dir.path().join("bsd-nan.toml");
    std::fs::write(&method_path, method).unwrap();
    let out = dir.path().join("out");
    // the loss is made NaN from step 1 by the trainer's fault injection (never a config)
    let o = gb_tests::xtask_with_env(
        &[
            "inpaint",
            "--scene",
            s(&scene),
            "--preset",
            s(&preset),
            "--out",
            s(&out),
            "--device",
            "flex",
            "--method",
            s(&method_path),
            "--prior",
            PRIOR,
            "--steps",
            "10",
        ],
        &[(gb_inpaint::trainer::INJECT_NAN_ENV, "1")],
    );
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    let ckpt = out.join("checkpoint.bin");
    assert!(
        err.contains("2 consecutive steps had a non-finite loss"),
        "{err}"
    );
    assert!(
        err.contains(&format!("{} (step 1)", ckpt.display())),
        "the message names the last good checkpoint: {err}"
    );
    assert!(err.contains("step skipped"), "each skip is logged: {err}");
    let lines = log_lines(&out);
    let skipped: Vec<bool> = lines
        .iter()
        .map(|l| l["skipped"].as_bool().unwrap())
        .collect();
    assert_eq!(skipped, [false, true, true]);
    assert!(lines[1]["loss"].is_null() && lines[1]["guidance"].as_array().unwrap().len() == 2);
    assert!(ckpt.is_file() && !out.join("metrics.json").exists());
}

/// Runs a failing command: exit 2, one `error:` line containing every `needle`, and nothing
/// trained.
fn fails(extra: &[&str], needles: &[&str], prepare: impl Fn(&Path, &Path)) {
    let dir = tempfile::tempdir().unwrap();
    let (scene, preset) = setup(dir.path());
    prepare(dir.path(), &scene);
    let out = dir.path().join("out");
    let o = inpaint(&scene, &preset, &out, extra);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("error: "), "{err}");
    for n in needles {
        assert!(err.contains(n), "expected `{n}` in: {err}");
    }
    assert!(!err.contains("panicked"), "{err}");
    assert!(
        !out.join("train_log.jsonl").exists() && !out.join("checkpoint.bin").exists(),
        "training started"
    );
}

#[test]
fn a_bad_prior_folder_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("not-a-prior");
    std::fs::create_dir_all(bad.join("unet")).unwrap();
    std::fs::write(bad.join("model_index.json"), "{}").unwrap();
    fails(
        &["--method", "bsd", "--prior", s(&bad)],
        &[s(&bad)],
        |_, _| {},
    );
}

#[test]
fn a_bad_lora_file_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("broken_lora.safetensors");
    std::fs::write(&bad, b"this is not a safetensors file").unwrap();
    fails(
        &["--method", "gb-nerf", "--prior", PRIOR, "--lora", s(&bad)],
        &["LoRA file", s(&bad)],
        |_, _| {},
    );
}

#[test]
fn a_method_with_the_lora_and_a_prior_without_one_is_an_error_naming_the_expected_file() {
    fails(
        &["--method", "gb-nerf", "--prior", PRIOR],
        &[
            &format!("{PRIOR}/pytorch_lora_weights.safetensors"),
            "--lora",
        ],
        |_, _| {},
    );
}

#[test]
fn a_scene_without_masks_is_an_error() {
    fails(
        &["--method", "bsd", "--prior", PRIOR],
        &["no training view with an object mask", "label"],
        |_, scene| std::fs::remove_dir_all(scene.join("images_1/label")).unwrap(),
    );
}

#[test]
fn pre_inpainted_without_inpainted_images_is_an_error_naming_the_scene() {
    fails(
        &["--method", "pre-inpainted"],
        &["RGB_inpainted", "scene"],
        |_, _| {},
    );
}

#[test]
fn without_method_and_prior_the_default_runs() {
    // gb-nerf-unseen (the recommended method) with the built-in tiny prior
    // (assets/tiny-prior) and its LoRA
    let dir = tempfile::tempdir().unwrap();
    let (scene, preset) = setup(dir.path());
    let out = dir.path().join("out");
    check(
        &inpaint(&scene, &preset, &out, &["--steps", "1"]),
        "default",
    );
    let m = metrics(&out);
    assert_eq!(m["method"], "gb-nerf-unseen");
    let cfg = std::fs::read_to_string(out.join("config.toml")).unwrap();
    assert!(cfg.contains("tiny-prior"), "{cfg}");
}

#[test]
#[cfg_attr(
    gb_no_shared_data,
    ignore = "needs the shared test data (../shared or GB_TEST_DATA): data/statue and weights/brisque_*_live.yml"
)]
fn a_real_scene_without_test_views_is_scored_without_a_reference() {
    let dir = tempfile::tempdir().unwrap();
    let preset = small_preset(dir.path(), None);
    let statue = gb_core::test_data_dir().join("data/statue");
    let out = dir.path().join("statue-run");
    // no nerfstudio export: it renders all 29 views at full size, and export.rs covers it
    let extra = [
        "--method",
        "none",
        "--steps",
        "20",
        "--orbit-frames",
        "0",
        "--export",
        "none",
    ];
    check(
        &inpaint(&statue, &preset, &out, &extra),
        "inpaint on statue",
    );
    let m = metrics(&out);
    assert_eq!(m["test_views"], 0);
    let eval = &m["eval"];
    // the first 3 masked training views, rendered and scored
    assert_eq!(eval["n_images"], 3, "{eval}");
    for image in eval["per_image"].as_array().unwrap() {
        let name = image["name"].as_str().unwrap();
        assert!(name.starts_with("train_IMG_"), "{name}");
        for kind in ["rgb", "depth", "normal"] {
            assert!(out.join(format!("renders/{name}_{kind}.png")).is_file());
        }
        for k in ["brisque", "brisque_bbox"] {
            let v = image[k]
                .as_f64()
                .unwrap_or_else(|| panic!("{name} {k}: {image}"));
            assert!((0.0..=100.0).contains(&v), "{name} {k} = {v}");
        }
        assert_ne!(image["brisque"], image["brisque_bbox"]);
    }
    for k in ["psnr", "ssim", "lpips", "d_psnr", "fid"] {
        assert!(eval[k].is_null(), "{k}: {}", eval[k]);
        let why = eval["unavailable"][k].as_str().unwrap();
        assert!(why.contains("no test view with ground truth"), "{k}: {why}");
    }
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    for image in eval["per_image"].as_array().unwrap() {
        let src = format!("renders/{}_rgb.png", image["name"].as_str().unwrap());
        assert!(page.contains(&src), "report.html does not show {src}");
    }
    assert!(page.contains("BRISQUE"), "the metric table has no BRISQUE");
}

#[test]
fn seed_overrides_the_presets_training_seed_and_reproduces_a_run() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, preset) = setup(dir.path());
    let run = |name: &str, seed: &str| {
        let out = dir.path().join(name);
        let extra = [
            "--method",
            "none",
            "--steps",
            "3",
            "--seed",
            seed,
            "--orbit-frames",
            "0",
        ];
        check(&inpaint(&scene, &preset, &out, &extra), name);
        let cfg = std::fs::read_to_string(out.join("config.toml")).unwrap();
        assert!(
            cfg.lines().any(|l| l.trim() == format!("seed = {seed}")),
            "{name}: config.toml does not record seed {seed}:\n{cfg}"
        );
        let losses: Vec<f64> = log_lines(&out)
            .iter()
            .map(|l| l["loss"].as_f64().unwrap())
            .collect();
        assert_eq!(losses.len(), 3, "{name}");
        losses
    };
    let (a, again, other) = (run("a", "7"), run("a-again", "7"), run("b", "8"));
    assert_eq!(a, again, "the same seed must reproduce the run");
    assert_ne!(a, other, "another seed must draw other ray batches");
}

#[test]
fn depth_selects_the_supervision_and_is_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, preset) = setup(dir.path());
    let run = |depth: Option<&str>| {
        let out = dir.path().join(depth.unwrap_or("default"));
        let mut extra = vec!["--method", "none", "--steps", "3", "--orbit-frames", "0"];
        if let Some(d) = depth {
            extra.extend(["--depth", d]);
        }
        check(
            &inpaint(&scene, &preset, &out, &extra),
            &out.display().to_string(),
        );
        let cfg = std::fs::read_to_string(out.join("config.toml")).unwrap();
        let recorded = format!("depth = \"{}\"", depth.unwrap_or("sparse"));
        assert!(
            cfg.lines().any(|l| l.trim() == recorded),
            "config.toml does not record {recorded}:\n{cfg}"
        );
        log_lines(&out)
            .iter()
            .map(|l| l["loss"].as_f64().unwrap())
            .collect::<Vec<f64>>()
    };
    let (default, sparse, dense, none) = (
        run(None),
        run(Some("sparse")),
        run(Some("dense")),
        run(Some("none")),
    );
    assert_eq!(default, sparse, "sparse is the presets' default");
    assert_ne!(sparse, dense);
    assert_ne!(sparse, none);
    assert_ne!(dense, none);
    let bad = inpaint(
        &scene,
        &preset,
        &dir.path().join("bad"),
        &["--depth", "lidar"],
    );
    assert_eq!(bad.status.code(), Some(2));
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("--depth") && err.contains("lidar"), "{err}");
}
