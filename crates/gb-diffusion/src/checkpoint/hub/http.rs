//! A minimal blocking HTTP/1.1 client over `std::net::TcpStream`, for plain `http://`
//! endpoints only (a local mirror, a loopback test server).
//!
//! Why not hf-hub's own client: the workspace builds `hf-hub` with
//! `default-features = false` (no `ureq`, no TLS), so its sync `api` module does not exist,
//! and turning the feature on would pull a TLS stack into every build. This client does the
//! little a snapshot download needs: `GET`, redirects (relative or `http://`), `Content-Length`,
//! `Transfer-Encoding: chunked` or read-to-close bodies, streamed so that multi-GB weights
//! never sit in memory.

use std::io::{BufRead, BufReader, Read};
use std::net::{TcpStream, ToSocketAddrs};
use std::time::Duration;

/// How long to wait for a connection, and for each read or write.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(30);
const IO_TIMEOUT: Duration = Duration::from_secs(120);
/// Redirects followed before giving up.
const MAX_REDIRECTS: usize = 5;
/// Longest status or header line accepted.
const MAX_LINE: usize = 16 * 1024;

/// Why a request failed.
#[derive(Debug)]
pub(crate) enum HttpError {
    /// The server could not be reached (refused, unreachable, name not resolved): the
    /// caller may fall back to the offline cache.
    Connect(String),
    /// The server answered with a non-2xx status.
    Status {
        /// The status code.
        code: u16,
        /// The reason phrase.
        reason: String,
        /// The URL that answered it (after redirects).
        url: String,
    },
    /// Anything else: a malformed URL or response, an unsupported scheme, a truncated body.
    Other(String),
}

impl std::fmt::Display for HttpError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Connect(m) | Self::Other(m) => f.write_str(m),
            Self::Status { code, reason, url } => write!(f, "GET {url}: HTTP {code} {reason}"),
        }
    }
}

/// A parsed `http://host[:port]/path?query` URL.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct HttpUrl {
    /// Host name or address (IPv6 without brackets).
    pub host: String,
    /// Port (80 when absent).
    pub port: u16,
    /// Path and query, starting with `/`.
    pub path: String,
}

impl HttpUrl {
    /// Parses `url`; anything but `http://` is an error that says so.
    pub fn parse(url: &str) -> Result<Self, HttpError> {
        let Some(rest) = url.strip_prefix("http://") else {
            let scheme = url.split("://").next().unwrap_or(url);
            return Err(HttpError::Other(format!(
                "{url}: the built-in downloader speaks plain http:// only, not `{scheme}` \
                 (hf-hub is built without its TLS client to keep the build small); download \
                 the repository with `huggingface-cli download <id>` into the cache instead, \
                 or point HF_ENDPOINT at an http:// mirror"
            )));
        };
        let (authority, path) = match rest.find('/') {
            Some(i) => (&rest[..i], &rest[i..]),
            None => (rest, "/"),
        };
        let authority = authority.rsplit('@').next().unwrap_or(authority);
        let (host, port) = if let Some(v6) = authority.strip_prefix('[') {
            let (h, tail) = v6
                .split_once(']')
                .ok_or_else(|| HttpError::Other(format!("{url}: malformed IPv6 host")))?;
            (h.to_string(), tail.strip_prefix(':'))
        } else {
            match authority.rsplit_once(':') {
                Some((h, p)) => (h.to_string(), Some(p)),
                None => (authority.to_string(), None),
            }
        };
        let port = match port {
            Some(p) => p
                .parse()
                .map_err(|_| HttpError::Other(format!("{url}: invalid port `{p}`")))?,
            None => 80,
        };
        if host.is_empty() {
            return Err(HttpError::Other(format!("{url}: no host")));
        }
        Ok(Self {
            host,
            port,
            path: path.to_string(),
        })
    }

