//! Hub downloads through `hf-hub` against a loopback server that speaks the hub's protocol
//! and serves the committed tiny pipeline (`fixtures/sd_image/pipeline`):
//!
//! - `GET /api/models/{id}/revision/{rev}`: JSON `sha`, `siblings[].rfilename` (chunked);
//! - `GET /{id}/resolve/{rev}/{file}`: weights (`*.safetensors`, LFS files on the real hub)
//!   answer `302` with an absolute `Location` on a "CDN" path, `X-Linked-Etag` and
//!   `X-Repo-Commit`; tokenizer files a relative `307` to `/api/resolve-cache/...`, as the
//!   hub does for small files; other files answer directly with `ETag` and `X-Repo-Commit`.
//!   Every file answer honours `Range` (`206`, `Content-Range`), which hf-hub needs for the
//!   size.
//!
//! The server listens on 127.0.0.1 only, answers at most [`MAX_REQUESTS`] requests, stops
//! after [`LIFETIME`] at the latest, and stops when dropped. Settings are passed explicitly
//! ([`HubSettings::from_vars`] with a map), so no test touches the process environment.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::io::{BufRead, BufReader, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use gb_core::BackendKind;
use gb_diffusion::checkpoint::hub::{
    download, resolve, resolve_cached, HubSettings, CACHE_ENV, ENDPOINT_ENV, OFFLINE_ENV, TOKEN_ENV,
};
use gb_diffusion::distill::sd_adapter::SdPrior;
use gb_diffusion::pipeline::SdComponents;

const COMMIT: &str = "0123456789abcdef0123456789abcdef01234567";
const FULL_VAE: &str = "vae/diffusion_pytorch_model.safetensors";
const FP16_VAE: &str = "vae/diffusion_pytorch_model.fp16.safetensors";
const FULL_UNET: &str = "unet/diffusion_pytorch_model.safetensors";
const FP16_UNET: &str = "unet/diffusion_pytorch_model.fp16.safetensors";
const TOKEN: &str = "hf_loopback_token";
/// Requests one server answers at most.
const MAX_REQUESTS: usize = 300;
/// How long one server lives at most.
const LIFETIME: Duration = Duration::from_secs(120);

fn pipeline() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sd_image/pipeline")
}

/// Every file under `dir`, as `/`-separated relative paths.
fn walk(dir: &Path, prefix: &str, out: &mut Vec<String>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir).unwrap().flatten().collect();
    entries.sort_by_key(|e| e.file_name());
    for e in entries {
        let name = format!("{prefix}{}", e.file_name().to_string_lossy());
        if e.path().is_dir() {
            walk(&e.path(), &format!("{name}/"), out);
        } else {
            out.push(name);
        }
    }
}

fn fixture_files() -> Vec<String> {
    let mut files = Vec::new();
    walk(&pipeline(), "", &mut files);
    assert!(files.len() >= 10, "{files:?}");
    files
}

/// One served repository: listed file -> fixture file it is served from (`None`: listed
/// but answered 404).
struct RepoSpec {
    files: BTreeMap<String, Option<String>>,
}

fn tiny_sd() -> RepoSpec {
    let mut files: BTreeMap<_, _> = fixture_files()
        .into_iter()
        .map(|f| (f.clone(), Some(f)))
        .collect();
    // Listed, but never needed: an fp16 twin of a component that has full weights, a
    // component gb-diffusion does not load, a README.
    files.insert(FP16_UNET.into(), None);
    files.insert("safety_checker/model.safetensors".into(), None);
    files.insert("README.md".into(), None);
    RepoSpec { files }
}

/// One request as the server saw it.
#[derive(Clone, Debug)]
struct Seen {
    path: String,
    range: Option<String>,
    auth: Option<String>,
}

struct Server {
    endpoint: String,
    stop: Arc<AtomicBool>,
    log: Arc<Mutex<Vec<Seen>>>,
    handle: Option<JoinHandle<()>>,
}

