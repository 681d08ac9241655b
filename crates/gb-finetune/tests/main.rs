//! The integration tests of this package, linked as one binary (`--test integration`):
//! each file of this folder is a module, so a change relinks one test binary, not one per
//! file. `cargo test --workspace --test integration --test help -- MODULE::` runs one file's
//! tests (`--test help` makes cargo build the `xtask` binary that the end-to-end tests run;
//! the filter is a substring, so `resume::` also runs `recipe_resume::`).

mod data_captions;
mod data_crop;
mod data_diode;
mod data_masks;
mod data_parallel;
mod data_synthetic;
mod recipe_resume;
mod tiny_prior_benefit;
mod train_lora;
mod validate_only;

/// Burn's device RNG is process-global, and trainers seed it before they initialise their
/// parameters. Every test of this binary that builds a trainer, seeds the RNG or depends on a
/// seeded initialisation holds this lock, whichever module it is in, so that no two
/// interleave their draws (they were apart when each file was its own binary).
pub static DEVICE_RNG: std::sync::Mutex<()> = std::sync::Mutex::new(());
