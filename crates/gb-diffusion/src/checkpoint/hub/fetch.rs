//! Downloading a pipeline snapshot through `hf-hub`'s blocking client (ureq over rustls).
//!
//! `hf-hub` 0.4.3 asks `GET {endpoint}/api/models/{id}/revision/{revision}` for the listing
//! (`siblings[].rfilename`, `sha`), then for each file `GET {endpoint}/{id}/resolve/{rev}/{file}`
//! twice: once with `Range: bytes=0-0` for the metadata (`x-repo-commit`, `x-linked-etag` or
//! `etag`, and the size from `Content-Range`, following relative redirects and one absolute
//! one, the CDN), once for the bytes. Files land in the cache layout `huggingface_hub` shares:
//! `blobs/<etag>`, `snapshots/<commit>/<file>` (a relative symlink) and `refs/<rev>`.
//!
//! Files are asked for at the listed commit, not the branch, so that one snapshot never mixes
//! two commits, and `refs/<revision>` is written only once every file is there.

use std::path::{Path, PathBuf};

use hf_hub::api::sync::{ApiBuilder, ApiError, ApiRepo};
use hf_hub::{Cache, Repo, RepoType};

use super::select::{select_files, MARKER};
use super::settings::HubSettings;
use crate::checkpoint::WeightVariant;
use crate::config::{read_json_config, ModelIndex};

/// Times `hf-hub` resumes an interrupted file download before giving up.
const RETRIES: usize = 2;

/// Why a download failed.
#[derive(Debug)]
pub(super) enum Failure {
    /// No HTTP answer at all (name not resolved, connection refused, TLS failure): a cached
    /// snapshot may stand in.
    Unreachable(String),
    /// Anything else: an HTTP error status, a malformed answer, a disk error.
    Other(String),
}

impl Failure {
    /// The one-line message.
    pub(super) fn message(&self) -> &str {
        match self {
            Self::Unreachable(m) | Self::Other(m) => m,
        }
    }
}

/// The cache folder of repository `id` under `cache_dir`.
pub(super) fn repo_dir(cache_dir: &Path, id: &str) -> PathBuf {
    cache_dir.join(Repo::model(id.to_string()).folder_name())
}

/// Downloads what the pipeline `id` at `revision` needs (see [`select_files`]) into the cache
/// of `settings`, skipping files the snapshot already has, and returns the snapshot folder.
pub(super) fn fetch_snapshot(
    id: &str,
    revision: &str,
    settings: &HubSettings,
    variant: WeightVariant,
) -> Result<PathBuf, Failure> {
    let api = ApiBuilder::from_cache(Cache::new(settings.cache_dir.clone()))
        .with_endpoint(settings.endpoint.clone())
        .with_token(settings.token.clone())
        .with_progress(settings.progress)
        .with_retries(RETRIES)
        .with_user_agent("gb-nerf-rs", env!("CARGO_PKG_VERSION"))
        .build()
        .map_err(|e| Failure::Other(format!("cannot set up the hub client: {e}")))?;
    let model = |rev: &str| Repo::with_revision(id.to_string(), RepoType::Model, rev.to_string());
    let listing = api
        .repo(model(revision))
        .info()
        .map_err(|e| describe(e, &format!("listing revision `{revision}`")))?;
    let commit = listing.sha;
    if commit.is_empty() || !commit.bytes().all(|b| b.is_ascii_alphanumeric()) {
        return Err(Failure::Other(format!(
            "listing revision `{revision}`: the hub answered an invalid commit `{commit}`"
        )));
    }
    let files: Vec<String> = listing.siblings.into_iter().map(|s| s.rfilename).collect();
    if !files.iter().any(|f| f == MARKER) {
        return Err(Failure::Other(format!(
            "revision `{revision}` (commit {commit}) has no `{MARKER}`: not a diffusers pipeline"
        )));
    }
    let snapshot = repo_dir(&settings.cache_dir, id)
        .join("snapshots")
        .join(&commit);
    let at_commit = api.repo(model(&commit));
    fetch_file(&at_commit, &snapshot, MARKER)?;
    let index: ModelIndex =
        read_json_config(&snapshot.join(MARKER)).map_err(|e| Failure::Other(e.to_string()))?;
    let wanted = select_files(&index, &files, variant).map_err(Failure::Other)?;
    for file in &wanted {
        fetch_file(&at_commit, &snapshot, file)?;
    }
    publish_ref(&settings.cache_dir, id, revision, &commit)?;
    tracing::info!(
        id,
        revision,
        commit,
        files = wanted.len() + 1,
        "snapshot ready at {}",
        snapshot.display()
    );
    Ok(snapshot)
}