impl Server {
    fn start(repos: BTreeMap<&'static str, RepoSpec>) -> Self {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        listener.set_nonblocking(true).unwrap();
        let endpoint = format!("http://{}", listener.local_addr().unwrap());
        let stop = Arc::new(AtomicBool::new(false));
        let log = Arc::new(Mutex::new(Vec::new()));
        let (stop2, log2, endpoint2) = (stop.clone(), log.clone(), endpoint.clone());
        let handle = std::thread::spawn(move || {
            let deadline = Instant::now() + LIFETIME;
            let mut served = 0;
            while !stop2.load(Ordering::SeqCst) && Instant::now() < deadline {
                match listener.accept() {
                    Ok((stream, _)) if served < MAX_REQUESTS => {
                        served += 1;
                        serve(stream, &repos, &log2, &endpoint2);
                    }
                    Ok(_) => break,
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                        std::thread::sleep(Duration::from_millis(2));
                    }
                    Err(_) => break,
                }
            }
        });
        Self {
            endpoint,
            stop,
            log,
            handle: Some(handle),
        }
    }

    fn requests(&self) -> Vec<Seen> {
        self.log.lock().unwrap().clone()
    }

    /// The distinct files asked for under `/resolve/`.
    fn resolved_files(&self) -> BTreeSet<String> {
        self.requests()
            .iter()
            .filter_map(|r| r.path.split_once(&format!("/resolve/{COMMIT}/")))
            .map(|(_, file)| file.to_string())
            .collect()
    }
}

impl Drop for Server {
    /// Stops the server and closes its port.
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(handle) = self.handle.take() {
            let _ = handle.join();
        }
    }
}

/// A loopback port with nothing listening on it.
fn closed_port() -> u16 {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    listener.local_addr().unwrap().port()
}

fn respond(stream: &mut TcpStream, status: &str, headers: &[(&str, String)], body: &[u8]) {
    let mut head = format!("HTTP/1.1 {status}\r\nConnection: close\r\n");
    for (k, v) in headers {
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    head.push_str("\r\n");
    // A client may hang up early (a metadata request reads no body): not the server's problem.
    let _ = stream.write_all(head.as_bytes());
    let _ = stream.write_all(body);
}

fn not_found(stream: &mut TcpStream) {
    let headers = [
        ("X-Error-Code", "EntryNotFound".to_string()),
        ("X-Error-Message", "Entry not found".to_string()),
        ("Content-Length", "15".to_string()),
    ];
    respond(stream, "404 Not Found", &headers, b"Entry not found");
}

/// A 64-bit FNV-1a hash of `bytes` seeded with `seed`, as hex.
fn hash(bytes: &[u8], seed: u64) -> String {
    let h = bytes.iter().fold(0xcbf2_9ce4_8422_2325 ^ seed, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    });
    format!("{h:016x}")
}

/// The `X-Linked-Etag` of an LFS file (the blob name hf-hub gives it).
fn lfs_etag(bytes: &[u8]) -> String {
    (1..=4).map(|seed| hash(bytes, seed)).collect()
}

/// `bytes`, whole or the `Range` asked for, with `headers`.
fn serve_bytes(
    stream: &mut TcpStream,
    bytes: &[u8],
    range: Option<&str>,
    mut headers: Vec<(&str, String)>,
) {
    let Some(spec) = range.and_then(|r| r.strip_prefix("bytes=")) else {
        headers.push(("Content-Length", bytes.len().to_string()));
        return respond(stream, "200 OK", &headers, bytes);
    };
    let (start, end) = spec.split_once('-').unwrap();
    let start: usize = start.parse().unwrap();
    let end = match end {
        "" => bytes.len() - 1,
        e => e.parse::<usize>().unwrap().min(bytes.len() - 1),
    };
    if start > end {
        return respond(stream, "416 Range Not Satisfiable", &headers, b"");
    }
    headers.push((
        "Content-Range",
        format!("bytes {start}-{end}/{}", bytes.len()),
    ));
    headers.push(("Content-Length", (end + 1 - start).to_string()));
    respond(stream, "206 Partial Content", &headers, &bytes[start..=end]);
}

