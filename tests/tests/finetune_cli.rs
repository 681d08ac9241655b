//! `cargo xtask finetune --diode DIR --base MODEL` on a DIODE-layout folder made here, with
//! the tiny fixture prior: it trains, writes the LoRA, the log and a checkpoint, resumes,
//! and refuses bad input with one line naming the path.

use std::path::Path;

use gb_tests::{workspace_root, xtask};

/// A little-endian f32 `.npy`.
fn write_npy(path: &Path, shape: &[usize], data: &[f32]) {
    let shape: Vec<u64> = shape.iter().map(|&d| d as u64).collect();
    std::fs::write(path, gb_core::npy::encode_f32(&shape, data).unwrap()).unwrap();
}

/// One DIODE scan with `n` images of a tilted plane.
fn fake_diode(root: &Path, split: &str, n: usize) {
    let dir = root.join(split).join("indoors/scene_00001/scan_00002");
    std::fs::create_dir_all(&dir).unwrap();
    let (w, h) = (48usize, 40usize);
    for k in 0..n {
        let stem = format!("00001_00002_indoors_000_{k:03}");
        let mut img = gb_core::RgbImage::filled(w, h, [0.0; 3]);
        for y in 0..h {
            for x in 0..w {
                let v = ((x / 6 + y / 6 + k) % 2) as f32;
                img.set(
                    x,
                    y,
                    [0.2 + 0.6 * v, x as f32 / w as f32, y as f32 / h as f32],
                );
            }
        }
        gb_core::write_rgb_png(&dir.join(format!("{stem}.png")), &img).unwrap();
        write_npy(
            &dir.join(format!("{stem}_depth.npy")),
            &[h, w, 1],
            &vec![2.0; w * h],
        );
        write_npy(
            &dir.join(format!("{stem}_depth_mask.npy")),
            &[h, w],
            &vec![1.0; w * h],
        );
        let normal: Vec<f32> = (0..w * h).flat_map(|_| [0.0f32, 0.6, 0.8]).collect();
        write_npy(&dir.join(format!("{stem}_normal.npy")), &[h, w, 3], &normal);
    }
}

fn prior() -> String {
    workspace_root()
        .join("crates/gb-diffusion/tests/fixtures/sd_image/pipeline")
        .display()
        .to_string()
}

#[test]
fn finetune_on_a_diode_folder_trains_exports_and_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let diode = tmp.path().join("diode");
    fake_diode(&diode, "train", 3);
    fake_diode(&diode, "val", 1);
    let out = tmp.path().join("run");
    let (d, o, p) = (
        diode.display().to_string(),
        out.display().to_string(),
        prior(),
    );
    let common = [
        "finetune",
        "--diode",
        &d,
        "--base",
        &p,
        "--batch",
        "1",
        "--rank",
        "4",
        "--alpha",
        "4",
        "--resolution",
        "32",
        "--validate-every",
        "0",
        "--validation-samples",
        "1",
        "--checkpoint-every",
        "1",
        "--quiet",
        "--out",
        &o,
    ];
    let mut args = common.to_vec();
    args.extend(["--steps", "2"]);
    let run = xtask(&args);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let lora = out.join("pytorch_lora_weights.safetensors");
    assert!(std::fs::metadata(&lora).unwrap().len() > 1000);
    assert!(out.join("checkpoint.gbft").is_file());
    let log = std::fs::read_to_string(out.join("train_log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), 2);
    for line in log.lines() {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        assert!(v["loss"].as_f64().unwrap().is_finite());
    }
    let summary: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    let base = &summary["validation_base"]["prior"];
    assert!(base["rgb_masked_psnr"].as_f64().unwrap().is_finite());
    assert!(base["normal_angular_error_deg"].as_f64().unwrap() >= 0.0);

    let mut args = common.to_vec();
    args.extend(["--steps", "3", "--resume"]);
    // resuming may extend the run: one more step, continued from the checkpoint
    let again = xtask(&args);
    assert!(
        again.status.success(),
        "{}",
        String::from_utf8_lossy(&again.stderr)
    );
    let summary: serde_json::Value = serde_json::from_slice(&again.stdout).unwrap();
    assert_eq!(summary["steps"].as_u64(), Some(3));
    let log2 = std::fs::read_to_string(out.join("train_log.jsonl")).unwrap();
    assert_eq!(log2.lines().count(), 3);
    assert!(
        log2.starts_with(log.as_str()),
        "the first two steps were rewritten:\n{log}\n{log2}"
    );
}

#[test]
fn finetune_bad_inputs_exit_2_naming_the_path() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("no-diode-here");
    let p = prior();
    let m = missing.display().to_string();
    let out = tmp.path().join("o").display().to_string();
    let r = xtask(&[
        "finetune", "--diode", &m, "--base", &p, "--out", &out, "--quiet",
    ]);
    assert_eq!(r.status.code(), Some(2));
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(err.contains("no-diode-here"), "{err}");

    // a DIODE image without its normal file
    let diode = tmp.path().join("partial");
    fake_diode(&diode, "train", 1);
    let scan = diode.join("train/indoors/scene_00001/scan_00002");
    std::fs::remove_file(scan.join("00001_00002_indoors_000_000_normal.npy")).unwrap();
    let d = diode.display().to_string();
    let r = xtask(&[
        "finetune", "--diode", &d, "--base", &p, "--out", &out, "--quiet",
    ]);
    assert_eq!(r.status.code(), Some(2));
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(err.contains("_normal.npy"), "{err}");

    // a base that is not a prior
    let r = xtask(&[
        "finetune",
        "--synthetic",
        "--base",
        &m,
        "--out",
        &out,
        "--quiet",
    ]);
    assert_eq!(r.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&r.stderr).contains("no-diode-here"));
}
