//! The integration tests of this package, linked as one binary (`--test integration`):
//! each file of this folder is a module, so a change relinks one test binary, not one per
//! file. `cargo test --workspace --test integration --test help -- MODULE::` runs one file's
//! tests (`--test help` makes cargo build the `xtask` binary that the end-to-end tests run;
//! the filter is a substring, so `resume::` also runs `recipe_resume::`).

mod brisque_parity;
mod common;
mod fid_parity;
mod nima_parity;
mod parity_lpips;
mod parity_psnr_ssim;
mod parity_stlpips;