fn serve(
    mut stream: TcpStream,
    repos: &BTreeMap<&'static str, RepoSpec>,
    log: &Mutex<Vec<Seen>>,
    endpoint: &str,
) {
    let _ = stream.set_nonblocking(false);
    let _ = stream.set_read_timeout(Some(Duration::from_secs(10)));
    let _ = stream.set_write_timeout(Some(Duration::from_secs(10)));
    let mut reader = BufReader::new(stream.try_clone().unwrap());
    let mut first = String::new();
    if reader.read_line(&mut first).unwrap_or(0) == 0 {
        return;
    }
    let (mut range, mut auth) = (None, None);
    loop {
        let mut line = String::new();
        if reader.read_line(&mut line).unwrap_or(0) == 0 || line.trim().is_empty() {
            break;
        }
        if let Some((k, v)) = line.split_once(':') {
            match k.trim().to_ascii_lowercase().as_str() {
                "range" => range = Some(v.trim().to_string()),
                "authorization" => auth = Some(v.trim().to_string()),
                _ => {}
            }
        }
    }
    let path = first.split(' ').nth(1).unwrap_or("").to_string();
    log.lock().unwrap().push(Seen {
        path: path.clone(),
        range: range.clone(),
        auth,
    });
    let known_rev = |rev: &str| rev == "main" || rev == COMMIT;
    let commit_header = ("X-Repo-Commit", COMMIT.to_string());

    if let Some(rest) = path.strip_prefix("/api/models/") {
        let Some((id, rev)) = rest.split_once("/revision/") else {
            return not_found(&mut stream);
        };
        let Some(repo) = repos.get(id).filter(|_| known_rev(rev)) else {
            return not_found(&mut stream);
        };
        let siblings: Vec<_> = repo
            .files
            .keys()
            .map(|f| serde_json::json!({ "rfilename": f }))
            .collect();
        let json = serde_json::json!({ "id": id, "sha": COMMIT, "siblings": siblings });
        // Chunked, in two chunks.
        let text = json.to_string().into_bytes();
        let (a, b) = text.split_at(text.len() / 2);
        let mut body = Vec::new();
        for part in [a, b] {
            body.extend(format!("{:x}\r\n", part.len()).as_bytes());
            body.extend(part);
            body.extend(b"\r\n");
        }
        body.extend(b"0\r\n\r\n");
        let headers = [
            ("Content-Type", "application/json".to_string()),
            ("Transfer-Encoding", "chunked".to_string()),
        ];
        return respond(&mut stream, "200 OK", &headers, &body);
    }
    // /cdn/{owner}/{name}/{file}, /api/resolve-cache/models/{owner}/{name}/{commit}/{file}
    // or /{owner}/{name}/resolve/{rev}/{file}.
    enum Route {
        Cdn,
        Cache,
        Resolve,
    }
    let (route, rest) = if let Some(r) = path.strip_prefix("/cdn/") {
        (Route::Cdn, r)
    } else if let Some(r) = path.strip_prefix("/api/resolve-cache/models/") {
        (Route::Cache, r)
    } else {
        (Route::Resolve, path.trim_start_matches('/'))
    };
    let parts: Vec<&str> = rest.splitn(3, '/').collect();
    if parts.len() < 3 {
        return not_found(&mut stream);
    }
    let id = format!("{}/{}", parts[0], parts[1]);
    let file = match route {
        Route::Cdn => parts[2].to_string(),
        Route::Cache => match parts[2].split_once('/') {
            Some((rev, file)) if rev == COMMIT => file.to_string(),
            _ => return not_found(&mut stream),
        },
        Route::Resolve => match parts[2]
            .strip_prefix("resolve/")
            .and_then(|t| t.split_once('/'))
        {
            Some((rev, file)) if known_rev(rev) => file.to_string(),
            _ => return not_found(&mut stream),
        },
    };
    let Some(Some(source)) = repos.get(id.as_str()).and_then(|r| r.files.get(&file)) else {
        return not_found(&mut stream);
    };
    let bytes = std::fs::read(pipeline().join(source)).unwrap();
    let range = range.as_deref();
    match route {
        Route::Resolve if file.ends_with(".safetensors") => {
            let headers = [
                ("Location", format!("{endpoint}/cdn/{id}/{file}")),
                ("X-Linked-Etag", format!("\"{}\"", lfs_etag(&bytes))),
                ("X-Linked-Size", bytes.len().to_string()),
                ("ETag", format!("\"{}\"", hash(b"pointer", 0))),
                commit_header,
                ("Content-Length", "0".to_string()),
            ];
            respond(&mut stream, "302 Found", &headers, b"");
        }
        Route::Resolve if file.starts_with("tokenizer/") => {
            let headers = [
                (
                    "Location",
                    format!("/api/resolve-cache/models/{id}/{COMMIT}/{file}"),
                ),
                commit_header,
                ("Content-Length", "0".to_string()),
            ];
            respond(&mut stream, "307 Temporary Redirect", &headers, b"");
        }
        Route::Cdn => serve_bytes(&mut stream, &bytes, range, vec![]),
        Route::Resolve | Route::Cache => {
            let headers = vec![("ETag", format!("\"{}\"", hash(&bytes, 0))), commit_header];
            serve_bytes(&mut stream, &bytes, range, headers);
        }
    }
}

