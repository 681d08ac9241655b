//! Shared helpers of gb-eval's parity tests: the fixtures written by
//! `tools/eval_parity/make_fixtures.py`.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

use gb_core::{read_gray, read_rgb, RgbImage};
use serde_json::Value;

/// The fixture folder.
pub fn fixture_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/eval")
}

/// The parsed `expected.json`.
pub fn expected() -> Value {
    let text = std::fs::read_to_string(fixture_dir().join("expected.json")).expect("expected.json");
    serde_json::from_str(&text).expect("expected.json parses")
}

/// A fixture image.
pub fn image(name: &str) -> RgbImage {
    read_rgb(&fixture_dir().join("images").join(name), None).expect("fixture image")
}

/// A fixture mask (non-zero = inside).
pub fn mask(name: &str) -> Vec<bool> {
    let (_, _, v) = read_gray(&fixture_dir().join("images").join(name)).expect("fixture mask");
    v.into_iter().map(|x| x > 0.0).collect()
}

/// A reference number; the string "inf" is infinity.
pub fn number(v: &Value) -> f64 {
    match v {
        Value::String(s) if s == "inf" => f64::INFINITY,
        other => other
            .as_f64()
            .unwrap_or_else(|| panic!("not a number: {other}")),
    }
}

/// Tracks the largest absolute deviation seen and asserts each against `tol`.
pub struct Deviation {
    what: &'static str,
    tol: f64,
    /// Largest deviation so far.
    pub max: f64,
}

impl Deviation {
    /// A tracker for `what` with tolerance `tol`.
    pub fn new(what: &'static str, tol: f64) -> Self {
        Self {
            what,
            tol,
            max: 0.0,
        }
    }

    /// Checks `got` against `want` for `case`.
    pub fn check(&mut self, case: &str, got: f64, want: f64) {
        if want.is_infinite() {
            assert_eq!(got, want, "{} {case}: got {got}, want {want}", self.what);
            return;
        }
        let d = (got - want).abs();
        self.max = self.max.max(d);
        assert!(
            d <= self.tol,
            "{} {case}: got {got}, want {want} (|d| = {d:e} > {:e})",
            self.what,
            self.tol
        );
    }

    /// Prints the largest deviation (visible with `--nocapture`).
    pub fn report(&self) {
        println!(
            "{}: largest deviation {:e} (tolerance {:e})",
            self.what, self.max, self.tol
        );
    }
}
