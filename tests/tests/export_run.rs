//! `cargo xtask export --run OUT` (`gb_inpaint::run::export_run`): the export written later
//! from a finished run's checkpoint is the one `inpaint --export full` writes, file for file,
//! for a guided method (its checkpoint holds guidance state that the export does not load).

use gb_tests::{assert_success, files_under, path_str as s, small_preset, small_stairs, xtask};

#[test]
fn export_from_the_checkpoint_equals_the_run_s_own_export() {
    let dir = tempfile::tempdir().unwrap();
    let scene = small_stairs(dir.path(), 64, 48, 1);
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

    let (want, got) = (files_under(&out.join("export")), files_under(&again));
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