/// Settings as [`HubSettings::from_env`] would read them from `vars`.
fn settings_from(vars: &[(&str, &str)]) -> HubSettings {
    let map: HashMap<String, String> = vars
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    HubSettings::from_vars(|k| map.get(k).cloned(), None)
}

#[test]
fn downloads_a_loadable_pipeline_then_works_offline() {
    let server = Server::start(BTreeMap::from([("owner/tiny-sd", tiny_sd())]));
    let cache = tempfile::tempdir().unwrap();
    let cache_str = cache.path().to_str().unwrap();
    let online = settings_from(&[
        (ENDPOINT_ENV, &server.endpoint),
        (CACHE_ENV, cache_str),
        (TOKEN_ENV, TOKEN),
    ]);
    let dir = resolve("owner/tiny-sd", &online).unwrap();
    let repo_dir = cache.path().join("models--owner--tiny-sd");
    assert_eq!(dir, repo_dir.join("snapshots").join(COMMIT));
    assert_eq!(
        std::fs::read_to_string(repo_dir.join("refs/main")).unwrap(),
        COMMIT
    );
    assert!(!repo_dir.join("refs").join(COMMIT).exists());

    // Every fixture file arrived byte for byte; nothing unneeded was fetched.
    let files = fixture_files();
    for f in &files {
        let got = std::fs::read(dir.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert_eq!(got, std::fs::read(pipeline().join(f)).unwrap(), "{f}");
    }
    let requests = server.requests();
    assert_eq!(
        server.resolved_files(),
        files.iter().cloned().collect::<BTreeSet<_>>(),
        "{requests:#?}"
    );
    assert!(requests[0]
        .path
        .starts_with("/api/models/owner/tiny-sd/revision/main"));
    for skipped in ["fp16", "safety_checker", "README"] {
        assert!(
            !requests.iter().any(|r| r.path.contains(skipped)),
            "{skipped}: {requests:#?}"
        );
    }
    // hf-hub asked for the size with a one-byte range, followed both kinds of redirect, and
    // sent the token everywhere (the CDN is on the same host here).
    assert!(requests
        .iter()
        .any(|r| r.path.starts_with("/cdn/") && r.range.as_deref() == Some("bytes=0-0")));
    assert!(requests
        .iter()
        .any(|r| r.path.starts_with("/api/resolve-cache/")));
    let bearer = format!("Bearer {TOKEN}");
    assert!(
        requests
            .iter()
            .all(|r| r.auth.as_deref() == Some(bearer.as_str())),
        "{requests:#?}"
    );
    #[cfg(unix)]
    {
        let link = std::fs::read_link(dir.join(FULL_UNET)).unwrap();
        assert!(link.starts_with("../../../blobs"), "{}", link.display());
    }
    let blobs: Vec<String> = std::fs::read_dir(repo_dir.join("blobs"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(!blobs.iter().any(|b| b.ends_with(".part")), "{blobs:?}");
    let unet_bytes = std::fs::read(pipeline().join(FULL_UNET)).unwrap();
    assert!(blobs.contains(&lfs_etag(&unet_bytes)), "{blobs:?}");

    // The snapshot is found offline and loads as both priors.
    assert_eq!(resolve_cached("owner/tiny-sd", cache.path()).unwrap(), dir);
    let device = BackendKind::Flex.device();
    let prior =
        SdComponents::load_inpainting(&dir, &device).expect("SdComponents from the download");
    assert_eq!(prior.unet_config.in_channels, 9);
    let sd = SdPrior::load(
        &dir,
        &gb_diffusion::distill::PriorOptions::default(),
        &device,
    )
    .expect("SdPrior from the download");
    let local = SdPrior::load(
        &pipeline(),
        &gb_diffusion::distill::PriorOptions::default(),
        &device,
    )
    .unwrap();
    assert_eq!(sd.resolution, local.resolution);

    // Offline first: resolving again asks nothing; a refresh asks only for the listing.
    let before = server.requests().len();
    assert_eq!(resolve("owner/tiny-sd", &online).unwrap(), dir);
    assert_eq!(server.requests().len(), before);
    assert_eq!(download("owner/tiny-sd", &online).unwrap(), dir);
    let after = server.requests();
    assert_eq!(after.len(), before + 1, "{:#?}", &after[before..]);

    // HF_HUB_OFFLINE=1: the cached snapshot resolves, a missing one is a clear error, and
    // the server (still up) hears nothing.
    let offline = settings_from(&[
        (ENDPOINT_ENV, &server.endpoint),
        (CACHE_ENV, cache_str),
        (OFFLINE_ENV, "1"),
    ]);
    assert!(offline.offline);
    let before = server.requests().len();
    assert_eq!(resolve("owner/tiny-sd", &offline).unwrap(), dir);
    let err = resolve("owner/never-cached", &offline)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("owner/never-cached") && err.contains(OFFLINE_ENV) && !err.contains('\n'),
        "{err}"
    );
    assert_eq!(server.requests().len(), before);

    // Server gone: the cached snapshot still resolves, through download and resolve.
    let endpoint = server.endpoint.clone();
    drop(server);
    let offline = download("owner/tiny-sd", &online).unwrap();
    assert_eq!(offline, dir);
    assert_eq!(resolve("owner/tiny-sd", &online).unwrap(), dir);
    SdPrior::load(
        &offline,
        &gb_diffusion::distill::PriorOptions::default(),
        &device,
    )
    .expect("SdPrior offline");
    let err = download("owner/never-cached", &online)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("owner/never-cached")
            && err.contains("cannot reach")
            && err.contains("not in the hub cache"),
        "{err}"
    );
    let err = resolve("owner/never-cached", &online)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("not in the hub cache")
            && err.contains(&format!("downloading it from {endpoint} failed")),
        "{err}"
    );
}

