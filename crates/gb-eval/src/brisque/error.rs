//! Errors of the BRISQUE metric: model files, images and degenerate statistics.

use std::path::PathBuf;

/// BRISQUE could not load its model or could not score an image.
#[derive(Debug, thiserror::Error)]
pub enum BrisqueError {
    /// A model or range file could not be read.
    #[error("cannot read BRISQUE file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The IO error.
        source: std::io::Error,
    },
    /// A model or range file is not in the expected format.
    #[error("{path}: line {line}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number (0 when the problem is not tied to a line).
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A field of a model file is missing or has the wrong shape.
    #[error("{path}: field '{field}': {message}")]
    Field {
        /// The file.
        path: PathBuf,
        /// The field, as a dotted path.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// The model's feature count does not match the 36 BRISQUE features or the range.
    #[error("model expects {model} features but {what} has {got}")]
    FeatureCount {
        /// Features the model expects.
        model: usize,
        /// What disagrees ("BRISQUE", "the range file").
        what: &'static str,
        /// Its count.
        got: usize,
    },
    /// The image buffer does not match its declared size.
    #[error("image buffer holds {got} bytes, expected {expected} ({width}x{height}x{channels})")]
    BadBuffer {
        /// Bytes found.
        got: usize,
        /// Bytes expected.
        expected: usize,
        /// Width.
        width: usize,
        /// Height.
        height: usize,
        /// Channels.
        channels: usize,
    },
    /// The image is too small for two scales of 7x7 statistics.
    #[error("image {width}x{height} is too small for BRISQUE (at least 8x8 is needed)")]
    TooSmall {
        /// Width.
        width: usize,
        /// Height.
        height: usize,
    },
    /// The MSCN statistics are degenerate (for example a constant image), so the AGGD fit
    /// is undefined.
    #[error("BRISQUE is undefined for this image: {0}")]
    Degenerate(String),
}
