//! `cargo xtask eval` end to end, on gb-eval's parity fixtures (expected values from
//! scikit-image and stlpips-pytorch, see tools/eval_parity/make_fixtures.py).

use std::path::{Path, PathBuf};

use gb_tests::{workspace_root, xtask};
use serde_json::Value;

fn fixtures() -> PathBuf {
    workspace_root().join("crates/gb-eval/tests/fixtures/eval")
}

fn expected() -> Value {
    serde_json::from_str(&std::fs::read_to_string(fixtures().join("expected.json")).unwrap())
        .unwrap()
}

fn case<'a>(doc: &'a Value, name: &str) -> &'a Value {
    doc["cases"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["name"] == name)
        .unwrap()
}

/// Copies the named cases into `root/{pred,gt,masks}` as 000.png, 001.png, ...
fn set_up(root: &Path, names: &[&str]) {
    let doc = expected();
    for sub in ["pred", "gt", "masks"] {
        std::fs::create_dir_all(root.join(sub)).unwrap();
    }
    for (i, name) in names.iter().enumerate() {
        let c = case(&doc, name);
        let file = format!("{i:03}.png");
        for (sub, key) in [("pred", "pred"), ("gt", "gt"), ("masks", "mask")] {
            let src = fixtures().join("images").join(c[key].as_str().unwrap());
            std::fs::copy(src, root.join(sub).join(&file)).unwrap();
        }
    }
}

fn mean_of(doc: &Value, names: &[&str], key: &str) -> f64 {
    names
        .iter()
        .map(|n| case(doc, n)[key].as_f64().unwrap())
        .sum::<f64>()
        / names.len() as f64
}

fn arg(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
#[cfg_attr(
    gb_no_shared_data,
    ignore = "needs the shared test data (../shared or GB_TEST_DATA): weights/ (ST-LPIPS, FID, BRISQUE)"
)]
fn eval_writes_the_paper_metrics_as_json_and_markdown() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let names = ["statue_noise", "fern_blur", "checker_noise"];
    set_up(root, &names);
    let weights = gb_core::test_data_dir().join("weights");
    let (json, md) = (root.join("out.json"), root.join("out.md"));
    let out = xtask(&[
        "eval",
        "--pred",
        arg(&root.join("pred")),
        "--gt",
        arg(&root.join("gt")),
        "--masks",
        arg(&root.join("masks")),
        "--metrics",
        "psnr,ssim,lpips,nima",
        "--weights",
        arg(&weights),
        "--json",
        arg(&json),
        "--markdown",
        arg(&md),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let report: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let doc = expected();
    assert_eq!(report["n_images"], 3);
    for (key, tol) in [
        ("psnr", 1e-5),
        ("psnr_bbox", 1e-5),
        ("psnr_mask", 1e-5),
        ("ssim", 1e-5),
        ("ssim_bbox", 1e-5),
        ("ssim_mask", 1e-5),
    ] {
        let got = report[key]
            .as_f64()
            .unwrap_or_else(|| panic!("{key} missing: {report}"));
        let want = mean_of(&doc, &names, key);
        assert!((got - want).abs() < tol, "{key}: {got} vs {want}");
    }
    let lpips = report["lpips"].as_f64().expect("lpips");
    assert!(
        (lpips - mean_of(&doc, &names, "stlpips")).abs() < 1e-4,
        "{lpips}"
    );
    assert!(report["lpips_bbox"].as_f64().is_some(), "{report}");
    assert_eq!(
        report["nima"],
        Value::Null,
        "no NIMA weights exist here: never a number"
    );
    assert!(report["unavailable"]["nima"]
        .as_str()
        .is_some_and(|r| !r.is_empty()));
    assert_eq!(report["per_image"].as_array().unwrap().len(), 3);
    let table = std::fs::read_to_string(&md).unwrap();
    assert!(
        table.starts_with(
            "| region | PSNR ↑ | SSIM ↑ | FID ↓ | NIMA ↑ | BRISQUE ↓ | D-FID ↓ | D-PSNR ↑"
        ),
        "{table}"
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("| full image |"));
}

#[test]
fn identical_sets_report_infinite_psnr_as_the_string_inf() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    set_up(root, &["identical"]);
    let depth = fixtures().join("depth");
    for (sub, file) in [
        ("pd", "ramp_identical_pred.npy"),
        ("gd", "ramp_identical_gt.npy"),
    ] {
        std::fs::create_dir_all(root.join(sub)).unwrap();
        std::fs::copy(depth.join(file), root.join(sub).join("000.npy")).unwrap();
    }
    let json = root.join("out.json");
    let out = xtask(&[
        "eval",
        "--pred",
        arg(&root.join("pred")),
        "--gt",
        arg(&root.join("gt")),
        "--pred-depth",
        arg(&root.join("pd")),
        "--gt-depth",
        arg(&root.join("gd")),
        "--metrics",
        "psnr,d_psnr",
        "--json",
        arg(&json),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(report["psnr"], "inf");
    assert_eq!(report["d_psnr"], "inf");
}

#[test]
fn mismatched_folders_are_a_clear_error_with_exit_code_2() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    set_up(root, &["statue_noise", "fern_blur"]);
    std::fs::remove_file(root.join("gt/001.png")).unwrap();
    let out = xtask(&[
        "eval",
        "--pred",
        arg(&root.join("pred")),
        "--gt",
        arg(&root.join("gt")),
    ]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("holds 2 files") && err.contains("holds 1"),
        "{err}"
    );
}