#[test]
fn an_unreachable_https_hub_is_a_connection_error() {
    let cache = tempfile::tempdir().unwrap();
    let endpoint = format!("https://127.0.0.1:{}", closed_port());
    let settings = HubSettings::with_cache_dir(cache.path()).with_endpoint(&endpoint);
    let err = download("owner/tiny-sd", &settings)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("owner/tiny-sd")
            && err.contains("cannot reach the hub")
            && err.contains("Connection Failed")
            && err.contains(&endpoint),
        "{err}"
    );
    assert!(!err.to_lowercase().contains("scheme"), "{err}");
    let err = resolve("owner/tiny-sd", &settings).unwrap_err().to_string();
    assert!(
        err.contains(&format!("downloading it from {endpoint} failed"))
            && err.contains("Connection Failed"),
        "{err}"
    );
}

#[test]
fn a_missing_file_is_an_error_naming_the_file_and_url() {
    let mut broken = tiny_sd();
    broken.files.insert(FULL_VAE.into(), None);
    let server = Server::start(BTreeMap::from([("owner/broken", broken)]));
    let cache = tempfile::tempdir().unwrap();
    let settings = HubSettings::with_cache_dir(cache.path()).with_endpoint(&server.endpoint);
    let err = download("owner/broken", &settings).unwrap_err().to_string();
    let url = format!(
        "{}/owner/broken/resolve/{COMMIT}/{FULL_VAE}",
        server.endpoint
    );
    assert!(
        err.contains("owner/broken") && err.contains(FULL_VAE),
        "{err}"
    );
    assert!(err.contains(&url), "{err}");
    assert!(
        err.contains("HTTP 404") && err.contains("Entry not found"),
        "{err}"
    );
    // An incomplete snapshot is not published under refs/main, nor taken from the cache.
    let repo_dir = cache.path().join("models--owner--broken");
    assert!(!repo_dir.join("refs/main").exists());
    assert!(resolve_cached("owner/broken", cache.path()).is_err());

    let err = download("owner/absent", &settings).unwrap_err().to_string();
    let api = format!("{}/api/models/owner/absent/revision/main", server.endpoint);
    assert!(err.contains(&api) && err.contains("HTTP 404"), "{err}");
    let err = download("owner/broken@v9", &settings)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("revision/v9") && err.contains("revision `v9`"),
        "{err}"
    );
}

