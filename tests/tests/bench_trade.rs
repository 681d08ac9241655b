//! `cargo xtask bench trade` end to end on two small presets (the `fast` preset at 2 and 4
//! steps, 128 rays of 16 samples) and the `none` method on the procedural `stairs` scene:
//! one point per preset, the JSON's numbers equal to the runs' metrics, the SVG figure, and
//! a clear error for two presets of the same name.

use std::path::Path;

use gb_tests::{assert_success, path_str as s, small_preset, xtask};

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// `dir/<name>.toml`: the small preset with `steps` training steps.
fn preset_with_steps(dir: &Path, name: &str, steps: usize) -> std::path::PathBuf {
    let small = std::fs::read_to_string(small_preset(dir, None)).unwrap();
    let text = small.replace("steps = 400", &format!("steps = {steps}"));
    assert!(text.contains(&format!("\nsteps = {steps}\n")), "{text}");
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn trade_writes_one_point_per_preset_with_the_runs_numbers_and_a_figure() {
    let dir = tempfile::tempdir().unwrap();
    let short = preset_with_steps(dir.path(), "short", 2);
    let long = preset_with_steps(dir.path(), "long", 4);
    let (work, out) = (dir.path().join("work"), dir.path().join("results"));
    let presets = format!("{},{}", s(&short), s(&long));
    let run = xtask(&[
        "bench",
        "trade",
        "--scene",
        "stairs",
        "--presets",
        &presets,
        "--methods",
        "none",
        "--device",
        "flex",
        "--work",
        s(&work),
        "--out",
        s(&out),
    ]);
    assert_success(&run, "bench trade");
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        stdout.contains("| short | none |") && stdout.contains("| long | none |"),
        "{stdout}"
    );

    let files: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    let find = |ext: &str| {
        files
            .iter()
            .find(|p| p.extension().is_some_and(|e| e == ext))
            .unwrap_or_else(|| panic!("no .{ext} in {files:?}"))
            .clone()
    };
    let report = json(&find("json"));
    assert_eq!(report["benchmark"], "trade");
    assert!(report["machine"]["logical_cores"]
        .as_u64()
        .is_some_and(|n| n > 0));
    assert_eq!(
        report["preset_labels"],
        serde_json::json!(["short", "long"])
    );
    assert!(report["error"].is_null(), "{}", report["error"]);
    let points = report["points"].as_array().unwrap();
    assert_eq!(points.len(), 2, "{points:?}");
    for (p, (label, steps)) in points.iter().zip([("short", 2), ("long", 4)]) {
        assert_eq!(p["preset"], label);
        assert_eq!(p["method"], "none");
        let run_dir = work.join(label).join("stairs").join("seed-2").join("none");
        let metrics = json(&run_dir.join("metrics.json"));
        assert_eq!(metrics["steps"], steps);
        for key in ["ssim_bbox", "psnr_bbox", "d_psnr_bbox"] {
            assert_eq!(
                p[key].as_f64(),
                metrics["eval"][key].as_f64(),
                "{key} of {label}"
            );
            assert!(
                p[key].as_f64().is_some_and(f64::is_finite),
                "{key} of {label}: {p}"
            );
        }
        assert!(p["seconds"].as_f64().unwrap() >= p["train_seconds"].as_f64().unwrap());
        assert!(p["train_seconds"].as_f64().unwrap() > 0.0);
    }

    let svg = std::fs::read_to_string(find("svg")).unwrap();
    assert!(svg.starts_with("<svg xmlns=\"http://www.w3.org/2000/svg\""));
    assert_eq!(svg.matches("<svg ").count(), 5, "four panels in one figure");
    assert!(svg.contains("stairs: SSIM (mask box) ↑") && svg.contains("(presets: short → long)"));

    // two presets of one name would share a folder
    let clash = xtask(&[
        "bench",
        "trade",
        "--presets",
        &format!("{},fast", s(&dir.path().join("x/fast.toml"))),
        "--work",
        s(&work),
        "--out",
        s(&out),
    ]);
    assert_eq!(clash.status.code(), Some(2));
    let err = String::from_utf8_lossy(&clash.stderr);
    assert!(
        err.trim_end()
            .ends_with("--presets: two presets are named fast; give each its own name"),
        "{err}"
    );
}
