//! The reader properties of `gb_tests::fuzz` with few cases (64 per reader, or
//! `GB_FUZZ_CASES`); `cargo xtask-fuzz` runs the same properties with 10 000 cases each.
//! A failure prints the minimal failing input and `GB_FUZZ_SEED` to reproduce it. The tests
//! use a fixed seed unless `GB_FUZZ_SEED` is set, so CI is repeatable; `cargo xtask-fuzz`
//! draws a new seed per run.

use gb_tests::fuzz::{cases_from_env, readers, run_reader, DEFAULT_TEST_CASES};

/// The seed of the test runs: `GB_FUZZ_SEED`, else a fixed one.
fn test_seed() -> u64 {
    std::env::var("GB_FUZZ_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0x6762_6e65_7266)
}

fn run(name: &str) {
    let reader = readers()
        .into_iter()
        .find(|r| r.name == name)
        .unwrap_or_else(|| panic!("no reader named {name}"));
    let report = run_reader(&reader, cases_from_env(DEFAULT_TEST_CASES), test_seed());
    assert_eq!(
        report.failures,
        0,
        "{name} (GB_FUZZ_SEED={}): {}",
        report.seed,
        report.failure.unwrap_or_default()
    );
    assert!(report.executed >= u64::from(report.cases), "{report:?}");
}

macro_rules! reader_tests {
    ($($test:ident => $name:literal),* $(,)?) => {
        $(
            #[test]
            fn $test() {
                run($name);
            }
        )*

        #[test]
        fn every_reader_has_a_test() {
            let tested = [$($name),*];
            for r in readers() {
                assert!(tested.contains(&r.name), "{} has no test", r.name);
            }
            assert_eq!(tested.len(), readers().len());
        }
    };
}

reader_tests! {
    npy_gb_nerf => "npy/gb-nerf",
    npy_gb_finetune => "npy/gb-finetune",
    npy_gb_eval => "npy/gb-eval",
    safetensors_tensor_file => "safetensors/tensor-file",
    safetensors_fid => "safetensors/fid",
    safetensors_checkpoint => "safetensors/checkpoint",
    safetensors_lora_file => "safetensors/lora-file",
    lora_keys => "lora/keys",
    colmap_binary => "colmap/binary",
    colmap_text => "colmap/text",
    json_transforms => "json/transforms",
    toml_nerf_config => "toml/nerf-config",
    toml_method => "toml/method",
    yaml_opencv => "yaml/opencv",
    libsvm_model_and_range => "libsvm/model-and-range",
}
