//! Listing image files in a stable order.

use super::SceneError;
use std::path::{Path, PathBuf};

/// Image files (`.png`, `.jpg`, `.jpeg`, any case) directly inside `dir`, sorted by file
/// name (byte order), so that their order matches `poses_bounds.npy` rows.
pub fn list_images(dir: &Path) -> Result<Vec<PathBuf>, SceneError> {
    let rd = std::fs::read_dir(dir).map_err(|e| SceneError::io(dir, e))?;
    let mut out = Vec::new();
    for entry in rd {
        let entry = entry.map_err(|e| SceneError::io(dir, e))?;
        let path = entry.path();
        if path.is_file() && is_image(&path) {
            out.push(path);
        }
    }
    out.sort();
    Ok(out)
}

/// Whether a path has an image extension.
pub fn is_image(path: &Path) -> bool {
    matches!(
        path.extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .as_deref(),
        Some("png" | "jpg" | "jpeg")
    )
}

/// The file stem as a `String` (lossy).
pub fn stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}
