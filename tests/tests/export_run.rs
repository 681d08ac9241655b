//! `cargo xtask export --run OUT` (`gb_inpaint::run::export_run`): the export written later
//! from a finished run's checkpoint is the one `inpaint --export full` writes, file for file,
//! for a guided method (its checkpoint holds guidance state that the export does not load).

use std::path::Path;

use gb_tests::{assert_success, path_str as s, small_preset, xtask};

/// Every file under `dir`, as paths relative to it, sorted.
fn files(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out: Vec<_> = walkdir(dir)
        .into_iter()
        .map(|p| p.strip_prefix(dir).unwrap().to_path_buf())
        .collect();
    out.sort();
    out
}

fn walkdir(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            out.extend(walkdir(&path));
        } else {
            out.push(path);
        }
    }
    out
}

#[test]
fn export_from_the_checkpoint_equals_the_run_s_own_export() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene");
    let made = xtask(&[
        "scene",
        "--name",
        "stairs",
        "--width",
        "64",
        "--height",
        "48",
        "--views",
        "5",
        "--test-views",
        "1",
        "--seed",
        "0",
        "--out",
        s(&scene),
    ]);
    assert_success(&made, "scene");
    let preset = small_preset(dir.path(), None);
    let out = dir.path().join("run");
    let run = xtask(&[
        "inpaint",
        "--scene",
        s(&scene),
        "--preset",
        s(&preset),
        "--method",
        "gb-nerf-unseen",
        "--steps",
        "3",
        "--device",
        "flex",
        "--orbit-frames",
        "4",
        "--export",
        "full",
        "--out",
        s(&out),
    ]);
    assert_success(&run, "inpaint --export full");
    let again = dir.path().join("again");
    let exported = xtask(&[
        "export",
        "--run",
        s(&out),
        "--to",
        s(&again),
        "--orbit-frames",
        "4",
    ]);
    assert_success(&exported, "export --run");
    let stdout = String::from_utf8_lossy(&exported.stdout);
    assert!(stdout.contains("wrote 4 views (64x48)"), "{stdout}");

    let (want, got) = (files(&out.join("export")), files(&again));
    assert_eq!(want, got, "the files of the two exports");
    assert!(want.len() >= 2 * 4 + 2, "{want:?}");
    for f in &want {
        let (a, b) = (
            std::fs::read(out.join("export").join(f)).unwrap(),
            std::fs::read(again.join(f)).unwrap(),
        );
        assert!(
            a == b,
            "{} differs between the run's export and export --run",
            f.display()
        );
    }
}
