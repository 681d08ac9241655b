//! `cargo xtask bench pipeline` end to end with the built-in tiny prior and the `fast` preset
//! on flex: the JSON it writes holds one positive time per phase that add up to the step, the
//! component times, the projection to the preset's run and the floor at the given peak; and
//! `--steps 0` is refused with a message naming the flag.

use gb_tests::xtask;

#[test]
fn pipeline_bench_writes_a_consistent_step_profile() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    let run = xtask(&[
        "bench",
        "pipeline",
        "--prior",
        "tiny",
        "--preset",
        "fast",
        "--device",
        "flex",
        "--steps",
        "1",
        "--warmup",
        "0",
        "--peak-tflops",
        "10",
        "--out",
        out,
    ]);
    assert!(
        run.status.success(),
        "bench pipeline failed: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    let path = dir.path().join("pipeline-tiny-fast-flex.json");
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    assert!(doc["steps_failed"].is_null(), "{}", doc["steps_failed"]);
    assert_eq!(doc["prior_resolution"], 64);
    assert_eq!(doc["run_steps"], 400);
    let step = doc["step_s_median"].as_f64().unwrap();
    let phases = doc["phases_s_median"].as_object().unwrap();
    assert_eq!(phases.len(), 6);
    let mut sum = 0.0;
    for (name, v) in phases {
        let s = v.as_f64().unwrap();
        assert!(s > 0.0 && s.is_finite(), "phase {name}: {s}");
        sum += s;
    }
    assert!(
        (sum - step).abs() <= 1e-9 * step.max(1.0),
        "{sum} vs {step}"
    );
    for k in ["unet_batch2", "vae_encoder_fwd_bwd", "vae_encoder_fwd"] {
        let s = doc["components_s"][k].as_f64().unwrap();
        assert!(s > 0.0 && s < step * 10.0, "{k}: {s}");
    }
    let projected = doc["projected_run_s"].as_f64().unwrap();
    assert!((projected - 400.0 * step).abs() <= 1e-9 * projected);
    let floor = &doc["floor"]["at_peak"][0];
    assert!((floor["floor_s_per_step"].as_f64().unwrap() - 0.4).abs() < 1e-12);
    for k in ["nerf", "unet", "vae"] {
        let f = doc["split_fraction"][k].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&f), "{k}: {f}");
    }
}

#[test]
fn pipeline_bench_refuses_zero_steps() {
    let run = xtask(&["bench", "pipeline", "--prior", "tiny", "--steps", "0"]);
    assert!(!run.status.success());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("--steps"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}
