//! Property tests of every reader of untrusted files ("fuzzing on stable Rust" with
//! `proptest`): each reader gets arbitrary bytes, mutations of a valid file (see [`mutate`])
//! and valid files; it must return `Ok` or `Err` and never panic, and a valid file must read
//! back the values written.
//!
//! The properties live here once and run in two modes: `tests/tests/fuzz.rs` (in `cargo test`,
//! [`cases_from_env`] cases per reader, 64 unless `GB_FUZZ_CASES` says otherwise) and
//! `cargo xtask-fuzz` (10 000 cases per reader, with a JSON report).

mod brisque;
mod checkpoint;
mod colmap;
mod lora;
pub mod mutate;
mod npy;
mod safetensors_files;
mod toml_configs;
mod transforms;

use std::cell::Cell;
use std::time::Instant;

use proptest::strategy::Strategy;
use proptest::test_runner::{Config, RngSeed, TestCaseError, TestRunner};

/// Cases per reader in `cargo test` unless `GB_FUZZ_CASES` is set.
pub const DEFAULT_TEST_CASES: u32 = 64;

/// One property run over one reader.
pub struct Reader {
    /// The reader's name (`npy/gb-nerf`, `toml/nerf-config`, ...).
    pub name: &'static str,
    /// What it exercises (crate, function).
    pub entry_point: &'static str,
    property: fn(&mut Harness) -> Result<(), String>,
}

/// What one reader's run did.
#[derive(Debug, Clone)]
pub struct ReaderReport {
    /// The reader's name.
    pub reader: &'static str,
    /// The function(s) exercised.
    pub entry_point: &'static str,
    /// Cases asked for.
    pub cases: u32,
    /// Inputs actually given to the reader (cases, plus shrinking steps after a failure).
    pub executed: u64,
    /// Failing properties (0 or 1: proptest stops at the first failure and shrinks it).
    pub failures: u32,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// The RNG seed (`GB_FUZZ_SEED` reproduces the run).
    pub seed: u64,
    /// The minimal failing input and reason, when a property failed.
    pub failure: Option<String>,
}

/// The runner of one property: a proptest [`TestRunner`], a counter of executed inputs and a
/// scratch folder for the readers that take paths.
pub struct Harness {
    runner: TestRunner,
    executed: Cell<u64>,
    scratch: tempfile::TempDir,
}

impl Harness {
    fn new(cases: u32, seed: u64) -> Self {
        let config = Config {
            cases,
            failure_persistence: None,
            rng_seed: RngSeed::Fixed(seed),
            max_shrink_iters: 2_000,
            max_global_rejects: cases.saturating_mul(4).max(1024),
            ..Config::default()
        };
        Self {
            runner: TestRunner::new(config),
            executed: Cell::new(0),
            scratch: tempfile::tempdir().expect("cannot create a scratch folder"),
        }
    }

    /// The scratch folder (emptied by nobody: readers overwrite their files each case).
    pub fn scratch(&self) -> &std::path::Path {
        self.scratch.path()
    }

    /// Runs `test` on `strategy`'s values; the error names the minimal failing input.
    pub fn check<S: Strategy>(
        &mut self,
        strategy: S,
        test: impl Fn(S::Value, &std::path::Path) -> Result<(), TestCaseError>,
    ) -> Result<(), String> {
        let executed = &self.executed;
        let scratch = self.scratch.path();
        self.runner
            .run(&strategy, |v| {
                executed.set(executed.get() + 1);
                test(v, scratch)
            })
            .map_err(|e| {
                let mut s = e.to_string();
                if s.len() > 4000 {
                    let mut cut = 4000;
                    while !s.is_char_boundary(cut) {
                        cut -= 1;
                    }
                    s.truncate(cut);
                    s.push_str(" ...");
                }
                s
            })
    }
}

/// Fails the case unless `cond` holds.
pub fn ensure(cond: bool, what: impl FnOnce() -> String) -> Result<(), TestCaseError> {
    if cond {
        Ok(())
    } else {
        Err(TestCaseError::fail(what()))
    }
}

