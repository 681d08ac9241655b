//! The integration tests of this package, linked as one binary (`--test integration`):
//! each file of this folder is a module, so a change relinks one test binary, not one per
//! file. `cargo test --workspace --test integration --test help -- MODULE::` runs one file's
//! tests (`--test help` makes cargo build the `xtask` binary that the end-to-end tests run;
//! the filter is a substring, so `resume::` also runs `recipe_resume::`).

mod ablate;
mod bad_input;
mod bench_gpu;
mod bench_pipeline;
mod bench_trade;
mod capture;
mod cli;
mod distill_cli;
mod docs_links;
mod eval;
mod export_run;
mod finetune_cli;
mod fuzz;
mod geometry;
mod grid;
mod grid_slurm;
mod inpaint_methods;
mod installed;
mod mpi_launch;
mod parity_text;
mod reference;
mod report_browser;
mod resume;
mod scenes;

/// Burn's device RNG is process-global, and trainers seed it before they initialise their
/// parameters (the MLP's lazily, at the first step). Every test of this binary that trains
/// in-process (not through the `xtask` binary) holds this lock while it does, so that no two
/// interleave their draws (they were apart when each file was its own binary).
pub static DEVICE_RNG: std::sync::Mutex<()> = std::sync::Mutex::new(());
