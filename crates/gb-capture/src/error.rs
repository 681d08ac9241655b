//! What can go wrong in a capture, each with the file, flag or step to fix.

use std::path::PathBuf;

/// A capture failed.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// The `colmap` program is not there.
    #[error("--colmap {program}: COLMAP is not installed or not on PATH ({reason}); install it (Debian/Ubuntu: apt-get install colmap) or pass --colmap PATH")]
    ColmapMissing {
        /// The program tried.
        program: String,
        /// Why it did not start.
        reason: String,
    },
    /// `--images` holds too few images.
    #[error("--images {}: {found} images (png, jpg); a capture needs at least 3", dir.display())]
    TooFewImages {
        /// The folder.
        dir: PathBuf,
        /// Images found.
        found: usize,
    },
    /// Masks whose names match no image.
    #[error("--masks {}: {} mask(s) match no image of --images by name: {}; name each mask after its image (IMG_0001.jpg -> IMG_0001.png)", dir.display(), names.len(), names.join(", "))]
    MaskNames {
        /// The mask folder.
        dir: PathBuf,
        /// The unmatched mask file names (the first few).
        names: Vec<String>,
    },
    /// A mask's size differs from its image's.
    #[error("{}: the mask is {mask_w}x{mask_h}, its image is {image_w}x{image_h}", path.display())]
    MaskSize {
        /// The mask.
        path: PathBuf,
        /// Mask width.
        mask_w: usize,
        /// Mask height.
        mask_h: usize,
        /// Image width.
        image_w: usize,
        /// Image height.
        image_h: usize,
    },
    /// A COLMAP step failed.
    #[error("COLMAP {stage} failed ({status}); its log: {}", log.display())]
    Colmap {
        /// The COLMAP command.
        stage: &'static str,
        /// Its exit status.
        status: String,
        /// Its output.
        log: PathBuf,
    },
    /// COLMAP registered too few of the images.
    #[error("COLMAP registered {registered} of {total} images (at least half and 3 are needed): take more overlapping photos, try --matcher exhaustive, or check that the masks cover only the object; unregistered: {}", unregistered.join(", "))]
    TooFewRegistered {
        /// Images registered.
        registered: usize,
        /// Images given.
        total: usize,
        /// The first unregistered names.
        unregistered: Vec<String>,
    },
    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// An image could not be read or written.
    #[error(transparent)]
    Image(#[from] gb_core::ImageIoError),
    /// The sparse model could not be read or written.
    #[error(transparent)]
    Scene(#[from] gb_nerf::scene::SceneError),
}

impl CaptureError {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }
}
