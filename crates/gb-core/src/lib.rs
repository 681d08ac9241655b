//! Shared plumbing used by every gb-nerf-rs crate: run-time backend selection
//! ([`backend`]), crash-safe file writes ([`atomic`]) and PNG/JPEG image IO ([`image_io`]).

pub mod assets;
pub mod atomic;
pub mod backend;
pub mod image_io;
pub mod npy_guard;
pub mod resample;
pub mod testdata;

pub use assets::{assets_dir, tiny_prior_dir};
pub use atomic::write_atomic;
pub use backend::{heavy_test_backends, test_backends, BackendKind};
pub use npy_guard::check_npy_header;
pub use image_io::{read_gray, read_rgb, write_gray_png, write_rgb_png, ImageIoError, RgbImage};
pub use testdata::test_data_dir;
