//! Resolving a Hugging Face hub id (`stable-diffusion-v1-5/stable-diffusion-inpainting[@revision]`)
//! to a local diffusers folder in the hub cache, downloading it through `hf-hub` when it is
//! not cached.
//!
//! - [`resolve`]: what the CLI calls. A local folder as is; else a complete snapshot already
//!   in the cache, without any network call; else (unless offline) a download.
//! - [`resolve_cached`]: offline: the snapshot that `refs/<revision>` (or a full commit hash)
//!   names, when it holds everything the pipeline loads. Files put there by
//!   `huggingface-cli download`, Python's `huggingface_hub` or [`download`] all count.
//! - [`download`] / [`download_variant`]: online. Lists the revision, then fetches
//!   `model_index.json` and, for each component gb-diffusion loads
//!   ([`LOADED_COMPONENTS`]), its JSON/text configs and its `*.safetensors` weights (see
//!   `hub/select.rs`; pickled-only components are refused with advice). Falls back to the
//!   cached snapshot when the hub cannot be reached.
//!
//! Settings ([`HubSettings`], read once from the environment by [`HubSettings::from_env`]):
//! `HF_ENDPOINT` (the hub), `HF_HUB_CACHE` / `HF_HOME` (the cache), `HF_TOKEN` (auth) and
//! `HF_HUB_OFFLINE` (no network at all).

mod fetch;
mod select;
mod settings;

use std::path::{Path, PathBuf};

pub use select::{select_files, snapshot_gap, LOADED_COMPONENTS, MARKER};
pub use settings::{
    HubSettings, CACHE_ENV, DEFAULT_ENDPOINT, ENDPOINT_ENV, HOME_ENV, OFFLINE_ENV, TOKEN_ENV,
};

use super::{CheckpointError, WeightVariant};
use fetch::Failure;

/// Whether `spec` looks like a hub id (`owner/name`, optionally `@revision`) rather than
/// an existing local path.
pub fn is_hub_id(spec: &str) -> bool {
    !Path::new(spec).exists() && spec.split('@').next().is_some_and(valid_id)
}

/// `owner/name`: two non-empty parts, neither starting with `.`.
fn valid_id(id: &str) -> bool {
    let parts: Vec<&str> = id.split('/').collect();
    parts.len() == 2 && parts.iter().all(|p| !p.is_empty() && !p.starts_with('.'))
}

/// Splits `owner/name[@revision]` into the id and the revision (`main` by default).
fn split_spec(spec: &str) -> (&str, String) {
    match spec.split_once('@') {
        Some((id, rev)) if !rev.is_empty() => (id, rev.to_string()),
        Some((id, _)) => (id, "main".to_string()),
        None => (spec, "main".to_string()),
    }
}

/// Whether `rev` is a full commit hash (then `snapshots/<rev>` is used directly).
fn is_commit_hash(rev: &str) -> bool {
    rev.len() == 40 && rev.bytes().all(|b| b.is_ascii_hexdigit())
}

fn hub_error(spec: &str, message: String) -> CheckpointError {
    CheckpointError::Hub {
        id: spec.to_string(),
        message,
    }
}

/// Resolves hub id `spec` (`owner/name[@revision]`) in the hub cache rooted at `cache_dir`
/// to its snapshot folder. Never touches the network. Errors when the revision is not cached
/// or its snapshot lacks a file the pipeline loads ([`snapshot_gap`]).
pub fn resolve_cached(spec: &str, cache_dir: &Path) -> Result<PathBuf, CheckpointError> {
    let (id, revision) = split_spec(spec);
    let repo_dir = fetch::repo_dir(cache_dir, id);
    let by_ref = std::fs::read_to_string(repo_dir.join("refs").join(&revision))
        .ok()
        .map(|commit| commit.trim().to_string())
        .filter(|commit| !commit.is_empty() && !commit.contains(['/', '\\', '.']));
    let commit = by_ref.or_else(|| is_commit_hash(&revision).then(|| revision.clone()));
    let snapshot = commit
        .map(|c| repo_dir.join("snapshots").join(c))
        .filter(|dir| dir.join(MARKER).is_file())
        .ok_or_else(|| {
            hub_error(
                spec,
                format!(
                    "revision `{revision}` is not in the hub cache at {}",
                    cache_dir.display()
                ),
            )
        })?;
    if let Some(gap) = snapshot_gap(&snapshot) {
        return Err(hub_error(
            spec,
            format!(
                "the cached snapshot {} is incomplete: {gap}",
                snapshot.display()
            ),
        ));
    }
    Ok(snapshot)
}

