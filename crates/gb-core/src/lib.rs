//! Shared plumbing used by every gb-nerf-rs crate: run-time backend selection
//! ([`backend`]), crash-safe file writes ([`atomic`]), PNG/JPEG image IO ([`image_io`]),
//! `.npy` reading and writing ([`npy`]), the sectioned checkpoint container ([`sections`]), progress bars that do not fight the log ([`progress`]), one-line error messages
//! ([`messages`]), the prior's float precision ([`precision`]), row lookups with a parallel
//! backward ([`indexing`]), content fingerprints for caches ([`fingerprint`]), the one PSNR
//! formula ([`psnr`]) and, with the `clap` feature, the command lines' value parsers
//! (`cli`).

pub mod assets;
pub mod atomic;
pub mod backend;
#[cfg(feature = "clap")]
pub mod cli;
pub mod fingerprint;
pub mod image_io;
pub mod indexing;
pub mod messages;
pub mod npy;
pub mod npy_guard;
pub mod precision;
pub mod progress;
pub mod psnr;
pub mod resample;
pub mod sections;
pub mod tensor_values;
/// Where the shared test data lives (the gb-testdata crate, also the build scripts' helper).
pub use gb_testdata as testdata;
pub use gb_testdata::shared_data_guard;

pub use assets::{assets_dir, tiny_prior_dir};
pub use atomic::write_atomic;
pub use backend::{heavy_test_backends, test_backends, BackendKind, Devices};
pub use image_io::{
    image_size, read_gray, read_rgb, write_gray_png, write_rgb_png, ImageIoError, RgbImage,
};
pub use indexing::{gather_rows, row_indices};
pub use npy_guard::check_npy_header;
pub use precision::{Precision, PrecisionError};
pub use psnr::psnr_from_mse;
pub use tensor_values::{device_reads, f32_values, read_f32, TensorValuesError};
pub use testdata::test_data_dir;
