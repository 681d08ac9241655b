//! Errors of the scene loaders and the procedural generator. Every variant names the file
//! or folder it is about, so a CLI can print it as one clear line.

use std::path::PathBuf;

/// A scene could not be loaded or written.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The path does not exist or is not a folder.
    #[error("{path}: not a folder")]
    NotAFolder {
        /// The path given as a scene.
        path: PathBuf,
    },
    /// The folder holds nothing at all.
    #[error("{path}: empty folder, expected a scene (poses_bounds.npy + images_N/, or transforms*.json)")]
    EmptyFolder {
        /// The folder.
        path: PathBuf,
    },
    /// The folder is neither an LLFF/SPIn-NeRF nor a Blender/nerfstudio scene.
    #[error(
        "{path}: unknown scene layout, expected poses_bounds.npy + images_N/, or transforms*.json"
    )]
    UnknownLayout {
        /// The folder.
        path: PathBuf,
    },
    /// A file the layout requires is missing.
    #[error("{path}: missing {what}")]
    Missing {
        /// The file or folder that should exist.
        path: PathBuf,
        /// What it is.
        what: String,
    },
    /// A `.npy` file could not be parsed or has the wrong dtype.
    #[error("{path}: cannot read .npy: {reason}")]
    Npy {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// The pose array has the wrong shape.
    #[error("{path}: pose array has shape {shape:?}, expected N x 17 (3x5 [R|t|hwf] + near, far)")]
    PoseShape {
        /// The file.
        path: PathBuf,
        /// The shape found.
        shape: Vec<u64>,
    },
    /// A pose or bound is NaN or infinite.
    #[error("{path}: non-finite value {value} in row {row}, column {col}")]
    NonFinitePose {
        /// The file.
        path: PathBuf,
        /// Row (view) index.
        row: usize,
        /// Column index (0..17).
        col: usize,
        /// The value.
        value: f64,
    },
    /// Image and pose counts differ.
    #[error("{images_dir}: {images} images but {poses} poses in {poses_path}")]
    CountMismatch {
        /// The image folder.
        images_dir: PathBuf,
        /// Number of images found.
        images: usize,
        /// The pose file.
        poses_path: PathBuf,
        /// Number of poses in it.
        poses: usize,
    },
    /// An image could not be read.
    #[error(transparent)]
    Image(#[from] gb_core::ImageIoError),
    /// A COLMAP model file is malformed or does not match the scene.
    #[error("{path}: {reason}")]
    Colmap {
        /// The model file.
        path: PathBuf,
        /// What is wrong (with the line or byte offset where it applies).
        reason: String,
    },
    /// A mask file has no image of the same name.
    #[error("{path}: mask has no image of the same name in {images_dir}")]
    OrphanMask {
        /// The mask file.
        path: PathBuf,
        /// The image folder searched.
        images_dir: PathBuf,
    },
    /// Images of one scene have different sizes.
    #[error("{path}: image is {got_w}x{got_h}, but the scene's images are {want_w}x{want_h}")]
    ImageSize {
        /// The image.
        path: PathBuf,
        /// Its width.
        got_w: usize,
        /// Its height.
        got_h: usize,
        /// The expected width.
        want_w: usize,
        /// The expected height.
        want_h: usize,
    },
    /// A JSON file could not be parsed or lacks a field.
    #[error("{path}: {reason}")]
    Json {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// A depth or normal array does not match its image.
    #[error("{path}: array has shape {shape:?}, expected {expected}")]
    ArrayShape {
        /// The file.
        path: PathBuf,
        /// Shape found.
        shape: Vec<u64>,
        /// Shape expected, in words.
        expected: String,
    },
    /// A mask file whose values are not binary.
    #[error("{path}: mask is not binary: {pixels} of {total} pixels lie strictly between 0 and its maximum; object masks are 0/1 or 0/255 (non-zero on the object)")]
    MaskNotBinary {
        /// The mask file.
        path: PathBuf,
        /// Pixels that are neither 0 nor the maximum.
        pixels: usize,
        /// All pixels.
        total: usize,
    },
    /// A depth or normal array holds NaN or infinity.
    #[error(
        "{path}: non-finite value {value} at pixel ({x}, {y}); mark pixels without a value with 0"
    )]
    NonFiniteArray {
        /// The file.
        path: PathBuf,
        /// Column of the first such pixel.
        x: usize,
        /// Row of the first such pixel.
        y: usize,
        /// The value.
        value: f64,
    },
    /// An invalid option value.
    #[error("invalid option: {0}")]
    Option(String),
    /// A file system error.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
}

impl SceneError {
    /// Wraps an IO error with its path.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        SceneError::Io {
            path: path.into(),
            source,
        }
    }
}