/// A local diffusers folder as is; otherwise hub id `spec` from the cache of `settings`
/// when a complete snapshot is there (no network call), else downloaded from its endpoint,
/// unless `settings.offline`.
pub fn resolve(spec: &str, settings: &HubSettings) -> Result<PathBuf, CheckpointError> {
    let path = Path::new(spec);
    if path.is_dir() {
        return Ok(path.to_path_buf());
    }
    if !is_hub_id(spec) {
        return Err(CheckpointError::MissingFile {
            path: path.to_path_buf(),
            what: "a diffusers pipeline folder or a hub id `owner/name[@revision]`".into(),
        });
    }
    let cached = match resolve_cached(spec, &settings.cache_dir) {
        Ok(dir) => return Ok(dir),
        Err(CheckpointError::Hub { message, .. }) => message,
        Err(other) => other.to_string(),
    };
    let (id, revision) = split_spec(spec);
    if settings.offline {
        return Err(hub_error(spec, offline_message(&cached, id)));
    }
    fetch::fetch_snapshot(id, &revision, settings, WeightVariant::Auto).map_err(|f| {
        hub_error(
            spec,
            format!(
                "{cached}, and downloading it from {} failed: {}",
                settings.endpoint,
                f.message()
            ),
        )
    })
}

/// The message for a snapshot that is not cached while `HF_HUB_OFFLINE` is set.
fn offline_message(cached: &str, id: &str) -> String {
    format!(
        "{cached}, and {OFFLINE_ENV} is set, so nothing is downloaded (unset it, or fetch the \
         pipeline once with `huggingface-cli download {id}`)"
    )
}

/// Downloads the pipeline `spec` (`owner/name[@revision]`) with the plain weights where a
/// component has them, else its `.fp16` ones ([`WeightVariant::Auto`]); see
/// [`download_variant`].
pub fn download(spec: &str, settings: &HubSettings) -> Result<PathBuf, CheckpointError> {
    download_variant(spec, settings, WeightVariant::Auto)
}

