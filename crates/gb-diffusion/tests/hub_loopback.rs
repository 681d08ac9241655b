//! Hub download (`checkpoint::hub::download`) against a loopback HTTP server that serves the
//! committed tiny pipeline (`fixtures/sd_image/pipeline`) under the hub's URL scheme:
//! `GET /api/models/{id}/revision/{rev}` (JSON: `sha`, `siblings[].rfilename`) and
//! `GET /{id}/resolve/{rev}/{file}`. The server answers the way the real hub and its CDN
//! vary: chunked JSON, weights behind a relative 302 redirect with an `ETag`, configs with a
//! weak `ETag` and `Content-Length`, tokenizer files with neither (body read to close).

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use gb_core::BackendKind;
use gb_diffusion::checkpoint::hub::{download, resolve, resolve_cached};
use gb_diffusion::distill::sd_adapter::SdPrior;
use gb_diffusion::inpaint::InpaintPrior;

const COMMIT: &str = "0123456789abcdef0123456789abcdef01234567";
const FULL_VAE: &str = "vae/diffusion_pytorch_model.safetensors";
const FP16_VAE: &str = "vae/diffusion_pytorch_model.fp16.safetensors";
const FP16_UNET: &str = "unet/diffusion_pytorch_model.fp16.safetensors";

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

struct Server {
    endpoint: String,
    stop: Arc<AtomicBool>,
    log: Arc<Mutex<Vec<String>>>,
    handle: Option<JoinHandle<()>>,
}

