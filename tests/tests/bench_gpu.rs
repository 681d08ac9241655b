//! `cargo xtask bench gpu --smoke` end to end: the command the GPU machine runs, at tiny sizes.
//! It runs on flex, and on wgpu with `GB_TEST_HEAVY_WGPU=1` (a whole prior and NeRF on
//! lavapipe spend minutes autotuning; see `gb_core::heavy_test_backends`). The report
//! holds every stage with positive times (the cold first call apart from the steady state), a
//! pipeline step whose phases add up, the 10k-step projection from that step, and NeRF speeds
//! on the device and on flex with their ratio. The offline bundle (`--prepare`) carries a
//! binary that runs the same smoke through its `run.sh`.

use std::path::{Path, PathBuf};
use std::process::Command;

use gb_core::BackendKind;
use gb_tests::{assert_success, path_str as s, workspace_root, xtask};

/// The bundle of `bench gpu --prepare` (no downloads here: empty `--debs` and `--wheels`
/// folders), refused over a carry limit with both sizes, then made; its `run.sh` unpacks the
/// binary and runs `bench gpu --smoke` into `$OUT`, the way the GPU machine runs it.
fn smoke_through_the_bundle(device: &str, dir: &Path) -> PathBuf {
    let (bundle, empty) = (dir.join("bundle"), dir.join("empty"));
    std::fs::create_dir_all(&empty).unwrap();
    // a loader package that must stay packed where the machine has a loader
    std::fs::write(empty.join("not-a-package.deb"), b"not a package").unwrap();
    let prepare = |limit_mib: &str| {
        xtask(&[
            "bench",
            "gpu",
            "--prepare",
            s(&bundle),
            "--debs",
            s(&empty),
            "--wheels",
            s(&empty),
            "--xz-level",
            "0",
            "--carry-limit-mib",
            limit_mib,
            "--with-assets",
        ])
    };
    let refused = prepare("1");
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success());
    assert!(
        err.contains("MiB, over the 1 MiB that travel to a GPU machine"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");

    let made = prepare("100000");
    assert_success(&made, "bench gpu --prepare");
    let said = String::from_utf8_lossy(&made.stdout);
    assert!(
        said.contains(&format!("command: bash {}/run.sh", bundle.display())),
        "{said}"
    );
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(bundle.join("manifest.json")).unwrap()).unwrap();
    let binary = &manifest["binary"];
    let xz = std::fs::metadata(bundle.join("gb-nerf.xz")).unwrap().len();
    assert_eq!(binary["xz_bytes"], xz);
    assert!(xz < binary["stripped_bytes"].as_u64().unwrap(), "{binary}");
    assert!(manifest["tracked_tree_bytes"].as_u64().unwrap() > 1 << 20);
    assert_eq!(manifest["wheels"], serde_json::json!([]));
    assert_eq!(manifest["debs"], serde_json::json!(["not-a-package.deb"]));
    assert!(!bundle.join("site.tar.xz").exists());
    assert_eq!(manifest["assets_in_bundle"], true);
    assert!(bundle.join("assets/tiny-prior/model_index.json").is_file());
    assert!(bundle.join("tools/bench/unet_bench.py").is_file());

    let out = dir.join("out");
    let run = Command::new("bash")
        .arg(bundle.join("run.sh"))
        .args(["--smoke", "--device", device])
        .env("OUT", &out)
        .env("GB_BUNDLE_WORK", dir.join("work"))
        .current_dir(workspace_root())
        .output()
        .unwrap();
    assert_success(&run, "bash BUNDLE/run.sh --smoke");
    let log = std::fs::read_to_string(out.join("gpu-bench.log")).unwrap();
    assert!(log.contains("run.sh: bench gpu exited with 0"), "{log}");
    let has_loader = Command::new("sh")
        .args(["-c", "ldconfig -p | grep 'libvulkan\\.so\\.1'"])
        .output()
        .is_ok_and(|o| o.status.success());
    if has_loader {
        assert!(!log.contains("unpacking"), "{log}");
    }
    out.join("gpu-bench.json")
}