#[test]
fn a_component_with_only_fp16_weights_downloads_them() {
    let mut repo = tiny_sd();
    repo.files.remove(FULL_VAE);
    repo.files.insert(FP16_VAE.into(), Some(FULL_VAE.into()));
    let server = Server::start(BTreeMap::from([("owner/fp16-vae", repo)]));
    let cache = tempfile::tempdir().unwrap();
    let settings = HubSettings::with_cache_dir(cache.path()).with_endpoint(&server.endpoint);
    let dir = download("owner/fp16-vae@main", &settings).unwrap();
    let fetched = server.resolved_files();
    assert!(fetched.contains(FP16_VAE), "{fetched:?}");
    assert!(!fetched.contains(FP16_UNET), "{fetched:?}");
    assert!(!dir.join(FULL_VAE).exists());
    assert_eq!(
        std::fs::read(dir.join(FP16_VAE)).unwrap(),
        std::fs::read(pipeline().join(FULL_VAE)).unwrap()
    );
    // The folder loader picks the `.fp16` file when it is the only one.
    let device = BackendKind::Flex.device();
    SdComponents::load_inpainting(&dir, &device).expect("prior with an fp16-named VAE");
}

#[test]
fn a_pickled_only_repository_is_refused_with_advice() {
    let mut repo = tiny_sd();
    repo.files.remove(FULL_UNET);
    repo.files.remove(FP16_UNET);
    repo.files.insert(
        "unet/diffusion_pytorch_model.bin".into(),
        Some(FULL_UNET.into()),
    );
    let server = Server::start(BTreeMap::from([("owner/pickled", repo)]));
    let cache = tempfile::tempdir().unwrap();
    let settings = HubSettings::with_cache_dir(cache.path()).with_endpoint(&server.endpoint);
    let err = resolve("owner/pickled", &settings).unwrap_err().to_string();
    assert!(
        err.contains("owner/pickled")
            && err.contains("`unet`")
            && err.contains("pickled")
            && err.contains("safetensors")
            && !err.contains('\n'),
        "{err}"
    );
    // Only the index was fetched: the pickled file never.
    let fetched = server.resolved_files();
    assert_eq!(
        fetched,
        BTreeSet::from(["model_index.json".to_string()]),
        "{fetched:?}"
    );
}