    /// The URL as text.
    pub fn to_url(&self) -> String {
        let host = if self.host.contains(':') {
            format!("[{}]", self.host)
        } else {
            self.host.clone()
        };
        if self.port == 80 {
            format!("http://{host}{}", self.path)
        } else {
            format!("http://{host}:{}{}", self.port, self.path)
        }
    }

    /// The `Location` of a redirect, resolved against this URL.
    fn join(&self, location: &str) -> Result<Self, HttpError> {
        if location.contains("://") {
            return Self::parse(location);
        }
        let path = if location.starts_with('/') {
            location.to_string()
        } else {
            let base = self.path.split('?').next().unwrap_or("/");
            let dir = &base[..base.rfind('/').map_or(0, |i| i + 1)];
            format!("{dir}{location}")
        };
        Ok(Self {
            path,
            ..self.clone()
        })
    }
}

/// A response whose body has not been read yet.
pub(crate) struct Response {
    /// The final URL (after redirects).
    pub url: String,
    /// Header names (lower-case) and values.
    headers: Vec<(String, String)>,
    /// The body, already de-chunked and bounded by `Content-Length`.
    body: Box<dyn Read>,
    /// `Content-Length`, when the server sent one.
    pub content_length: Option<u64>,
}

impl Response {
    /// The first header called `name` (case-insensitive).
    pub fn header(&self, name: &str) -> Option<&str> {
        let name = name.to_ascii_lowercase();
        self.headers
            .iter()
            .find(|(k, _)| *k == name)
            .map(|(_, v)| v.as_str())
    }

    /// Copies the body into `out`, checking that a declared `Content-Length` was met.
    pub fn copy_to(mut self, out: &mut dyn std::io::Write) -> Result<u64, HttpError> {
        let n = std::io::copy(&mut self.body, out)
            .map_err(|e| HttpError::Other(format!("GET {}: reading the body: {e}", self.url)))?;
        if let Some(len) = self.content_length {
            if n != len {
                return Err(HttpError::Other(format!(
                    "GET {}: body truncated ({n} of {len} bytes)",
                    self.url
                )));
            }
        }
        Ok(n)
    }

    /// The whole body as text (for small JSON answers).
    pub fn text(self) -> Result<String, HttpError> {
        let url = self.url.clone();
        let mut buf = Vec::new();
        self.copy_to(&mut buf)?;
        String::from_utf8(buf)
            .map_err(|_| HttpError::Other(format!("GET {url}: body is not UTF-8")))
    }
}

/// `GET url`, following redirects; a non-2xx answer is [`HttpError::Status`].
pub(crate) fn get(url: &str, token: Option<&str>) -> Result<Response, HttpError> {
    let mut target = HttpUrl::parse(url)?;
    for _ in 0..=MAX_REDIRECTS {
        let (code, reason, headers, reader) = send(&target, token)?;
        let find = |name: &str| {
            headers
                .iter()
                .find(|(k, _)| k == name)
                .map(|(_, v)| v.clone())
        };
        if matches!(code, 301 | 302 | 303 | 307 | 308) {
            let location = find("location").ok_or_else(|| {
                HttpError::Other(format!(
                    "GET {}: HTTP {code} without a Location header",
                    target.to_url()
                ))
            })?;
            target = target.join(&location)?;
            continue;
        }
        if !(200..300).contains(&code) {
            return Err(HttpError::Status {
                code,
                reason,
                url: target.to_url(),
            });
        }
        let chunked =
            find("transfer-encoding").is_some_and(|v| v.to_ascii_lowercase().contains("chunked"));
        let content_length = if chunked {
            None
        } else {
            find("content-length")
                .map(|v| {
                    v.trim().parse::<u64>().map_err(|_| {
                        HttpError::Other(format!(
                            "GET {}: invalid Content-Length `{v}`",
                            target.to_url()
                        ))
                    })
                })
                .transpose()?
        };
        let body: Box<dyn Read> = if chunked {
            Box::new(Chunked {
                inner: reader,
                left: 0,
                done: false,
            })
        } else if let Some(len) = content_length {
            Box::new(reader.take(len))
        } else {
            Box::new(reader)
        };
        return Ok(Response {
            url: target.to_url(),
            headers,
            body,
            content_length,
        });
    }
    Err(HttpError::Other(format!(
        "GET {url}: more than {MAX_REDIRECTS} redirects"
    )))
}

