//! Errors of NIMA: weights files, tensors and input images.

use std::path::PathBuf;

use crate::fid::FidError;

/// NIMA could not be loaded or run.
#[derive(Debug, thiserror::Error)]
pub enum NimaError {
    /// A weights file could not be read.
    #[error("cannot read NIMA weights {path}: {source}")]
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
    /// A tensor the network needs is missing from the weights.
    #[error("{path}: missing tensor '{tensor}' (NIMA needs pyiqa's state dict: `base_model.*` (timm inception_resnet_v2) and `classifier.2.{{weight,bias}}`)")]
    MissingTensor {
        /// The file (or a label for in-memory weights).
        path: PathBuf,
        /// Tensor name, as the file spells it.
        tensor: String,
    },
    /// A tensor has the wrong shape or dtype.
    #[error("{path}: tensor '{tensor}' has shape {got:?} ({dtype}), expected {expected:?} (F32)")]
    BadTensor {
        /// The file (or a label for in-memory weights).
        path: PathBuf,
        /// Tensor name, as the file spells it.
        tensor: String,
        /// Shape found.
        got: Vec<usize>,
        /// Dtype found.
        dtype: String,
        /// Shape expected.
        expected: Vec<usize>,
    },
    /// An image buffer does not match its declared size, or is empty.
    #[error("image of {width}x{height}: buffer holds {got} values, expected {expected} (HxWx3, non-empty)")]
    BadImage {
        /// Width.
        width: usize,
        /// Height.
        height: usize,
        /// Values found.
        got: usize,
        /// Values expected.
        expected: usize,
    },
    /// The network input side is below what InceptionResNetV2 accepts.
    #[error("NIMA input size {0} is too small: InceptionResNetV2 needs at least {min} px", min = super::MIN_INPUT_SIZE)]
    InputTooSmall(usize),
    /// The network produced NaN or infinity.
    #[error("non-finite value in the NIMA {0}")]
    NonFinite(&'static str),
}

impl NimaError {
    /// The same error from the shared safetensors reader (whose type is FID's).
    pub(crate) fn from_reader(err: FidError) -> Self {
        match err {
            FidError::Io { path, source } => NimaError::Io { path, source },
            FidError::Format { path, message } => NimaError::Format { path, message },
            FidError::MissingTensor { path, tensor } => NimaError::MissingTensor { path, tensor },
            FidError::BadTensor {
                path,
                tensor,
                got,
                dtype,
                expected,
            } => NimaError::BadTensor {
                path,
                tensor,
                got,
                dtype,
                expected,
            },
            other => NimaError::Format {
                path: PathBuf::new(),
                message: other.to_string(),
            },
        }
    }
}
