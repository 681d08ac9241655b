//! `cargo xtask bench gpu --smoke` end to end: the command the GPU machine runs, at tiny sizes.
//! It runs on flex, and on wgpu with `GB_TEST_HEAVY_WGPU=1` (a whole prior and NeRF on
//! lavapipe spend minutes autotuning; see `gb_core::heavy_test_backends`). The report
//! holds every section with positive times, a pipeline step whose phases add up, the 10k-step
//! projection from that step, and NeRF speeds on the device and on flex with their ratio.

use gb_core::BackendKind;
use gb_tests::xtask;

#[test]
fn gpu_bench_smoke_writes_every_section() {
    let device = if gb_core::heavy_test_backends().contains(&BackendKind::Wgpu) {
        "wgpu"
    } else {
        "flex"
    };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("gpu-smoke.json");
    let run = xtask(&[
        "bench",
        "gpu",
        "--smoke",
        "--device",
        device,
        "--out",
        path.to_str().unwrap(),
    ]);
    assert!(
        run.status.success(),
        "bench gpu --smoke failed: {}",
        String::from_utf8_lossy(&run.stderr)
    );
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
    positive(&doc["unet"]["unet_forward_f32_s"], "unet f32");
    assert_eq!(doc["unet"]["latent"], 8);
    // flex and wgpu both have f16 tensors: the half-precision prior is timed too
    positive(&doc["unet"]["unet_forward_f16_s"], "unet f16");
    assert!(doc["unet"]["unet_f16_ratio_vs_diffusers_fp16"].is_null());
    positive(&doc["vae_encoder"]["vae_encoder_fwd_bwd_s"], "vae");
    positive(&doc["vae_encoder"]["vae_encoder_fwd_bwd_f16_s"], "vae f16");
    assert_eq!(doc["diffusers"]["skipped"], "--smoke");

    let step = &doc["pipeline_step"];
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
    let projected = positive(&doc["projected_10k_steps_s"], "projection");
    assert!((projected - 10_000.0 * step_s).abs() <= 1e-9 * projected);

    let rows = doc["nerf"]["presets"].as_array().unwrap();
    assert_eq!(rows.len(), 1);
    assert_eq!(rows[0]["preset"], "fast");
    assert_eq!(rows[0]["device"], device);
    let on_device = positive(&rows[0]["steps_per_s"]["device"], "nerf device");
    let on_flex = positive(&rows[0]["steps_per_s"]["flex"], "nerf flex");
    let ratio = positive(&rows[0]["device_over_flex"], "ratio");
    assert!((ratio - on_device / on_flex).abs() <= 1e-9 * ratio);
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