type Head = (u16, String, Vec<(String, String)>, BufReader<TcpStream>);

/// Sends one request and reads the status line and headers.
fn send(url: &HttpUrl, token: Option<&str>) -> Result<Head, HttpError> {
    let shown = url.to_url();
    let addrs = (url.host.as_str(), url.port)
        .to_socket_addrs()
        .map_err(|e| HttpError::Connect(format!("GET {shown}: cannot resolve the host: {e}")))?;
    let mut last = None;
    let mut stream = None;
    for addr in addrs {
        match TcpStream::connect_timeout(&addr, CONNECT_TIMEOUT) {
            Ok(s) => {
                stream = Some(s);
                break;
            }
            Err(e) => last = Some(e),
        }
    }
    let stream = stream.ok_or_else(|| {
        HttpError::Connect(format!(
            "GET {shown}: cannot connect: {}",
            last.map_or_else(|| "no address".to_string(), |e| e.to_string())
        ))
    })?;
    let io = |e: std::io::Error| HttpError::Other(format!("GET {shown}: {e}"));
    stream.set_read_timeout(Some(IO_TIMEOUT)).map_err(io)?;
    stream.set_write_timeout(Some(IO_TIMEOUT)).map_err(io)?;
    let host = if url.host.contains(':') {
        format!("[{}]", url.host)
    } else {
        url.host.clone()
    };
    let host = if url.port == 80 {
        host
    } else {
        format!("{host}:{}", url.port)
    };
    let mut request = format!(
        "GET {} HTTP/1.1\r\nHost: {host}\r\nUser-Agent: gb-nerf-rs/{} (hf-hub cache layout)\r\n\
         Accept: */*\r\nAccept-Encoding: identity\r\nConnection: close\r\n",
        url.path,
        env!("CARGO_PKG_VERSION")
    );
    if let Some(t) = token {
        request.push_str(&format!("Authorization: Bearer {t}\r\n"));
    }
    request.push_str("\r\n");
    use std::io::Write;
    (&stream).write_all(request.as_bytes()).map_err(io)?;
    let mut reader = BufReader::new(stream);
    let status = read_line(&mut reader).map_err(io)?;
    let mut parts = status.splitn(3, ' ');
    let version = parts.next().unwrap_or("");
    let code = parts.next().and_then(|c| c.parse::<u16>().ok());
    let (true, Some(code)) = (version.starts_with("HTTP/1."), code) else {
        return Err(HttpError::Other(format!(
            "GET {shown}: not an HTTP/1.x status line: `{status}`"
        )));
    };
    let reason = parts.next().unwrap_or("").to_string();
    let mut headers = Vec::new();
    loop {
        let line = read_line(&mut reader).map_err(io)?;
        if line.is_empty() {
            break;
        }
        if let Some((k, v)) = line.split_once(':') {
            headers.push((k.trim().to_ascii_lowercase(), v.trim().to_string()));
        }
    }
    Ok((code, reason, headers, reader))
}

/// One CRLF- (or LF-) terminated line, without the terminator.
fn read_line(reader: &mut impl BufRead) -> std::io::Result<String> {
    let mut buf = Vec::new();
    let n = (&mut *reader)
        .take(MAX_LINE as u64)
        .read_until(b'\n', &mut buf)?;
    if n == 0 {
        return Err(std::io::Error::new(
            std::io::ErrorKind::UnexpectedEof,
            "connection closed before the response head ended",
        ));
    }
    if buf.last() != Some(&b'\n') {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            "response line too long",
        ));
    }
    while matches!(buf.last(), Some(b'\n' | b'\r')) {
        buf.pop();
    }
    String::from_utf8(buf)
        .map_err(|_| std::io::Error::new(std::io::ErrorKind::InvalidData, "non-UTF-8 header"))
}

