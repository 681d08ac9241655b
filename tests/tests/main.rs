//! The integration tests of this package, linked as one binary (`--test integration`):
//! each file of this folder is a module, so a change relinks one test binary, not one per
//! file. `cargo test --workspace --test integration -- MODULE::` runs one file's tests.

mod ablate;
mod bad_input;
mod bench_gpu;
mod bench_pipeline;
mod bench_trade;
mod cli;
mod distill_cli;
mod docs_links;
mod eval;
mod finetune_cli;
mod fuzz;
mod grid;
mod grid_slurm;
mod inpaint_methods;
mod installed;
mod parity_text;
mod reference;
mod report_browser;
mod resume;
mod scenes;
