//! [`HubSettings`]: the hub endpoint, cache, token and offline switch, read from the
//! environment once (the variables `huggingface_hub` reads) or built directly.
//!
//! `hf-hub` 0.4.3 itself reads only `HF_HOME` and `HF_ENDPOINT` (`ApiBuilder::from_env`); this
//! module reads every variable explicitly and hands the result to `ApiBuilder::from_cache`,
//! so that nothing else depends on the process environment.

use std::path::{Path, PathBuf};

/// The hub used when `HF_ENDPOINT` is not set.
pub const DEFAULT_ENDPOINT: &str = "https://huggingface.co";

/// The hub URL (as in `huggingface_hub`).
pub const ENDPOINT_ENV: &str = "HF_ENDPOINT";
/// The cache root holding `models--owner--name` folders.
pub const CACHE_ENV: &str = "HF_HUB_CACHE";
/// The Hugging Face home (`$HF_HOME/hub` is the default cache, `$HF_HOME/token` the token).
pub const HOME_ENV: &str = "HF_HOME";
/// An access token for gated or private repositories.
pub const TOKEN_ENV: &str = "HF_TOKEN";
/// `1`/`true`/`yes`/`on`: never touch the network.
pub const OFFLINE_ENV: &str = "HF_HUB_OFFLINE";

/// Where and how hub ids are resolved and downloaded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HubSettings {
    /// The hub URL, without a trailing `/`.
    pub endpoint: String,
    /// The cache root (`models--owner--name/{blobs,refs,snapshots}` live under it).
    pub cache_dir: PathBuf,
    /// A bearer token sent with every request.
    pub token: Option<String>,
    /// No network at all: only snapshots already in the cache resolve.
    pub offline: bool,
    /// A progress bar per downloaded file (on a terminal).
    pub progress: bool,
}

impl HubSettings {
    /// Settings for the cache at `cache_dir`: the default endpoint, no token, online, no
    /// progress bars (tests and programs that choose everything themselves).
    pub fn with_cache_dir(cache_dir: impl Into<PathBuf>) -> Self {
        Self {
            endpoint: DEFAULT_ENDPOINT.to_string(),
            cache_dir: cache_dir.into(),
            token: None,
            offline: false,
            progress: false,
        }
    }

    /// These settings with `endpoint` (trimmed, without a trailing `/`; empty keeps the
    /// current one).
    pub fn with_endpoint(mut self, endpoint: &str) -> Self {
        if let Some(e) = clean_endpoint(endpoint) {
            self.endpoint = e;
        }
        self
    }

    /// Reads the process environment: `HF_ENDPOINT` (default <https://huggingface.co>),
    /// `HF_HUB_CACHE` (default `$HF_HOME/hub`, `HF_HOME` defaulting to
    /// `~/.cache/huggingface`), `HF_TOKEN` (default: the file `$HF_HOME/token` that
    /// `huggingface-cli login` writes) and `HF_HUB_OFFLINE`. Progress bars are on when
    /// stderr is a terminal.
    pub fn from_env() -> Self {
        use std::io::IsTerminal;
        let mut settings = Self::from_vars(|name| std::env::var(name).ok(), std::env::home_dir());
        settings.progress = std::io::stderr().is_terminal();
        settings
    }

    /// [`Self::from_env`] with the variables looked up through `var` and the user's home
    /// folder given (no progress bars).
    pub fn from_vars(var: impl Fn(&str) -> Option<String>, home: Option<PathBuf>) -> Self {
        let set = |name: &str| var(name).filter(|v| !v.trim().is_empty());
        let hf_home = set(HOME_ENV)
            .map(PathBuf::from)
            .unwrap_or_else(|| home.unwrap_or_default().join(".cache").join("huggingface"));
        let cache_dir = set(CACHE_ENV)
            .map(PathBuf::from)
            .unwrap_or_else(|| hf_home.join("hub"));
        let token = set(TOKEN_ENV)
            .map(|t| t.trim().to_string())
            .or_else(|| read_token_file(&hf_home.join("token")));
        Self {
            endpoint: set(ENDPOINT_ENV)
                .and_then(|e| clean_endpoint(&e))
                .unwrap_or_else(|| DEFAULT_ENDPOINT.to_string()),
            cache_dir,
            token,
            offline: set(OFFLINE_ENV).is_some_and(|v| is_truthy(&v)),
            progress: false,
        }
    }
}

/// `endpoint` trimmed and without trailing `/`; `None` when empty.
fn clean_endpoint(endpoint: &str) -> Option<String> {
    let e = endpoint.trim().trim_end_matches('/');
    (!e.is_empty()).then(|| e.to_string())
}

/// The values `huggingface_hub` takes as true for its boolean variables.
fn is_truthy(value: &str) -> bool {
    matches!(
        value.trim().to_ascii_uppercase().as_str(),
        "1" | "ON" | "YES" | "TRUE"
    )
}

/// The token stored by `huggingface-cli login`, when the file exists and is not empty.
fn read_token_file(path: &Path) -> Option<String> {
    let text = std::fs::read_to_string(path).ok()?;
    let token = text.trim();
    (!token.is_empty()).then(|| token.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn settings(vars: &[(&str, &str)], home: &Path) -> HubSettings {
        let map: HashMap<String, String> = vars
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        HubSettings::from_vars(|k| map.get(k).cloned(), Some(home.to_path_buf()))
    }

    #[test]
    fn defaults_follow_huggingface_hub() {
        let home = tempfile::tempdir().unwrap();
        let s = settings(&[], home.path());
        assert_eq!(s.endpoint, DEFAULT_ENDPOINT);
        assert_eq!(s.cache_dir, home.path().join(".cache/huggingface/hub"));
        assert_eq!(s.token, None);
        assert!(!s.offline);

        // `huggingface-cli login` writes $HF_HOME/token.
        let hf_home = home.path().join(".cache/huggingface");
        std::fs::create_dir_all(&hf_home).unwrap();
        std::fs::write(hf_home.join("token"), "hf_from_file\n").unwrap();
        assert_eq!(
            settings(&[], home.path()).token.as_deref(),
            Some("hf_from_file")
        );
        assert_eq!(
            settings(&[(TOKEN_ENV, "hf_env")], home.path())
                .token
                .as_deref(),
            Some("hf_env")
        );
    }

    #[test]
    fn every_variable_is_honoured() {
        let home = tempfile::tempdir().unwrap();
        let other = home.path().join("elsewhere");
        let s = settings(
            &[
                (ENDPOINT_ENV, " http://127.0.0.1:8080/ "),
                (HOME_ENV, other.to_str().unwrap()),
                (OFFLINE_ENV, "1"),
            ],
            home.path(),
        );
        assert_eq!(s.endpoint, "http://127.0.0.1:8080");
        assert_eq!(s.cache_dir, other.join("hub"));
        assert!(s.offline);
        let s = settings(
            &[(CACHE_ENV, "/tmp/hub-cache"), (HOME_ENV, "/tmp/hf-home")],
            home.path(),
        );
        assert_eq!(s.cache_dir, PathBuf::from("/tmp/hub-cache"));
        for (value, offline) in [("true", true), ("YES", true), ("on", true), ("0", false)] {
            assert_eq!(
                settings(&[(OFFLINE_ENV, value)], home.path()).offline,
                offline,
                "{value}"
            );
        }
        let s = HubSettings::with_cache_dir("/c").with_endpoint("https://mirror.example/");
        assert_eq!(s.endpoint, "https://mirror.example");
        assert_eq!(s.clone().with_endpoint("  ").endpoint, s.endpoint);
    }
}
