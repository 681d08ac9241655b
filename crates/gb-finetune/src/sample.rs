//! One RGB / normal-map training pair in memory, and the interface every dataset implements.

use crate::FinetuneError;

/// One training example: an RGB image, optionally its normal map, and a caption.
///
/// Images are `[height, width, 3]` row-major `f32` in `[0, 1]`.
#[derive(Debug, Clone, PartialEq)]
pub struct PairSample {
    /// A stable name (file stem) for logs and errors.
    pub name: String,
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// RGB, `[h, w, 3]`, in `[0, 1]`.
    pub rgb: Vec<f32>,
    /// Normal-map image `(n + 1) / 2` of the unit camera-space normal (OpenGL camera axes,
    /// see [`crate::normal_map`]), `[h, w, 3]`; `None` when the source has no normals.
    pub normal: Option<Vec<f32>>,
    /// `[h, w]`, 1 where the normal is valid and 0 where it is not (no depth, sky, ...).
    pub normal_valid: Vec<f32>,
    /// The image's caption without the modality prefix (may be empty).
    pub caption: String,
}

/// A random-access collection of [`PairSample`]s.
pub trait PairSource: Send + Sync {
    /// Number of samples.
    fn len(&self) -> usize;
    /// Whether there are no samples.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Loads sample `index` (`index < len()`).
    fn load(&self, index: usize) -> Result<PairSample, FinetuneError>;
}