/// Downloads `file` into `snapshot` unless it is there already (a commit's files never
/// change).
fn fetch_file(repo: &ApiRepo, snapshot: &Path, file: &str) -> Result<(), Failure> {
    let pointer = snapshot.join(file);
    if pointer.is_file() {
        return Ok(());
    }
    // A link whose blob was deleted: hf-hub would fail to replace it.
    if std::fs::symlink_metadata(&pointer).is_ok() {
        std::fs::remove_file(&pointer).map_err(|e| {
            Failure::Other(format!(
                "file `{file}`: removing the broken link {}: {e}",
                pointer.display()
            ))
        })?;
    }
    let got = repo
        .download(file)
        .map_err(|e| describe(e, &format!("file `{file}`")))?;
    if got != pointer {
        return Err(Failure::Other(format!(
            "file `{file}`: the hub served it from another commit ({}) than the listing's ({})",
            got.display(),
            pointer.display()
        )));
    }
    tracing::debug!(file, "downloaded");
    Ok(())
}

/// Writes `refs/<revision>` = `commit`, and removes the `refs/<commit>` that hf-hub writes
/// after each file fetched at the commit (unless the revision is that commit).
fn publish_ref(cache_dir: &Path, id: &str, revision: &str, commit: &str) -> Result<(), Failure> {
    let cache = Cache::new(cache_dir.to_path_buf());
    let repo = Repo::with_revision(id.to_string(), RepoType::Model, revision.to_string());
    let refs = repo_dir(cache_dir, id).join("refs");
    cache
        .repo(repo)
        .create_ref(commit)
        .map_err(|e| Failure::Other(format!("writing {}: {e}", refs.join(revision).display())))?;
    if revision != commit {
        // Best effort: a leftover ref naming its own commit is harmless.
        let _ = std::fs::remove_file(refs.join(commit));
    }
    Ok(())
}

/// One line for `err`, the failure of `what` (`file `x``, `listing revision `main``).
fn describe(err: ApiError, what: &str) -> Failure {
    let one_line = |s: String| s.replace(['\r', '\n'], " ");
    match err {
        ApiError::RequestError(e) => {
            let text = e.to_string();
            match (*e).into_response() {
                Some(response) => {
                    let code = response.status();
                    let hint = match code {
                        401 | 403 => " (gated or private: set HF_TOKEN to a token with access)",
                        404 => " (not found)",
                        _ => "",
                    };
                    let detail = response
                        .header("x-error-message")
                        .map(|m| format!(": {m}"))
                        .unwrap_or_default();
                    Failure::Other(one_line(format!(
                        "{what}: GET {}: HTTP {code}{hint}{detail}",
                        response.get_url()
                    )))
                }
                None => {
                    Failure::Unreachable(one_line(format!("{what}: cannot reach the hub: {text}")))
                }
            }
        }
        ApiError::TooManyRetries(inner) => describe(*inner, what),
        ApiError::MissingHeader(header) => Failure::Other(format!(
            "{what}: the answer has no `{header}` header (not a Hugging Face hub endpoint?)"
        )),
        other => Failure::Other(one_line(format!("{what}: {other}"))),
    }
}