impl Server {
    fn start(repos: BTreeMap<&'static str, RepoSpec>) -> Self {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let endpoint = format!("http://{}", listener.local_addr().unwrap());
        let stop = Arc::new(AtomicBool::new(false));
        let log = Arc::new(Mutex::new(Vec::new()));
        let (stop2, log2) = (stop.clone(), log.clone());
        let handle = std::thread::spawn(move || {
            for stream in listener.incoming() {
                if stop2.load(Ordering::SeqCst) {
                    break;
                }
                if let Ok(stream) = stream {
                    serve(stream, &repos, &log2);
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

    fn requests(&self) -> Vec<String> {
        self.log.lock().unwrap().clone()
    }

    /// Stops the server and closes its port.
    fn shutdown(mut self) {
        self.stop.store(true, Ordering::SeqCst);
        let _ = TcpStream::connect(self.endpoint.trim_start_matches("http://"));
        self.handle.take().unwrap().join().unwrap();
    }
}

fn respond(stream: &mut TcpStream, status: &str, headers: &[(&str, String)], body: &[u8]) {
    let mut head = format!("HTTP/1.1 {status}\r\nConnection: close\r\n");
    for (k, v) in headers {
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    head.push_str("\r\n");
    // A client may hang up early (it already has the blob): not the server's problem.
    let _ = stream.write_all(head.as_bytes());
    let _ = stream.write_all(body);
}

fn serve(
    mut stream: TcpStream,
    repos: &BTreeMap<&'static str, RepoSpec>,
    log: &Mutex<Vec<String>>,
) {
    let mut reader = BufReader::new(stream.try_clone().unwrap());
    let mut first = String::new();
    reader.read_line(&mut first).unwrap();
    loop {
        let mut line = String::new();
        if reader.read_line(&mut line).unwrap() == 0 || line.trim().is_empty() {
            break;
        }
    }
    let path = first.split(' ').nth(1).unwrap_or("").to_string();
    log.lock().unwrap().push(path.clone());
    let not_found = |s: &mut TcpStream| respond(s, "404 Not Found", &[], b"Entry not found");

    if let Some(rest) = path.strip_prefix("/api/models/") {
        let Some((id, rev)) = rest.split_once("/revision/") else {
            return not_found(&mut stream);
        };
        let Some(repo) = repos.get(id).filter(|_| rev == "main" || rev == COMMIT) else {
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
    // /{owner}/{name}/resolve/{rev}/{file} or /cdn/{owner}/{name}/{file}
    let (cdn, rest) = match path.strip_prefix("/cdn/") {
        Some(rest) => (true, rest.to_string()),
        None => (false, path.trim_start_matches('/').to_string()),
    };
    let parts: Vec<&str> = rest.splitn(3, '/').collect();
    if parts.len() < 3 {
        return not_found(&mut stream);
    }
    let id = format!("{}/{}", parts[0], parts[1]);
    let file = if cdn {
        parts[2].to_string()
    } else {
        let Some(tail) = parts[2].strip_prefix("resolve/") else {
            return not_found(&mut stream);
        };
        let Some((rev, file)) = tail.split_once('/') else {
            return not_found(&mut stream);
        };
        if rev != "main" && rev != COMMIT {
            return not_found(&mut stream);
        }
        file.to_string()
    };
    let Some(Some(source)) = repos.get(id.as_str()).and_then(|r| r.files.get(&file)) else {
        return not_found(&mut stream);
    };
    let bytes = std::fs::read(pipeline().join(source)).unwrap();
    if file.ends_with(".safetensors") && !cdn {
        let headers = [
            ("Location", format!("/cdn/{id}/{file}")),
            ("Content-Length", "0".to_string()),
        ];
        return respond(&mut stream, "302 Found", &headers, b"");
    }
    let mut headers = vec![];
    let tag: u64 = bytes
        .iter()
        .fold(7u64, |h, &b| h.wrapping_mul(31) ^ u64::from(b));
    if cdn {
        headers.push(("ETag", format!("\"{tag:016x}{:08x}\"", bytes.len())));
        headers.push(("Content-Length", bytes.len().to_string()));
    } else if file.starts_with("tokenizer/") {
        // Neither ETag nor Content-Length: the body ends when the connection closes.
    } else {
        headers.push(("ETag", format!("W/\"cfg-{tag:016x}\"")));
        headers.push(("Content-Length", bytes.len().to_string()));
    }
    respond(&mut stream, "200 OK", &headers, &bytes);
}

#[test]
fn downloads_a_loadable_pipeline_then_works_offline() {
    let server = Server::start(BTreeMap::from([("owner/tiny-sd", tiny_sd())]));
    let cache = tempfile::tempdir().unwrap();
    let dir = download("owner/tiny-sd", Some(&server.endpoint), Some(cache.path())).unwrap();
    let repo_dir = cache.path().join("models--owner--tiny-sd");
    assert_eq!(dir, repo_dir.join("snapshots").join(COMMIT));
    assert_eq!(
        std::fs::read_to_string(repo_dir.join("refs/main")).unwrap(),
        COMMIT
    );

    // Every fixture file arrived byte for byte; nothing unneeded was fetched.
    let files = fixture_files();
    for f in &files {
        let got = std::fs::read(dir.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert_eq!(got, std::fs::read(pipeline().join(f)).unwrap(), "{f}");
    }
    let requests = server.requests();
    let resolves = requests.iter().filter(|r| r.contains("/resolve/")).count();
    assert_eq!(resolves, files.len(), "{requests:#?}");
    assert!(requests[0].starts_with("/api/models/owner/tiny-sd/revision/main"));
    for skipped in ["fp16", "safety_checker", "README"] {
        assert!(
            !requests.iter().any(|r| r.contains(skipped)),
            "{skipped}: {requests:#?}"
        );
    }
    #[cfg(unix)]
    {
        let unet = dir.join("unet/diffusion_pytorch_model.safetensors");
        let link = std::fs::read_link(&unet).unwrap();
        assert!(link.starts_with("../../../blobs"), "{}", link.display());
    }
    let blobs: Vec<String> = std::fs::read_dir(repo_dir.join("blobs"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        !blobs.iter().any(|b| b.ends_with(".incomplete")),
        "{blobs:?}"
    );
    assert!(blobs.iter().any(|b| b.starts_with("fnv1a64-")), "{blobs:?}");
    assert!(blobs.iter().any(|b| b.starts_with("cfg-")), "{blobs:?}");

    // The snapshot is found offline and loads as both priors.
    assert_eq!(
        resolve_cached("owner/tiny-sd", Some(cache.path())).unwrap(),
        dir
    );
    let device = BackendKind::Flex.device();
    let prior = InpaintPrior::load(&dir, &device).expect("InpaintPrior from the download");
    assert_eq!(prior.unet_config.in_channels, 9);
    let sd = SdPrior::load(&dir, &device).expect("SdPrior from the download");
    let local = SdPrior::load(&pipeline(), &device).unwrap();
    assert_eq!(sd.resolution, local.resolution);

    // A second download re-uses the cached files (only the listing is asked for).
    let before = server.requests().len();
    let again = download("owner/tiny-sd", Some(&server.endpoint), Some(cache.path())).unwrap();
    assert_eq!(again, dir);
    let after = server.requests();
    assert_eq!(after.len(), before + 1, "{:#?}", &after[before..]);

    // Server gone: the cached snapshot still resolves, through download and resolve.
    let endpoint = server.endpoint.clone();
    server.shutdown();
    let offline = download("owner/tiny-sd", Some(&endpoint), Some(cache.path())).unwrap();
    assert_eq!(offline, dir);
    assert_eq!(
        resolve("owner/tiny-sd", Some(&endpoint), Some(cache.path())).unwrap(),
        dir
    );
    SdPrior::load(&offline, &device).expect("SdPrior offline");
    let err = download("owner/never-cached", Some(&endpoint), Some(cache.path()))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("owner/never-cached")
            && err.contains("cannot connect")
            && err.contains("not cached"),
        "{err}"
    );
    let err = resolve("owner/never-cached", Some(&endpoint), Some(cache.path()))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("not in the hf-hub cache") && err.contains("downloading it failed"),
        "{err}"
    );
}

#[test]
fn a_missing_file_is_an_error_naming_the_file_and_url() {
    let mut broken = tiny_sd();
    broken.files.insert(FULL_VAE.into(), None);
    let server = Server::start(BTreeMap::from([("owner/broken", broken)]));
    let cache = tempfile::tempdir().unwrap();
    let err = download("owner/broken", Some(&server.endpoint), Some(cache.path()))
        .unwrap_err()
        .to_string();
    let url = format!(
        "{}/owner/broken/resolve/{COMMIT}/{FULL_VAE}",
        server.endpoint
    );
    assert!(err.contains(FULL_VAE), "{err}");
    assert!(err.contains(&url), "{err}");
    assert!(err.contains("404"), "{err}");
    // An incomplete snapshot is not published under refs/main.
    assert!(resolve_cached("owner/broken", Some(cache.path())).is_err());

    let err = download("owner/absent", Some(&server.endpoint), Some(cache.path()))
        .unwrap_err()
        .to_string();
    let api = format!("{}/api/models/owner/absent/revision/main", server.endpoint);
    assert!(err.contains(&api) && err.contains("404"), "{err}");
    let err = download(
        "owner/broken@v9",
        Some(&server.endpoint),
        Some(cache.path()),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("revision/v9") && err.contains("v9"), "{err}");
    server.shutdown();
}

#[test]
fn a_component_with_only_fp16_weights_downloads_them() {
    let mut repo = tiny_sd();
    repo.files.remove(FULL_VAE);
    repo.files.insert(FP16_VAE.into(), Some(FULL_VAE.into()));
    let server = Server::start(BTreeMap::from([("owner/fp16-vae", repo)]));
    let cache = tempfile::tempdir().unwrap();
    let dir = download(
        "owner/fp16-vae@main",
        Some(&server.endpoint),
        Some(cache.path()),
    )
    .unwrap();
    let requests = server.requests();
    assert!(
        requests.iter().any(|r| r.ends_with(FP16_VAE)),
        "{requests:#?}"
    );
    assert!(
        !requests.iter().any(|r| r.ends_with(FP16_UNET)),
        "{requests:#?}"
    );
    assert!(!dir.join(FULL_VAE).exists());
    assert_eq!(
        std::fs::read(dir.join(FP16_VAE)).unwrap(),
        std::fs::read(pipeline().join(FULL_VAE)).unwrap()
    );
    // The folder loader picks the `.fp16` file when it is the only one.
    let device = BackendKind::Flex.device();
    InpaintPrior::load(&dir, &device).expect("prior with an fp16-named VAE");
    server.shutdown();
}
