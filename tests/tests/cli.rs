//! The CLI's own behaviour: argument errors, `--help`, and stderr through a pipe.

use gb_tests::{path_str, xtask};

#[test]
fn unknown_device_is_a_clear_error_with_exit_code_2() {
    let out = xtask(&["devices", "--device", "cuda"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("cuda"), "{err}");
    let last = err.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("error: ") && last.contains("--device") && err.lines().count() == 1,
        "one error line naming the flag: {err}"
    );
}

#[test]
fn devices_lists_flex_as_working() {
    let out = xtask(&["devices", "--device", "flex"]);
    assert!(out.status.success());
    let s = String::from_utf8_lossy(&out.stdout);
    assert!(s.contains("flex") && s.contains("ok"), "{s}");
    assert!(s.contains("prior precision f32 by default"), "{s}");
}

#[test]
fn device_aliases_are_accepted() {
    let out = xtask(&["devices", "--device", "cpu"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).starts_with("flex"));
}

#[test]
fn help_names_the_command_and_lists_the_devices() {
    let top = xtask(&["--help"]);
    assert!(top.status.success());
    let top = String::from_utf8_lossy(&top.stdout);
    assert!(top.contains("Usage: cargo xtask <COMMAND>"), "{top}");
    for cmd in ["inpaint", "finetune", "eval", "devices", "ablate", "parity"] {
        let out = xtask(&[cmd, "--help"]);
        assert!(out.status.success(), "{cmd} --help");
        let help = String::from_utf8_lossy(&out.stdout);
        assert!(
            help.contains(&format!("Usage: cargo xtask {cmd} [OPTIONS]")),
            "{cmd}: {help}"
        );
        assert!(
            help.contains("[possible values: ndarray, flex, wgpu]"),
            "{cmd} --help lists the devices: {help}"
        );
    }
}

#[test]
fn stderr_through_a_pipe_has_no_colour_codes() {
    // logs an INFO line (the prior is not used by `--method none`), then fails on the scene
    let dir = tempfile::tempdir().unwrap();
    let out = xtask(&[
        "inpaint",
        "--method",
        "none",
        "--prior",
        "tiny",
        "--scene",
        path_str(&dir.path().join("missing")),
        "--out",
        path_str(&dir.path().join("out")),
    ]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("INFO") && err.contains("prior not used"),
        "{err}"
    );
    assert!(!err.contains('\x1b'), "colour codes on a pipe: {err:?}");
    assert!(err.lines().last().unwrap().starts_with("error: "), "{err}");
}
