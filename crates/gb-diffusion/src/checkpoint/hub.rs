//! Resolving a Hugging Face hub id (`runwayml/stable-diffusion-inpainting[@revision]`) to a
//! local diffusers folder in the `hf-hub` cache, downloading it when it is not cached.
//!
//! - [`resolve_cached`]: offline, through `hf-hub`'s [`Cache`] (files put there by
//!   `huggingface-cli download`, by Python's `huggingface_hub`, or by [`download`]).
//! - [`download`]: online. It does what `huggingface_hub.snapshot_download` does for a
//!   diffusers pipeline: `GET {endpoint}/api/models/{id}/revision/{revision}` lists the files
//!   (`siblings[].rfilename`) and the commit (`sha`); then `model_index.json` and, for each
//!   component gb-diffusion loads ([`LOADED_COMPONENTS`]), its JSON/text configs and its
//!   `*.safetensors` weights, with the same plain-versus-`.fp16` choice as
//!   [`super::DiffusersFolder::weight_files`]. Each file comes from
//!   `{endpoint}/{id}/resolve/{commit}/{path}` (the commit, not the branch, so that one
//!   snapshot never mixes two commits) and lands in the cache layout that `hf-hub` and
//!   `huggingface_hub` share: `models--owner--name/blobs/<etag>`,
//!   `snapshots/<commit>/<path>` (a relative symlink to the blob, a copy where symlinks are
//!   unavailable) and, once every file is there, `refs/<revision>` holding the commit.
//!   When the server cannot be reached, a snapshot already in the cache is used instead.
//! - [`resolve`]: what the CLI calls: a local folder as is, else the cache, else a download.
//!
//! The endpoint is the argument, else the `HF_ENDPOINT` environment variable (as in
//! `huggingface_hub`), else <https://huggingface.co>. The cache is `$HF_HOME/hub` or
//! `~/.cache/huggingface/hub`. A token, when needed, comes from `HF_TOKEN` or `$HF_HOME/token`.
//!
//! **Transport (a deliberate choice).** The workspace builds `hf-hub` 0.4 with
//! `default-features = false`: its `ureq` feature, and with it the sync `api` module and a TLS
//! stack, is off (enabling it means a long rebuild of the dependency tree and a TLS build on
//! every machine). The download therefore goes through a small HTTP/1.1 client over
//! `std::net::TcpStream` (`checkpoint/hub/http.rs`) that speaks plain `http://` only: a local
//! or in-house mirror, or a loopback server (the tests). For `https://huggingface.co` itself,
//! fetch the repository once with `huggingface-cli download <id>`; every command then finds
//! it offline.

mod http;

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use hf_hub::{Cache, Repo, RepoType};

use super::{CheckpointError, WeightVariant};
use crate::config::{read_json_config, ModelIndex};
use http::HttpError;

/// Files whose presence in the cache marks a usable pipeline snapshot.
const MARKER: &str = "model_index.json";

/// The hub used when neither an endpoint nor `HF_ENDPOINT` is given.
pub const DEFAULT_ENDPOINT: &str = "https://huggingface.co";

/// The environment variable naming the hub endpoint (as in `huggingface_hub`).
pub const ENDPOINT_ENV: &str = "HF_ENDPOINT";

/// The pipeline components that gb-diffusion loads, and so downloads (others, such as
/// `safety_checker` or `feature_extractor`, are skipped: they are never used here and the
/// safety checker alone is over 1 GB).
pub const LOADED_COMPONENTS: [&str; 5] = ["scheduler", "text_encoder", "tokenizer", "unet", "vae"];

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

/// The hf-hub cache rooted at `cache_dir`, or the environment's.
fn open_cache(cache_dir: Option<&Path>) -> Cache {
    match cache_dir {
        Some(dir) => Cache::new(dir.to_path_buf()),
        None => Cache::from_env(),
    }
}

/// Whether `rev` is a full commit hash (then `snapshots/<rev>` is used directly).
fn is_commit_hash(rev: &str) -> bool {
    rev.len() == 40 && rev.bytes().all(|b| b.is_ascii_hexdigit())
}

