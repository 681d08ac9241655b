//! The integration tests of this package, linked as one binary (`--test integration`):
//! each file of this folder is a module, so a change relinks one test binary, not one per
//! file. `cargo test --workspace --test integration -- MODULE::` runs one file's tests.

mod brisque_parity;
mod common;
mod fid_parity;
mod nima_parity;
mod parity_lpips;
mod parity_psnr_ssim;
mod parity_stlpips;
