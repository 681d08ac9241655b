//! `cargo xtask scene` and `cargo xtask scene-info`, end to end: real scenes, generated
//! scenes, and every bad input (one clear line naming the file, exit code 2).

use gb_tests::xtask;
use std::path::Path;

fn stdout(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn stderr(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn info_json(dir: &Path, extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["scene-info", "--scene", dir.to_str().unwrap(), "--json"];
    args.extend_from_slice(extra);
    let out = xtask(&args);
    assert!(out.status.success(), "{}", stderr(&out));
    serde_json::from_str(&stdout(&out)).unwrap()
}

// fails when the shared data appeared after this crate was built without it
gb_core::shared_data_guard!();

#[test]
#[cfg_attr(
    gb_no_shared_data,
    ignore = "needs the shared test data (../shared or GB_TEST_DATA): data/ (statue, fern, lego_small)"
)]
fn scene_info_reads_the_real_scenes() {
    let data = gb_core::test_data_dir().join("data");
    let statue = info_json(&data.join("statue"), &[]);
    assert_eq!(statue["format"], "llff");
    assert_eq!(statue["train"]["views"], 29);
    assert_eq!(statue["train"]["with_mask"], 29);
    assert_eq!(statue["test"]["views"], 0);
    assert_eq!(statue["resolutions"], serde_json::json!([[504, 378]]));
    let fx = statue["intrinsics"][0].as_f64().unwrap();
    assert!((fx - 740.324_812 / 2.0).abs() < 1e-3, "{fx}");
    let cov = statue["train"]["mask_coverage_mean_pct"].as_f64().unwrap();
    assert!(cov > 1.0 && cov < 50.0, "{cov}");

    let fern = info_json(&data.join("fern"), &["--holdout-every", "8"]);
    assert_eq!(
        (
            fern["train"]["views"].as_u64(),
            fern["test"]["views"].as_u64()
        ),
        (Some(17), Some(3))
    );

    let lego = info_json(&data.join("lego_small"), &[]);
    assert_eq!(lego["format"], "blender");
    assert_eq!(
        (
            lego["train"]["views"].as_u64(),
            lego["test"]["views"].as_u64()
        ),
        (Some(100), Some(25))
    );
    assert_eq!(lego["resolutions"], serde_json::json!([[200, 200]]));

    // the text form names the same numbers
    let out = xtask(&[
        "scene-info",
        "--scene",
        data.join("statue").to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let text = stdout(&out);
    assert!(
        text.contains("29 views, 29 with mask") && text.contains("504x378"),
        "{text}"
    );
}

fn generate(dir: &Path, name: &str, seed: &str) -> std::process::Output {
    xtask(&[
        "scene",
        "--name",
        name,
        "--out",
        dir.to_str().unwrap(),
        "--seed",
        seed,
        "--width",
        "40",
        "--height",
        "30",
        "--views",
        "6",
        "--test-views",
        "2",
    ])
}

#[test]
fn generated_scenes_are_read_by_scene_info_and_pairs_are_written() {
    let root = tempfile::tempdir().unwrap();
    for name in ["stairs", "fence"] {
        let dir = root.path().join(name);
        let pairs = root.path().join(format!("{name}_pairs"));
        let out = xtask(&[
            "scene",
            "--name",
            name,
            "--out",
            dir.to_str().unwrap(),
            "--width",
            "40",
            "--height",
            "30",
            "--views",
            "6",
            "--test-views",
            "2",
            "--pairs",
            pairs.to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}", stderr(&out));
        assert!(
            stdout(&out).contains("6 views (4 train, 2 test)"),
            "{}",
            stdout(&out)
        );
        let info = info_json(&dir, &[]);
        assert_eq!(
            (
                info["train"]["views"].as_u64(),
                info["test"]["views"].as_u64()
            ),
            (Some(4), Some(2))
        );
        assert_eq!(info["train"]["with_depth"], 4);
        assert_eq!(info["test"]["with_normal"], 2);
        assert_eq!(info["resolutions"], serde_json::json!([[40, 30]]));
        assert!(info["train"]["mask_coverage_min_pct"].as_f64().unwrap() > 0.5);
        assert_eq!(info["warnings"], serde_json::json!([]));
        assert!(info["kind"]["Bounded"].is_object(), "{}", info["kind"]);
        let captions = std::fs::read_to_string(pairs.join("captions.jsonl")).unwrap();
        assert_eq!(captions.lines().count(), 6);
        assert!(dir.join("README.md").is_file());
    }
}

#[test]
fn same_seed_same_bytes_through_the_cli() {
    let root = tempfile::tempdir().unwrap();
    let (a, b, c) = (
        root.path().join("a"),
        root.path().join("b"),
        root.path().join("c"),
    );
    for (d, seed) in [(&a, "7"), (&b, "7"), (&c, "8")] {
        assert!(generate(d, "fence", seed).status.success());
    }
    let read = |d: &Path| std::fs::read(d.join("images_1/view_003.png")).unwrap();
    let poses = |d: &Path| std::fs::read(d.join("poses_bounds.npy")).unwrap();
    assert_eq!(read(&a), read(&b));
    assert_eq!(poses(&a), poses(&b));
    assert_ne!(read(&a), read(&c));
    assert_ne!(poses(&a), poses(&c));
}

/// A float64 C-order `.npy`.
fn npy_f64(shape: &[usize], data: &[f64]) -> Vec<u8> {
    let shape: Vec<u64> = shape.iter().map(|&d| d as u64).collect();
    gb_core::npy::encode_f64(&shape, data).unwrap()
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let p = e.unwrap().path();
        let dest = to.join(p.file_name().unwrap());
        if p.is_dir() {
            copy_dir(&p, &dest);
        } else {
            std::fs::copy(&p, &dest).unwrap();
        }
    }
}

/// Runs scene-info on `dir`; asserts exit code 2 and exactly one stderr line that contains
/// every one of `needles`.
fn assert_clear_error(dir: &Path, needles: &[&str]) {
    let out = xtask(&["scene-info", "--scene", dir.to_str().unwrap()]);
    assert_eq!(
        out.status.code(),
        Some(2),
        "stdout: {}\nstderr: {}",
        stdout(&out),
        stderr(&out)
    );
    let err = stderr(&out);
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(lines[0].starts_with("error: "), "{err}");
    for n in needles {
        assert!(lines[0].contains(n), "'{n}' not in: {}", lines[0]);
    }
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn every_bad_input_is_one_clear_line_with_exit_code_2() {
    let root = tempfile::tempdir().unwrap();
    let good = root.path().join("good");
    assert!(generate(&good, "stairs", "0").status.success());
    let case = |name: &str| {
        let d = root.path().join(name);
        copy_dir(&good, &d);
        d
    };

    let d = case("missing_poses");
    std::fs::remove_file(d.join("poses_bounds.npy")).unwrap();
    assert_clear_error(&d, &["poses_bounds.npy", "missing"]);

    let d = case("wrong_shape");
    std::fs::write(
        d.join("poses_bounds.npy"),
        npy_f64(&[100, 15], &vec![1.0; 1500]),
    )
    .unwrap();
    assert_clear_error(&d, &["poses_bounds.npy", "[100, 15]", "N x 17"]);

    let d = case("nan");
    let mut rows = vec![1.0; 6 * 17];
    rows[2 * 17 + 4] = f64::NAN;
    std::fs::write(d.join("poses_bounds.npy"), npy_f64(&[6, 17], &rows)).unwrap();
    assert_clear_error(&d, &["poses_bounds.npy", "NaN", "row 2", "column 4"]);

    let d = case("count");
    std::fs::remove_file(d.join("images_1/view_004.png")).unwrap();
    std::fs::remove_file(d.join("images_1/label/view_004.png")).unwrap();
    assert_clear_error(&d, &["images_1", "5 images but 6 poses"]);

    let d = case("bad_png");
    std::fs::write(d.join("images_1/view_002.png"), b"\x89PNG garbage").unwrap();
    assert_clear_error(&d, &["view_002.png", "cannot read image"]);
    // the decoder's message is printed once, not again as the error's cause
    let err = stderr(&xtask(&["scene-info", "--scene", d.to_str().unwrap()]));
    let reason = err
        .split("cannot read image: ")
        .nth(1)
        .unwrap_or("")
        .trim()
        .to_string();
    assert!(!reason.is_empty(), "{err}");
    let parts: Vec<&str> = reason.split(": ").collect();
    let unique: std::collections::HashSet<&str> = parts.iter().copied().collect();
    assert_eq!(unique.len(), parts.len(), "a cause is repeated: {err}");

    let d = case("orphan_mask");
    std::fs::copy(
        d.join("images_1/label/view_003.png"),
        d.join("images_1/label/ghost.png"),
    )
    .unwrap();
    assert_clear_error(&d, &["ghost.png", "mask has no image"]);

    let d = root.path().join("empty");
    std::fs::create_dir_all(&d).unwrap();
    assert_clear_error(&d, &["empty", "empty folder"]);
}

#[test]
fn bad_scene_options_are_clear_errors() {
    let root = tempfile::tempdir().unwrap();
    let out = xtask(&[
        "scene",
        "--name",
        "castle",
        "--out",
        root.path().join("x").to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("castle"), "{}", stderr(&out));
    let out = xtask(&[
        "scene",
        "--name",
        "stairs",
        "--out",
        root.path().join("y").to_str().unwrap(),
        "--views",
        "4",
        "--test-views",
        "4",
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("test views (4) must be fewer than views (4)"),
        "{}",
        stderr(&out)
    );
}