/// Downloads the pipeline `spec` (`owner/name[@revision]`) from the endpoint of `settings`
/// into its cache (files the snapshot already has are not fetched again) and returns the
/// snapshot folder, which [`resolve_cached`] finds afterwards. [`WeightVariant::Full`]: only
/// the plain weights, [`WeightVariant::Fp16`]: only the `.fp16` ones. When the hub cannot be
/// reached, the cached snapshot of the same revision is returned instead; when
/// `settings.offline`, only the cache is looked at.
pub fn download_variant(
    spec: &str,
    settings: &HubSettings,
    variant: WeightVariant,
) -> Result<PathBuf, CheckpointError> {
    let (id, revision) = split_spec(spec);
    if !valid_id(id) {
        return Err(hub_error(
            spec,
            "not a hub id of the form `owner/name[@revision]`".into(),
        ));
    }
    if settings.offline {
        return resolve_cached(spec, &settings.cache_dir).map_err(|e| match e {
            CheckpointError::Hub { message, .. } => hub_error(spec, offline_message(&message, id)),
            other => other,
        });
    }
    match fetch::fetch_snapshot(id, &revision, settings, variant) {
        Ok(dir) => Ok(dir),
        Err(Failure::Unreachable(msg)) => match resolve_cached(spec, &settings.cache_dir) {
            Ok(dir) => {
                tracing::warn!("{msg}; using the cached snapshot {}", dir.display());
                Ok(dir)
            }
            Err(_) => Err(hub_error(
                spec,
                format!(
                    "{msg}, and revision `{revision}` is not in the hub cache at {}",
                    settings.cache_dir.display()
                ),
            )),
        },
        Err(Failure::Other(msg)) => Err(hub_error(spec, msg)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const INDEX: &str = r#"{"_class_name":"StableDiffusionInpaintPipeline","unet":["diffusers","UNet2DConditionModel"]}"#;

    /// A complete snapshot `snapshots/<commit>` of `models--owner--tiny-sd`.
    fn snapshot(repo_dir: &Path, commit: &str) -> PathBuf {
        let snap = repo_dir.join("snapshots").join(commit);
        std::fs::create_dir_all(snap.join("unet")).unwrap();
        std::fs::write(snap.join(MARKER), INDEX).unwrap();
        std::fs::write(snap.join("unet/diffusion_pytorch_model.safetensors"), "w").unwrap();
        snap
    }

    #[test]
    fn resolves_a_cached_snapshot_and_reports_a_missing_one() {
        let cache = tempfile::tempdir().unwrap();
        let repo_dir = cache.path().join("models--owner--tiny-sd");
        let snap = snapshot(&repo_dir, "abc123");
        std::fs::create_dir_all(repo_dir.join("refs")).unwrap();
        std::fs::write(repo_dir.join("refs").join("main"), "abc123\n").unwrap();

        assert!(is_hub_id("owner/tiny-sd"));
        assert!(is_hub_id(
            "stable-diffusion-v1-5/stable-diffusion-inpainting@main"
        ));
        assert!(!is_hub_id("a/b/c"));
        assert_eq!(resolve_cached("owner/tiny-sd", cache.path()).unwrap(), snap);
        let err = resolve_cached("owner/other", cache.path()).unwrap_err();
        assert!(err.to_string().contains("owner/other"), "{err}");
        let err = resolve_cached("owner/tiny-sd@v2", cache.path()).unwrap_err();
        assert!(err.to_string().contains("v2"), "{err}");

        // A full commit hash finds its snapshot without a ref.
        let commit = "0123456789abcdef0123456789abcdef01234567";
        let snap2 = snapshot(&repo_dir, commit);
        let spec = format!("owner/tiny-sd@{commit}");
        assert_eq!(resolve_cached(&spec, cache.path()).unwrap(), snap2);

        // A snapshot without the weights is not usable.
        std::fs::remove_file(snap.join("unet/diffusion_pytorch_model.safetensors")).unwrap();
        let err = resolve_cached("owner/tiny-sd", cache.path())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("incomplete") && err.contains("`unet/`"),
            "{err}"
        );
    }

    #[test]
    fn offline_resolution_never_downloads() {
        let cache = tempfile::tempdir().unwrap();
        let mut settings = HubSettings::with_cache_dir(cache.path());
        settings.offline = true;
        // An endpoint nothing listens on: any network call would fail differently.
        settings.endpoint = "http://127.0.0.1:1".into();
        let err = resolve("owner/not-cached", &settings)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("owner/not-cached")
                && err.contains(OFFLINE_ENV)
                && !err.contains("cannot reach"),
            "{err}"
        );
        let err = download("owner/not-cached", &settings)
            .unwrap_err()
            .to_string();
        assert!(err.contains(OFFLINE_ENV), "{err}");
        let snap = snapshot(&cache.path().join("models--owner--tiny-sd"), "c1");
        std::fs::create_dir_all(cache.path().join("models--owner--tiny-sd/refs")).unwrap();
        std::fs::write(cache.path().join("models--owner--tiny-sd/refs/main"), "c1").unwrap();
        assert_eq!(resolve("owner/tiny-sd", &settings).unwrap(), snap);
        assert_eq!(download("owner/tiny-sd", &settings).unwrap(), snap);
    }

    #[test]
    fn splits_specs() {
        assert_eq!(split_spec("o/n@"), ("o/n", "main".to_string()));
        assert_eq!(split_spec("o/n"), ("o/n", "main".to_string()));
        assert_eq!(
            split_spec("o/n@refs/pr/1"),
            ("o/n", "refs/pr/1".to_string())
        );
        let err = download("not-an-id", &HubSettings::with_cache_dir("/nonexistent"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("not-an-id") && err.contains("owner/name"),
            "{err}"
        );
    }
}
