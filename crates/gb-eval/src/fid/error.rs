//! Errors of FID and D-FID: weights, images, and statistics that cannot be computed.

use std::path::PathBuf;

/// FID could not be computed.
#[derive(Debug, thiserror::Error)]
pub enum FidError {
    /// A weights file could not be read.
    #[error("cannot read FID weights {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The IO error.
        source: std::io::Error,
    },
    /// A weights file is not a valid safetensors file.
    #[error("{path}: not a valid safetensors file: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A tensor the network needs is missing from the weights file.
    #[error("{path}: missing tensor '{tensor}'")]
    MissingTensor {
        /// The file.
        path: PathBuf,
        /// Tensor name.
        tensor: String,
    },
    /// A tensor has the wrong shape or dtype.
    #[error("{path}: tensor '{tensor}' has shape {got:?} ({dtype}), expected {expected:?} (F32)")]
    BadTensor {
        /// The file.
        path: PathBuf,
        /// Tensor name.
        tensor: String,
        /// Shape found.
        got: Vec<usize>,
        /// Dtype found.
        dtype: String,
        /// Shape expected.
        expected: Vec<usize>,
    },
    /// A feature set has too few images for a covariance.
    #[error("the {set} set has {count} image(s): FID needs at least 2 per set (the covariance of one sample is undefined)")]
    TooFewImages {
        /// Which set ("prediction", "ground truth", ...).
        set: &'static str,
        /// Images in it.
        count: usize,
    },
    /// Feature sets or statistics of different dimensions were compared.
    #[error("feature dimensions differ: {a} against {b}")]
    DimensionMismatch {
        /// First dimension.
        a: usize,
        /// Second dimension.
        b: usize,
    },
    /// A feature buffer does not hold `count * dim` values.
    #[error("feature buffer holds {got} values, expected {count} x {dim}")]
    BadFeatures {
        /// Values found.
        got: usize,
        /// Rows expected.
        count: usize,
        /// Columns expected.
        dim: usize,
    },
    /// A feature, mean or covariance entry is NaN or infinite.
    #[error("non-finite value in the {0}")]
    NonFinite(&'static str),
    /// An image buffer does not match its declared size, or is empty.
    #[error("image {index}: buffer holds {got} values, expected {expected} ({width}x{height}x3)")]
    BadImage {
        /// Position of the image in its set.
        index: usize,
        /// Values found.
        got: usize,
        /// Values expected.
        expected: usize,
        /// Width.
        width: usize,
        /// Height.
        height: usize,
    },
}
