//! The integration tests of this package, linked as one binary (`--test integration`):
//! each file of this folder is a module, so a change relinks one test binary, not one per
//! file. `cargo test --workspace --test integration --test help -- MODULE::` runs one file's
//! tests (`--test help` makes cargo build the `xtask` binary that the end-to-end tests run;
//! the filter is a substring, so `resume::` also runs `recipe_resume::`).

mod auto_weights;
mod export;
mod guided_step;
mod personalize;
mod visibility;

/// Burn's device RNG is process-global, and trainers seed it before they initialise their
/// parameters. Every test of this binary that builds a trainer, seeds the RNG or depends on a
/// seeded initialisation holds this lock, whichever module it is in, so that no two
/// interleave their draws (they were apart when each file was its own binary).
pub static DEVICE_RNG: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// gb-diffusion's tiny fixture pipeline as the run's prior: f32, on flex.
pub fn fixture_prior() -> gb_inpaint::SdPrior {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../gb-diffusion/tests/fixtures/sd_image/pipeline");
    let opts = gb_inpaint::PriorOptions {
        precision: Some(gb_core::Precision::F32),
        ..Default::default()
    };
    gb_inpaint::load_prior(&dir, &opts, &gb_core::BackendKind::Flex.device()).unwrap()
}
