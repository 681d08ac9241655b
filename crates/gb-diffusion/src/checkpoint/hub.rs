//! Resolving a Hugging Face hub id (`runwayml/stable-diffusion-inpainting`) to a local
//! diffusers folder through the `hf-hub` cache (offline: files must already be cached,
//! e.g. by `huggingface-cli download`).

use std::path::{Path, PathBuf};

use hf_hub::{Cache, Repo, RepoType};

use super::CheckpointError;

/// Files whose presence in the cache marks a usable pipeline snapshot.
const MARKER: &str = "model_index.json";

/// Whether `spec` looks like a hub id (`owner/name`, optionally `@revision`) rather than
/// an existing local path.
pub fn is_hub_id(spec: &str) -> bool {
    !Path::new(spec).exists()
        && spec.split('@').next().is_some_and(|id| {
            let parts: Vec<&str> = id.split('/').collect();
            parts.len() == 2 && parts.iter().all(|p| !p.is_empty() && !p.starts_with('.'))
        })
}

/// Resolves hub id `spec` (`owner/name[@revision]`) in the hf-hub cache rooted at
/// `cache_dir` (default: `$HF_HOME/hub` or `~/.cache/huggingface/hub`) to the snapshot
/// folder that holds its `model_index.json`.
pub fn resolve_cached(spec: &str, cache_dir: Option<&Path>) -> Result<PathBuf, CheckpointError> {
    let (id, revision) = match spec.split_once('@') {
        Some((id, rev)) => (id, rev.to_string()),
        None => (spec, "main".to_string()),
    };
    let cache = match cache_dir {
        Some(dir) => Cache::new(dir.to_path_buf()),
        None => Cache::from_env(),
    };
    let repo = cache.repo(Repo::with_revision(
        id.to_string(),
        RepoType::Model,
        revision.clone(),
    ));
    let marker = repo.get(MARKER).ok_or_else(|| CheckpointError::Hub {
        id: spec.to_string(),
        message: format!(
            "`{MARKER}` of revision `{revision}` is not in the hf-hub cache at {} \
             (download it first, e.g. `huggingface-cli download {id}`)",
            cache.path().display()
        ),
    })?;
    marker
        .parent()
        .map(Path::to_path_buf)
        .ok_or_else(|| CheckpointError::Hub {
            id: spec.to_string(),
            message: format!("cached file {} has no parent folder", marker.display()),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resolves_a_cached_snapshot_and_reports_a_missing_one() {
        let cache = tempfile::tempdir().unwrap();
        let repo_dir = cache.path().join("models--owner--tiny-sd");
        let snap = repo_dir.join("snapshots").join("abc123");
        std::fs::create_dir_all(snap.join("unet")).unwrap();
        std::fs::write(snap.join(MARKER), "{}").unwrap();
        std::fs::create_dir_all(repo_dir.join("refs")).unwrap();
        std::fs::write(repo_dir.join("refs").join("main"), "abc123").unwrap();

        assert!(is_hub_id("owner/tiny-sd"));
        assert!(!is_hub_id("a/b/c"));
        let dir = resolve_cached("owner/tiny-sd", Some(cache.path())).unwrap();
        assert_eq!(dir, snap);
        let err = resolve_cached("owner/other", Some(cache.path())).unwrap_err();
        assert!(err.to_string().contains("owner/other"), "{err}");
        let err = resolve_cached("owner/tiny-sd@v2", Some(cache.path())).unwrap_err();
        assert!(err.to_string().contains("v2"), "{err}");
    }
}