#[test]
fn gpu_bench_smoke_through_the_bundle_writes_every_section() {
    let device = if gb_core::heavy_test_backends().contains(&BackendKind::Wgpu) {
        "wgpu"
    } else {
        "flex"
    };
    let dir = tempfile::tempdir().unwrap();
    let path = smoke_through_the_bundle(device, dir.path());
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    assert_eq!(doc["smoke"], true);
    assert_eq!(doc["device"], device);
    assert!(doc["machine"]["cpu"].is_string());
    // the report says whether the adapter is a GPU card (flex and lavapipe are not)
    let card = gb_core::backend::is_gpu_card(&device.parse::<BackendKind>().unwrap().device());
    assert_eq!(doc["adapter"]["backend"], device);
    assert_eq!(doc["adapter"]["is_gpu_card"], card);
    assert_eq!(doc["adapter"]["type"] == "gpu card", card);
    let positive = |v: &serde_json::Value, what: &str| {
        let s = v.as_f64().unwrap_or_else(|| panic!("{what}: {v}"));
        assert!(s > 0.0 && s.is_finite(), "{what}: {s}");
        s
    };
    let stages = &doc["stages"];
    // every timing keeps the cold first call apart from the steady state
    for stage in [
        "unet_forward_f32",
        "unet_forward_f16",
        "vae_encoder_fwd_bwd_f32",
        "vae_encoder_fwd_bwd_f16",
    ] {
        positive(&stages[stage]["steady_s"], stage);
        positive(&stages[stage]["first_call_s"], stage);
        assert_eq!(stages[stage]["repeats"], 1, "{stage}");
        positive(&stages[stage]["stage_s"], stage);
    }
    assert_eq!(doc["unet_latent"], 8);
    // flex and wgpu both have f16 tensors: the half-precision prior is timed too (above)
    assert!(doc["ratios"]["unet_f16_over_diffusers_fp16"].is_null());
    assert_eq!(doc["diffusers_reference"], "skipped: --smoke");
    assert!(stages["diffusers"].is_null());
    assert_eq!(doc["stages_not_measured"], serde_json::json!([]));

    let step = &stages["pipeline_step"];
    assert!(step["steps_failed"].is_null(), "{}", step["steps_failed"]);
    assert_eq!(step["prior"], "tiny");
    assert_eq!(step["device"], device);
    // the device's default precision: f32 off a GPU card (flex, lavapipe)
    assert_eq!(step["precision"], "f32");
    let step_s = positive(&step["step_s_median"], "step");
    let sum: f64 = step["phases_s_median"]
        .as_object()
        .unwrap()
        .values()
        .map(|v| v.as_f64().unwrap())
        .sum();
    assert!(
        (sum - step_s).abs() <= 1e-9 * step_s.max(1.0),
        "{sum} vs {step_s}"
    );
    let projected = positive(&doc["projected_10k_steps_h"], "projection");
    assert!((projected - 10_000.0 * step_s / 3600.0).abs() <= 1e-9 * projected);

    let rows = stages["nerf"]["presets"].as_array().unwrap();
    assert_eq!(rows.len(), 1);
    assert_eq!(rows[0]["preset"], "fast");
    assert_eq!(rows[0]["device"], device);
    let on_device = positive(&rows[0]["steps_per_s"]["device"], "nerf device");
    let on_flex = positive(&rows[0]["steps_per_s"]["flex"], "nerf flex");
    positive(&rows[0]["first_two_steps_s"]["device"], "nerf cold start");
    let ratio = positive(&rows[0]["device_over_flex"], "ratio");
    assert!((ratio - on_device / on_flex).abs() <= 1e-9 * ratio);
    assert!(stages["nerf"]["flex_cores"].as_u64().unwrap() >= 1);
    positive(&doc["wall_s"], "wall");
}

/// Without `--smoke`, a device that is no GPU card (flex; wgpu on lavapipe, when this machine
/// tests wgpu) is refused before anything runs, with the adapter's name, and no report.
#[test]
fn gpu_bench_refuses_a_device_that_is_no_gpu_card() {
    let mut devices = vec!["flex"];
    if gb_core::test_backends().contains(&BackendKind::Wgpu)
        && !gb_core::backend::is_gpu_card(&BackendKind::Wgpu.device())
    {
        devices.push("wgpu");
    }
    for device in devices {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("gpu.json");
        let run = xtask(&[
            "bench",
            "gpu",
            "--no-setup",
            "--python",
            "none",
            "--device",
            device,
            "--out",
            path.to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success(), "{device}: {err}");
        assert!(
            err.contains(&format!("--device {device}: the adapter '")),
            "{err}"
        );
        assert!(err.contains("is no GPU card"), "{err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!path.exists(), "{device}: a report was written");
    }
}

#[test]
fn gpu_bench_refuses_an_unknown_device_naming_the_flag() {
    let run = xtask(&["bench", "gpu", "--smoke", "--device", "cuda"]);
    assert!(!run.status.success());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("--device"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}