/// Every reader under test.
pub fn readers() -> Vec<Reader> {
    vec![
        Reader {
            name: "npy/gb-nerf",
            entry_point: "gb_nerf::scene::npy::read_float_array",
            property: npy::nerf,
        },
        Reader {
            name: "npy/gb-finetune",
            entry_point: "gb_finetune::diode::read_npy_f32",
            property: npy::finetune,
        },
        Reader {
            name: "npy/gb-eval",
            entry_point: "gb_eval::disparity::read_disparity",
            property: npy::eval,
        },
        Reader {
            name: "safetensors/tensor-file",
            entry_point: "gb_diffusion::tensor_file::{read_f32, read_i64}",
            property: safetensors_files::tensor_file,
        },
        Reader {
            name: "safetensors/fid",
            entry_point: "gb_eval::fid::safetensors_f32::F32Tensors::{parse, get_any}",
            property: safetensors_files::fid,
        },
        Reader {
            name: "safetensors/checkpoint",
            entry_point: "gb_diffusion::checkpoint::load_module",
            property: checkpoint::load,
        },
        Reader {
            name: "safetensors/lora-file",
            entry_point: "gb_diffusion::lora::LoraFile::read",
            property: lora::file,
        },
        Reader {
            name: "lora/keys",
            entry_point: "gb_diffusion::lora::LoraFile::read (key parser, adapter metadata)",
            property: lora::keys,
        },
        Reader {
            name: "colmap/binary",
            entry_point: "gb_nerf::scene::colmap::Model::read (cameras.bin, images.bin, points3D.bin)",
            property: colmap::binary,
        },
        Reader {
            name: "colmap/text",
            entry_point: "gb_nerf::scene::colmap::Model::read (cameras.txt, images.txt, points3D.txt)",
            property: colmap::text,
        },
        Reader {
            name: "json/transforms",
            entry_point: "gb_nerf::scene::blender::load",
            property: transforms::load,
        },
        Reader {
            name: "toml/nerf-config",
            entry_point: "gb_nerf::train::NerfConfig::from_toml",
            property: toml_configs::nerf,
        },
        Reader {
            name: "toml/method",
            entry_point: "gb_inpaint::MethodConfig::from_toml",
            property: toml_configs::method,
        },
        Reader {
            name: "yaml/opencv",
            entry_point: "gb_eval::brisque::{opencv_yaml::parse_opencv_yaml, RbfSvr::load_opencv_yaml, FeatureRange::load_opencv_yaml}",
            property: brisque::opencv_yaml,
        },
        Reader {
            name: "libsvm/model-and-range",
            entry_point: "gb_eval::brisque::libsvm::{load_libsvm_model, load_svm_scale_range}",
            property: brisque::libsvm,
        },
    ]
}

/// Runs one reader's property for `cases` cases.
pub fn run_reader(reader: &Reader, cases: u32, seed: u64) -> ReaderReport {
    let start = Instant::now();
    let mut harness = Harness::new(cases, seed);
    let result = (reader.property)(&mut harness);
    ReaderReport {
        reader: reader.name,
        entry_point: reader.entry_point,
        cases,
        executed: harness.executed.get(),
        failures: u32::from(result.is_err()),
        seconds: start.elapsed().as_secs_f64(),
        seed,
        failure: result.err(),
    }
}

/// Runs every reader's property for `cases` cases each, seeded from `seed`.
pub fn run_all(cases: u32, seed: u64) -> Vec<ReaderReport> {
    readers()
        .iter()
        .map(|r| run_reader(r, cases, seed))
        .collect()
}

/// `GB_FUZZ_CASES`, else `default`.
pub fn cases_from_env(default: u32) -> u32 {
    std::env::var("GB_FUZZ_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

/// `GB_FUZZ_SEED`, else a seed from the clock (printed in the reports).
pub fn seed_from_env() -> u64 {
    std::env::var("GB_FUZZ_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_nanos() as u64)
                .unwrap_or(0)
        })
}