/// Resolves hub id `spec` (`owner/name[@revision]`) in the hf-hub cache rooted at
/// `cache_dir` (default: `$HF_HOME/hub` or `~/.cache/huggingface/hub`) to the snapshot
/// folder that holds its `model_index.json`. Never touches the network.
pub fn resolve_cached(spec: &str, cache_dir: Option<&Path>) -> Result<PathBuf, CheckpointError> {
    let (id, revision) = split_spec(spec);
    let cache = open_cache(cache_dir);
    let repo = cache.repo(Repo::with_revision(
        id.to_string(),
        RepoType::Model,
        revision.clone(),
    ));
    let by_ref = repo.get(MARKER);
    let by_commit = || {
        let snap = cache
            .path()
            .join(Repo::model(id.to_string()).folder_name())
            .join("snapshots")
            .join(&revision);
        (is_commit_hash(&revision) && snap.join(MARKER).is_file()).then(|| snap.join(MARKER))
    };
    let marker = by_ref
        .or_else(by_commit)
        .ok_or_else(|| CheckpointError::Hub {
            id: spec.to_string(),
            message: format!(
                "`{MARKER}` of revision `{revision}` is not in the hf-hub cache at {} \
             (download it first, e.g. `huggingface-cli download {id}`, or set \
             {ENDPOINT_ENV} to an http:// mirror)",
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

/// The endpoint to use: `explicit`, else `$HF_ENDPOINT`, else [`DEFAULT_ENDPOINT`]; without
/// a trailing `/`.
pub fn endpoint(explicit: Option<&str>) -> String {
    pick_endpoint(explicit, std::env::var(ENDPOINT_ENV).ok().as_deref())
}

fn pick_endpoint(explicit: Option<&str>, env: Option<&str>) -> String {
    explicit
        .or(env)
        .map(str::trim)
        .filter(|e| !e.is_empty())
        .unwrap_or(DEFAULT_ENDPOINT)
        .trim_end_matches('/')
        .to_string()
}

/// A local diffusers folder as is; otherwise a hub id, from the cache when it is there,
/// else downloaded from `endpoint` (see [`endpoint`]) into the cache.
pub fn resolve(
    spec: &str,
    endpoint: Option<&str>,
    cache_dir: Option<&Path>,
) -> Result<PathBuf, CheckpointError> {
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
    let cached = match resolve_cached(spec, cache_dir) {
        Ok(dir) => return Ok(dir),
        Err(e) => e,
    };
    download(spec, endpoint, cache_dir).map_err(|e| CheckpointError::Hub {
        id: spec.to_string(),
        message: format!(
            "{}; downloading it failed: {}",
            hub_message(cached),
            hub_message(e)
        ),
    })
}

/// The message of a [`CheckpointError::Hub`] without its `hub id` prefix.
fn hub_message(e: CheckpointError) -> String {
    match e {
        CheckpointError::Hub { message, .. } => message,
        other => other.to_string(),
    }
}

/// Downloads the pipeline `spec` (`owner/name[@revision]`) from `endpoint` (see
/// [`endpoint`]) into the hf-hub cache at `cache_dir` (default: the environment's) and
/// returns its snapshot folder, which [`resolve_cached`] finds afterwards. Weight files
/// follow [`WeightVariant::Auto`]. When the server cannot be reached, a cached snapshot of
/// the same revision is returned instead.
pub fn download(
    spec: &str,
    endpoint: Option<&str>,
    cache_dir: Option<&Path>,
) -> Result<PathBuf, CheckpointError> {
    download_variant(spec, endpoint, cache_dir, WeightVariant::Auto)
}

/// [`download`] with a choice of weight files: [`WeightVariant::Full`] only the plain ones,
/// [`WeightVariant::Fp16`] only the `.fp16` ones, [`WeightVariant::Auto`] the plain ones
/// when a component has them, else its `.fp16` ones.
pub fn download_variant(
    spec: &str,
    endpoint: Option<&str>,
    cache_dir: Option<&Path>,
    variant: WeightVariant,
) -> Result<PathBuf, CheckpointError> {
    let (id, revision) = split_spec(spec);
    let hub_err = |message: String| CheckpointError::Hub {
        id: spec.to_string(),
        message,
    };
    if !valid_id(id) {
        return Err(hub_err("not a hub id of the form `owner/name`".into()));
    }
    let job = Snapshot {
        id,
        revision: &revision,
        endpoint: self::endpoint(endpoint),
        cache: open_cache(cache_dir),
        token: std::env::var("HF_TOKEN")
            .ok()
            .filter(|t| !t.trim().is_empty())
            .or_else(|| open_cache(cache_dir).token()),
    };
    match job.fetch(variant) {
        Ok(dir) => Ok(dir),
        Err(HttpError::Connect(msg)) => match resolve_cached(spec, cache_dir) {
            Ok(dir) => {
                tracing::warn!("{msg}; using the cached snapshot {}", dir.display());
                Ok(dir)
            }
            Err(_) => Err(hub_err(format!("{msg}, and the revision is not cached"))),
        },
        Err(e) => Err(hub_err(e.to_string())),
    }
}

/// One snapshot download.
struct Snapshot<'a> {
    id: &'a str,
    revision: &'a str,
    endpoint: String,
    cache: Cache,
    token: Option<String>,
}

impl Snapshot<'_> {
    fn repo_dir(&self) -> PathBuf {
        self.cache
            .path()
            .join(Repo::model(self.id.to_string()).folder_name())
    }

    fn fetch(&self, variant: WeightVariant) -> Result<PathBuf, HttpError> {
        let (commit, files) = self.list_files()?;
        if !files.iter().any(|f| f == MARKER) {
            return Err(HttpError::Other(format!(
                "revision `{}` (commit {commit}) has no `{MARKER}`: not a diffusers pipeline",
                self.revision
            )));
        }
        let snapshot = self.repo_dir().join("snapshots").join(&commit);
        self.fetch_file(&commit, MARKER, &snapshot)?;
        let index: ModelIndex = read_json_config(&snapshot.join(MARKER))
            .map_err(|e| HttpError::Other(e.to_string()))?;
        let wanted = select_files(&index, &files, variant);
        for file in &wanted {
            self.fetch_file(&commit, file, &snapshot)?;
        }
        let repo = self.cache.repo(Repo::with_revision(
            self.id.to_string(),
            RepoType::Model,
            self.revision.to_string(),
        ));
        repo.create_ref(&commit).map_err(|e| {
            HttpError::Other(format!(
                "writing refs/{} in {}: {e}",
                self.revision,
                self.repo_dir().display()
            ))
        })?;
        tracing::info!(
            id = self.id,
            revision = self.revision,
            commit,
            files = wanted.len() + 1,
            "snapshot downloaded to {}",
            snapshot.display()
        );
        Ok(snapshot)
    }

    /// `GET {endpoint}/api/models/{id}/revision/{revision}`: the commit and the file list.
    fn list_files(&self) -> Result<(String, Vec<String>), HttpError> {
        let url = format!(
            "{}/api/models/{}/revision/{}",
            self.endpoint,
            http::encode(self.id, true),
            http::encode(self.revision, false)
        );
        let text = http::get(&url, self.token.as_deref())
            .and_then(http::Response::text)
            .map_err(|e| match e {
                HttpError::Status { code, reason, url } => HttpError::Other(format!(
                    "GET {url}: HTTP {code} {reason} (repository or revision `{}` not found?)",
                    self.revision
                )),
                other => other,
            })?;
        let json: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| HttpError::Other(format!("GET {url}: invalid JSON: {e}")))?;
        let commit = json
            .get("sha")
            .and_then(|s| s.as_str())
            .filter(|s| !s.is_empty() && s.bytes().all(|b| b.is_ascii_alphanumeric()))
            .ok_or_else(|| HttpError::Other(format!("GET {url}: no valid `sha` in the answer")))?
            .to_string();
        let files = json
            .get("siblings")
            .and_then(|s| s.as_array())
            .ok_or_else(|| HttpError::Other(format!("GET {url}: no `siblings` list")))?
            .iter()
            .filter_map(|s| s.get("rfilename").and_then(|f| f.as_str()))
            .map(str::to_string)
            .collect();
        Ok((commit, files))
    }

    /// Downloads `file` of `commit` into the blob store and links it into `snapshot`
    /// (nothing to do when the snapshot already has it: a commit's files never change).
    fn fetch_file(&self, commit: &str, file: &str, snapshot: &Path) -> Result<(), HttpError> {
        let unsafe_path = file.is_empty()
            || file.starts_with('/')
            || file.contains('\\')
            || file
                .split('/')
                .any(|p| p.is_empty() || p == "." || p == "..");
        if unsafe_path {
            return Err(HttpError::Other(format!(
                "the server listed an unsafe file name `{file}`"
            )));
        }
        let pointer = snapshot.join(file);
        if pointer.is_file() {
            return Ok(());
        }
        let url = format!(
            "{}/{}/resolve/{}/{}",
            self.endpoint,
            http::encode(self.id, true),
            commit,
            http::encode(file, true)
        );
        let response = http::get(&url, self.token.as_deref()).map_err(|e| match e {
            HttpError::Status { code, reason, url } => {
                HttpError::Other(format!("file `{file}`: GET {url}: HTTP {code} {reason}"))
            }
            HttpError::Other(m) => HttpError::Other(format!("file `{file}`: {m}")),
            connect => connect,
        })?;
        let blobs = self.repo_dir().join("blobs");
        let io = |what: &str, p: &Path, e: std::io::Error| {
            HttpError::Other(format!("file `{file}`: {what} {}: {e}", p.display()))
        };
        std::fs::create_dir_all(&blobs).map_err(|e| io("creating", &blobs, e))?;
        let etag = response
            .header("x-linked-etag")
            .or_else(|| response.header("etag"))
            .map(clean_etag)
            .filter(|e| !e.is_empty());
        let blob = match &etag {
            Some(tag) if blobs.join(tag).is_file() => blobs.join(tag),
            _ => {
                let tmp = blobs.join(format!(
                    "{}.{}.incomplete",
                    etag.as_deref().unwrap_or("download"),
                    std::process::id()
                ));
                let mut out = HashingWriter {
                    inner: File::create(&tmp).map_err(|e| io("creating", &tmp, e))?,
                    hash: FNV_OFFSET,
                };
                let copied = response.copy_to(&mut out);
                let flushed = out.inner.sync_all();
                if let Err(e) = copied {
                    let _ = std::fs::remove_file(&tmp);
                    return Err(HttpError::Other(format!("file `{file}`: {e}")));
                }
                flushed.map_err(|e| io("writing", &tmp, e))?;
                let name = etag.unwrap_or_else(|| format!("fnv1a64-{:016x}", out.hash));
                let blob = blobs.join(name);
                std::fs::rename(&tmp, &blob).map_err(|e| io("renaming", &tmp, e))?;
                blob
            }
        };
        if let Some(parent) = pointer.parent() {
            std::fs::create_dir_all(parent).map_err(|e| io("creating", parent, e))?;
        }
        link_or_copy(&blob, &pointer, file.split('/').count())
            .map_err(|e| io("linking", &pointer, e))?;
        tracing::debug!(file, blob = %blob.display(), "downloaded");
        Ok(())
    }
}

/// The files of `files` (the repository listing) that the components of `index` need:
/// for each listed component in [`LOADED_COMPONENTS`], the `*.json` / `*.txt` files directly
/// in its folder and the `*.safetensors` weights of `variant`.
fn select_files(index: &ModelIndex, files: &[String], variant: WeightVariant) -> Vec<String> {
    let mut out = Vec::new();
    for component in index.component_names() {
        if !LOADED_COMPONENTS.contains(&component.as_str()) {
            continue;
        }
        let prefix = format!("{component}/");
        let direct: Vec<&str> = files
            .iter()
            .filter_map(|f| f.strip_prefix(&prefix))
            .filter(|rest| !rest.contains('/'))
            .collect();
        let mut full = Vec::new();
        let mut fp16 = Vec::new();
        for name in &direct {
            if name.ends_with(".json") || name.ends_with(".txt") {
                out.push(format!("{prefix}{name}"));
            } else if let Some(stem) = name.strip_suffix(".safetensors") {
                // Same rule as `folder::list_safetensors`.
                if stem.ends_with(".fp16") || stem.contains(".fp16-") {
                    fp16.push(format!("{prefix}{name}"));
                } else if !stem.contains('.') {
                    full.push(format!("{prefix}{name}"));
                }
            }
        }
        out.extend(match variant {
            WeightVariant::Full => full,
            WeightVariant::Fp16 => fp16,
            WeightVariant::Auto if !full.is_empty() => full,
            WeightVariant::Auto => fp16,
        });
    }
    out.sort();
    out
}

/// An ETag as a file name: no weak prefix, no quotes; empty when it holds anything but
/// `[A-Za-z0-9._-]`.
fn clean_etag(raw: &str) -> String {
    let tag = raw.trim().trim_start_matches("W/").trim_matches('"');
    if tag
        .bytes()
        .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.'))
        && !tag.starts_with('.')
    {
        tag.to_string()
    } else {
        String::new()
    }
}

/// `snapshots/<commit>/<file>` -> `../../blobs/<etag>` (one more `..` per folder level of
/// `file`), as `huggingface_hub` does; a copy when symlinks are unavailable.
fn link_or_copy(blob: &Path, pointer: &Path, depth: usize) -> std::io::Result<()> {
    let _ = std::fs::remove_file(pointer);
    #[cfg(unix)]
    {
        let mut rel = PathBuf::new();
        for _ in 0..depth + 1 {
            rel.push("..");
        }
        rel.push("blobs");
        rel.push(blob.file_name().unwrap_or_default());
        if std::os::unix::fs::symlink(&rel, pointer).is_ok() {
            return Ok(());
        }
    }
    let _ = depth;
    std::fs::copy(blob, pointer).map(|_| ())
}

const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
const FNV_PRIME: u64 = 0x0000_0100_0000_01b3;

/// A writer that FNV-1a-hashes what passes through (the blob name when the server sends
/// no ETag).
struct HashingWriter<W> {
    inner: W,
    hash: u64,
}

impl<W: Write> Write for HashingWriter<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        for &b in &buf[..n] {
            self.hash = (self.hash ^ u64::from(b)).wrapping_mul(FNV_PRIME);
        }
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
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

        // A full commit hash finds its snapshot without a ref.
        let commit = "0123456789abcdef0123456789abcdef01234567";
        let snap2 = repo_dir.join("snapshots").join(commit);
        std::fs::create_dir_all(&snap2).unwrap();
        std::fs::write(snap2.join(MARKER), "{}").unwrap();
        let spec = format!("owner/tiny-sd@{commit}");
        assert_eq!(resolve_cached(&spec, Some(cache.path())).unwrap(), snap2);
    }

    #[test]
    fn endpoint_precedence_and_etags() {
        assert_eq!(pick_endpoint(None, None), DEFAULT_ENDPOINT);
        assert_eq!(pick_endpoint(None, Some("http://m:1/")), "http://m:1");
        assert_eq!(
            pick_endpoint(Some("http://a"), Some("http://b")),
            "http://a"
        );
        assert_eq!(pick_endpoint(Some(" "), Some("http://b")), DEFAULT_ENDPOINT);
        assert_eq!(clean_etag("W/\"abc-12\""), "abc-12");
        assert_eq!(clean_etag("\"../x\""), "");
        assert_eq!(split_spec("o/n@"), ("o/n", "main".to_string()));
        assert_eq!(
            split_spec("o/n@refs/pr/1"),
            ("o/n", "refs/pr/1".to_string())
        );
    }

    #[test]
    fn selects_configs_and_the_weight_variant_of_loaded_components() {
        let index: ModelIndex = serde_json::from_str(
            r#"{"_class_name":"StableDiffusionInpaintPipeline",
                "unet":["diffusers","UNet2DConditionModel"],
                "vae":["diffusers","AutoencoderKL"],
                "safety_checker":["stable_diffusion","StableDiffusionSafetyChecker"],
                "tokenizer":["transformers","CLIPTokenizer"],
                "text_encoder":[null,null]}"#,
        )
        .unwrap();
        let files: Vec<String> = [
            "model_index.json",
            "README.md",
            "unet/config.json",
            "unet/diffusion_pytorch_model.safetensors",
            "unet/diffusion_pytorch_model.fp16.safetensors",
            "unet/diffusion_pytorch_model.bin",
            "vae/config.json",
            "vae/diffusion_pytorch_model.fp16.safetensors",
            "vae/sub/x.json",
            "safety_checker/model.safetensors",
            "tokenizer/vocab.json",
            "tokenizer/merges.txt",
            "text_encoder/model.safetensors",
        ]
        .map(String::from)
        .to_vec();
        let auto = select_files(&index, &files, WeightVariant::Auto);
        assert_eq!(
            auto,
            [
                "tokenizer/merges.txt",
                "tokenizer/vocab.json",
                "unet/config.json",
                "unet/diffusion_pytorch_model.safetensors",
                "vae/config.json",
                "vae/diffusion_pytorch_model.fp16.safetensors",
            ]
        );
        let full = select_files(&index, &files, WeightVariant::Full);
        assert!(!full.iter().any(|f| f.contains("fp16")), "{full:?}");
        let fp16 = select_files(&index, &files, WeightVariant::Fp16);
        assert!(fp16.contains(&"unet/diffusion_pytorch_model.fp16.safetensors".to_string()));
        assert!(!fp16.contains(&"unet/diffusion_pytorch_model.safetensors".to_string()));
    }
}
