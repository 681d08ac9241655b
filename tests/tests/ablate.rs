//! `cargo xtask ablate` on a tiny procedural stairs scene (128x96, 5 views: the mask box is large enough for SSIM) with the committed
//! tiny SD-inpainting fixture as the prior: two methods of the grid (none, mvip-nerf) and a
//! one-value w3 sweep (csd with w3 = 0.5, the fixture U-Net LoRA), 2 steps each. Checks the
//! run folders, the baseline / ablation / w3 tables (markdown and JSON, numbers equal to the
//! runs' metrics.json) and the sweep's SVG figure.

use std::path::Path;

use gb_tests::xtask;

use gb_tests::{path_str as s, small_preset, small_stairs};

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn ablate_runs_the_grid_and_writes_the_tables() {
    let dir = tempfile::tempdir().unwrap();
    let scene = small_stairs(dir.path(), 128, 96, 0);
    let preset = small_preset(dir.path(), None);
    let out = dir.path().join("ablate");
    let mut args = vec!["ablate"];
    args.extend(gb_tests::small_grid_flags(s(&scene), s(&preset)));
    args.extend(["--w3=0.5", "--out", s(&out)]);
    let o = xtask(&args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "ablate failed: {err}");

    // every run is a complete inpaint run; none is the others' baseline
    for m in ["none", "mvip-nerf", "csd-w3=0.5"] {
        for f in ["metrics.json", "config.toml", "report.html"] {
            assert!(out.join(m).join(f).is_file(), "{m}/{f}");
        }
        assert_eq!(json(&out.join(m).join("metrics.json"))["steps"], 2);
    }
    let mvip_page = std::fs::read_to_string(out.join("mvip-nerf/report.html")).unwrap();
    assert!(
        mvip_page.contains("report/view_000_baseline.png"),
        "baseline column"
    );
    assert!(!out.join("csd").exists(), "csd itself was not selected");

    // the baseline table: the two methods in the paper's order, numbers from metrics.json
    let b = json(&out.join("baselines.json"));
    let rows = b["rows"].as_array().unwrap();
    let methods: Vec<&str> = rows.iter().map(|r| r["method"].as_str().unwrap()).collect();
    assert_eq!(methods, ["none", "mvip-nerf"]);
    for r in rows {
        let m = json(&out.join(r["dir"].as_str().unwrap()).join("metrics.json"));
        for key in [
            "ssim_bbox",
            "psnr_bbox",
            "psnr",
            "d_psnr_bbox",
            "d_psnr_true_bbox",
        ] {
            let (got, want) = (r[key].as_f64(), m["eval"][key].as_f64());
            assert!(got.is_some(), "{key} of {}: {r}", r["method"]);
            assert_eq!(got, want, "{key} of {}", r["method"]);
        }
        assert!(r["train_seconds"].as_f64().unwrap() > 0.0);
        assert_eq!(r["steps"], 2.0);
    }
    let keys: Vec<&str> = b["columns"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["key"].as_str().unwrap())
        .collect();
    assert_eq!(keys[0], "ssim_bbox");
    assert!(keys.contains(&"d_psnr_bbox") && keys.contains(&"psnr"));
    let md = std::fs::read_to_string(out.join("baselines.md")).unwrap();
    assert!(md.contains("| NeRF without prior | `none` |"), "{md}");
    assert!(
        md.contains("| MVIP-NeRF (SDS, RGB + normals) | `mvip-nerf` |"),
        "{md}"
    );
    assert!(md.contains("SSIM (mask box) ↑"), "{md}");
    let ssim = rows[0]["ssim_bbox"].as_f64().unwrap();
    assert!(md.contains(&format!("{ssim:.4}")), "{md}");

    // the ablation table: only its origin row ran
    let a = json(&out.join("ablation.json"));
    let labels: Vec<&str> = a["rows"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["label"].as_str().unwrap())
        .collect();
    assert_eq!(labels, ["origin (SDS, no LoRA)"]);
    assert!(std::fs::read_to_string(out.join("ablation.md"))
        .unwrap()
        .contains("| origin (SDS, no LoRA) | `mvip-nerf` |"));

    // the w3 sweep: one row, its table and figure
    let w = json(&out.join("w3_sweep.json"));
    assert_eq!(w["rows"].as_array().unwrap().len(), 1);
    assert_eq!(w["rows"][0]["label"], "w3 = 0.5");
    let cfg = std::fs::read_to_string(out.join("csd-w3=0.5/config.toml")).unwrap();
    assert!(cfg.contains("w3 = 0.5"), "{cfg}");
    let svg = std::fs::read_to_string(out.join("w3_sweep.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("<circle"), "{svg}");
    assert!(std::fs::read_to_string(out.join("w3_sweep.md"))
        .unwrap()
        .contains("![CSD w3 sweep"));
}

#[test]
fn ablate_checks_the_prior_before_training() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene");
    let o = xtask(&[
        "scene",
        "--name",
        "stairs",
        "--width",
        "40",
        "--height",
        "30",
        "--views",
        "4",
        "--test-views",
        "1",
        "--out",
        s(&scene),
    ]);
    assert!(o.status.success());
    let out = dir.path().join("ablate");
    let bad = dir.path().join("no-prior-here");
    let o = xtask(&[
        "ablate",
        "--scene",
        s(&scene),
        "--methods",
        "none,bsd",
        "--prior",
        s(&bad),
        "--out",
        s(&out),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("no-prior-here"), "{err}");
    assert!(!out.join("none").exists(), "a run started before the check");
}