/// `Transfer-Encoding: chunked` body decoder.
struct Chunked<R> {
    inner: R,
    left: u64,
    done: bool,
}

impl<R: BufRead> Read for Chunked<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.done || buf.is_empty() {
            return Ok(0);
        }
        if self.left == 0 {
            let line = read_line(&mut self.inner)?;
            let size = line.split(';').next().unwrap_or("").trim();
            self.left = u64::from_str_radix(size, 16).map_err(|_| {
                std::io::Error::new(
                    std::io::ErrorKind::InvalidData,
                    format!("invalid chunk size `{size}`"),
                )
            })?;
            if self.left == 0 {
                // Trailers, then the final empty line.
                while !read_line(&mut self.inner)?.is_empty() {}
                self.done = true;
                return Ok(0);
            }
        }
        let want = buf
            .len()
            .min(usize::try_from(self.left).unwrap_or(usize::MAX));
        let n = self.inner.read(&mut buf[..want])?;
        if n == 0 {
            return Err(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                "connection closed inside a chunk",
            ));
        }
        self.left -= n as u64;
        if self.left == 0 {
            let end = read_line(&mut self.inner)?;
            if !end.is_empty() {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::InvalidData,
                    "chunk not followed by CRLF",
                ));
            }
        }
        Ok(n)
    }
}

/// Percent-encodes `s` for a URL path; `/` is kept when `keep_slash`.
pub(crate) fn encode(s: &str, keep_slash: bool) -> String {
    let mut out = String::with_capacity(s.len());
    for b in s.bytes() {
        match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'.' | b'_' | b'~' => {
                out.push(b as char)
            }
            b'/' if keep_slash => out.push('/'),
            _ => out.push_str(&format!("%{b:02X}")),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_urls_and_redirect_targets() {
        let u = HttpUrl::parse("http://127.0.0.1:8080/hf").unwrap();
        assert_eq!(
            (u.host.as_str(), u.port, u.path.as_str()),
            ("127.0.0.1", 8080, "/hf")
        );
        let u = HttpUrl::parse("http://mirror.local").unwrap();
        assert_eq!((u.port, u.path.as_str()), (80, "/"));
        let u = HttpUrl::parse("http://[::1]:9/a/b?x=1").unwrap();
        assert_eq!((u.host.as_str(), u.port), ("::1", 9));
        assert_eq!(u.to_url(), "http://[::1]:9/a/b?x=1");
        assert_eq!(u.join("/cdn/f").unwrap().path, "/cdn/f");
        assert_eq!(u.join("c").unwrap().path, "/a/c");
        let err = HttpUrl::parse("https://huggingface.co")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("https") && err.contains("huggingface-cli"),
            "{err}"
        );
        assert!(HttpUrl::parse("http://h:port/").is_err());
        assert_eq!(encode("a b/ü@x", true), "a%20b/%C3%BC%40x");
        assert_eq!(encode("refs/pr/1", false), "refs%2Fpr%2F1");
    }

    #[test]
    fn decodes_chunked_bodies() {
        let raw = b"4\r\nWiki\r\n5;ext=1\r\npedia\r\n0\r\nX-Trailer: 1\r\n\r\n";
        let mut body = String::new();
        Chunked {
            inner: &raw[..],
            left: 0,
            done: false,
        }
        .read_to_string(&mut body)
        .unwrap();
        assert_eq!(body, "Wikipedia");
        let bad = b"4\r\nWi";
        let mut out = Vec::new();
        let err = Chunked {
            inner: &bad[..],
            left: 0,
            done: false,
        }
        .read_to_end(&mut out)
        .unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::UnexpectedEof);
    }
}
