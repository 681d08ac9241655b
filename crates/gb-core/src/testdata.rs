//! Where the shared test data lives (`GB_TEST_DATA`, set by `.ci/run` to `../shared`).

use std::path::PathBuf;

/// The shared data folder: `$GB_TEST_DATA` (relative to the workspace root when relative), or `../shared` beside the checkout when the
/// variable is unset. Panics with a clear message when neither exists, because tests
/// that need real data must not silently pass without it.
pub fn test_data_dir() -> PathBuf {
    let dir = match std::env::var_os("GB_TEST_DATA") {
        // a relative path is taken from the workspace root (test binaries run in their
        // crate's folder, so `GB_TEST_DATA=../shared cargo test` must not depend on it)
        Some(d) if PathBuf::from(&d).is_relative() => PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../..")
            .join(d),
        Some(d) => PathBuf::from(d),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared"),
    };
    assert!(
        dir.join("data").is_dir(),
        "shared test data not found at {} (set GB_TEST_DATA to the folder holding data/ and weights/)",
        dir.display()
    );
    dir
}
