//! The binary starts and describes itself. (Its presence also makes `cargo test` build the
//! `xtask` binary that the end-to-end tests in `tests/` run.)

#[test]
fn help_lists_the_subcommands() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_gb-nerf"))
        .arg("--help")
        .output()
        .expect("cannot start xtask");
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("devices"), "{text}");
}
