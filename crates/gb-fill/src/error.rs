//! Errors of the fills.

/// Why a fill could not run. The caller names the file.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum FillError {
    /// The mask's size is not the image's.
    #[error("the mask is {}x{} but the image {}x{}", mask.0, mask.1, image.0, image.1)]
    SizeMismatch {
        /// Image width and height.
        image: (usize, usize),
        /// Mask width and height.
        mask: (usize, usize),
    },
    /// The mask holds another number of flags than the image has pixels.
    #[error("the mask holds {flags} flags for {pixels} pixels")]
    MaskLength {
        /// Flags given.
        flags: usize,
        /// Pixels of the image.
        pixels: usize,
    },
    /// No pixel is masked.
    #[error("the mask is empty: nothing to fill")]
    EmptyMask,
    /// A setting is out of range (the message names it).
    #[error("{0}")]
    Setting(String),
    /// Every pixel is masked.
    #[error("the mask covers the whole image: nothing known to fill from")]
    NothingKnown,
}
