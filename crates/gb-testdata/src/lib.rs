//! Where the shared test data lives (`GB_TEST_DATA`, set by `.ci/run` to `../shared`), and
//! how the tests that need it are skipped on a checkout without it.
//!
//! **Location.** `$GB_TEST_DATA` (taken from the workspace root when relative), else
//! `../shared` beside the checkout; it counts as present when it holds `data/`.
//!
//! **Skipping.** Each crate whose tests read the data has this crate as a build-dependency
//! (std only) and a `build.rs` that calls [`emit_build_script_cfg`]. Without the data that
//! sets `cfg(gb_no_shared_data)`, and the tests carry
//! `#[cfg_attr(gb_no_shared_data, ignore = "needs the shared test data (../shared or GB_TEST_DATA): ...")]`,
//! so libtest lists them as `ignored, needs the shared test data ...` and counts them in
//! each summary's `N ignored`. [`test_data_dir`] still panics when the data is missing, so
//! a test that needs it and is not marked fails rather than passing silently, and
//! [`shared_data_guard!`] fails when the data appeared after such a build.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// The cfg a build script sets when the shared test data is missing.
pub const MISSING_CFG: &str = "gb_no_shared_data";

/// The start of every `ignore` reason of a test that needs the shared data (what `.ci/run`
/// looks for: CI must never skip them).
pub const IGNORE_REASON_PREFIX: &str = "needs the shared test data";

/// The workspace root: the nearest folder at or above `manifest_dir` whose `Cargo.toml` has a
/// `[workspace]` table (`manifest_dir` itself when there is none).
pub fn workspace_root(manifest_dir: &Path) -> PathBuf {
    manifest_dir
        .ancestors()
        .find(|dir| {
            std::fs::read_to_string(dir.join("Cargo.toml"))
                .is_ok_and(|toml| toml.lines().any(|l| l.trim() == "[workspace]"))
        })
        .unwrap_or(manifest_dir)
        .to_path_buf()
}

/// Where the shared data folder should be, given the workspace root and the value of
/// `GB_TEST_DATA`: that value (joined to `root` when relative), or `root/../shared` when it
/// is unset or empty.
pub fn shared_data_location(root: &Path, gb_test_data: Option<OsString>) -> PathBuf {
    match gb_test_data.filter(|v| !v.is_empty()).map(PathBuf::from) {
        Some(dir) if dir.is_relative() => root.join(dir),
        Some(dir) => dir,
        None => root.join("..").join("shared"),
    }
}

/// The shared data folder of this workspace and whether it holds `data/`.
pub fn locate_test_data() -> (PathBuf, bool) {
    let root = workspace_root(Path::new(env!("CARGO_MANIFEST_DIR")));
    let dir = shared_data_location(&root, std::env::var_os("GB_TEST_DATA"));
    let present = dir.join("data").is_dir();
    (dir, present)
}

/// The shared data folder (see the module docs). Panics with a clear message when it is
/// missing, because a test that needs real data must not silently pass without it.
pub fn test_data_dir() -> PathBuf {
    let (dir, present) = locate_test_data();
    assert!(
        present,
        "shared test data not found at {} (no data/ folder): put the shared folder beside the \
         checkout as ../shared or set GB_TEST_DATA to the folder holding data/ and weights/; \
         a test that needs it must carry \
         #[cfg_attr(gb_no_shared_data, ignore = \"{IGNORE_REASON_PREFIX} ...\")] and its \
         crate the build.rs that sets that cfg (crates/gb-testdata)",
        dir.display()
    );
    dir
}

/// Build-script side (see the module docs): declares `cfg(gb_no_shared_data)`, sets it when
/// the shared data is missing, and asks Cargo to rerun the check when `GB_TEST_DATA`
/// changes or, with the data present, when its `data/` folder changes. A missing folder is
/// not watched: Cargo reruns a build script that watches a missing path on every build, and
/// the crate and everything above it would recompile each time. Data added later is picked
/// up when `GB_TEST_DATA` changes (or `touch build.rs`); [`shared_data_guard!`] says so.
pub fn emit_build_script_cfg() {
    let (dir, present) = locate_test_data();
    println!("cargo::rustc-check-cfg=cfg({MISSING_CFG})");
    println!("cargo::rerun-if-env-changed=GB_TEST_DATA");
    if present {
        println!("cargo::rerun-if-changed={}", dir.join("data").display());
    } else {
        println!("cargo::rustc-cfg={MISSING_CFG}");
        println!(
            "cargo::warning=shared test data not found at {}: the tests that need it are ignored",
            dir.display()
        );
    }
}

/// Fails when the shared data is present although `crate_dir`'s crate was built without it
/// (its tests that need the data are then still compiled as ignored).
pub fn assert_still_missing(crate_dir: &str) {
    let (dir, present) = locate_test_data();
    assert!(
        !present,
        "the shared test data is at {} now, but {crate_dir} was built before it appeared, so its \
         tests that need it are still ignored: `touch {crate_dir}/build.rs` (or change \
         GB_TEST_DATA) and run the tests again",
        dir.display()
    );
}

/// A test, compiled only when the calling crate was built without the shared data
/// (`cfg(gb_no_shared_data)`), that fails once the data is present: see
/// [`assert_still_missing`]. Invoke it once per crate that skips data tests.
#[macro_export]
macro_rules! shared_data_guard {
    () => {
        #[cfg(gb_no_shared_data)]
        #[test]
        fn shared_test_data_is_still_missing() {
            $crate::assert_still_missing(env!("CARGO_MANIFEST_DIR"));
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn location_follows_gb_test_data() {
        let root = Path::new("/ws");
        assert_eq!(shared_data_location(root, None), Path::new("/ws/../shared"));
        assert_eq!(
            shared_data_location(root, Some("".into())),
            Path::new("/ws/../shared")
        );
        assert_eq!(
            shared_data_location(root, Some("../data".into())),
            Path::new("/ws/../data")
        );
        assert_eq!(
            shared_data_location(root, Some("/abs/shared".into())),
            Path::new("/abs/shared")
        );
    }

    #[test]
    fn workspace_root_is_the_folder_with_the_workspace_table() {
        let root = workspace_root(Path::new(env!("CARGO_MANIFEST_DIR")));
        let toml = std::fs::read_to_string(root.join("Cargo.toml")).unwrap();
        assert!(toml.contains("[workspace]"));
        assert!(root.join("crates/gb-core/Cargo.toml").is_file());
    }
}
