//! Helpers for the end-to-end tests in `tests/tests/`.
//!
//! The tests run the `xtask` binary that `cargo test --workspace` builds (the xtask package has
//! an integration test, so Cargo builds its binary before any test runs). Running the binary
//! directly, rather than a nested `cargo run`, avoids waiting on Cargo's build-directory lock.

use std::path::PathBuf;
use std::process::{Command, Output};

/// The workspace root.
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The path of the `xtask` binary built beside the running test executable.
pub fn xtask_binary() -> PathBuf {
    let exe = std::env::current_exe().expect("no current executable");
    // target/<profile>/deps/<test>-<hash> -> target/<profile>/xtask
    let profile_dir = exe
        .parent()
        .and_then(|deps| deps.parent())
        .expect("test executable is not inside target/<profile>/deps");
    let bin = profile_dir.join(format!("xtask{}", std::env::consts::EXE_SUFFIX));
    assert!(
        bin.exists(),
        "{} not found: run the tests with `cargo test --workspace`, which builds it",
        bin.display()
    );
    bin
}

/// Runs `cargo xtask ARGS` (the built binary) from the workspace root and returns its output.
pub fn xtask(args: &[&str]) -> Output {
    Command::new(xtask_binary())
        .current_dir(workspace_root())
        .args(args)
        .output()
        .expect("cannot start the xtask binary")
}
