//! A safetensors file's layout, checked from its header alone before its tensors are read:
//! every tensor's data must lie inside the file, so that a truncated download is an error
//! naming the file and the first tensor it cuts, rather than a parser's generic message.
//!
//! Layout: 8 bytes little-endian `n`, `n` bytes of JSON header (`{"NAME": {"dtype": ...,
//! "shape": [...], "data_offsets": [begin, end]}, "__metadata__": {...}}`), then the data,
//! whose offsets count from the end of the header.

use std::io::Read;
use std::path::Path;

/// The largest header accepted (the safetensors crate's limit).
const MAX_HEADER: u64 = 100_000_000;

/// Checks the layout of the safetensors data `bytes` of `file_len` bytes (only the first
/// `8 + n` bytes are needed): a readable header, and every tensor's data offsets inside the
/// file. Returns a one-line reason; the caller names the file.
pub fn check_layout(bytes: &[u8], file_len: u64) -> Result<(), String> {
    let n = bytes
        .get(..8)
        .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")))
        .ok_or_else(|| format!("{file_len} bytes: too short for a safetensors header"))?;
    if n > MAX_HEADER || 8 + n > file_len {
        return Err(format!(
            "header length {n} does not fit the file's {file_len} bytes (not a safetensors \
             file, or a truncated one)"
        ));
    }
    let header = bytes
        .get(8..8 + n as usize)
        .ok_or_else(|| "the header is cut short (truncated file?)".to_string())?;
    let json: serde_json::Value =
        serde_json::from_slice(header).map_err(|e| format!("the header is not valid JSON: {e}"))?;
    let entries = json
        .as_object()
        .ok_or_else(|| "the header is not a JSON object".to_string())?;
    let data_len = file_len - 8 - n;
    let mut past_end: Option<(&str, u64)> = None;
    for (name, info) in entries.iter().filter(|(k, _)| *k != "__metadata__") {
        let offsets = info
            .get("data_offsets")
            .and_then(|o| o.as_array())
            .filter(|o| o.len() == 2)
            .and_then(|o| Some((o[0].as_u64()?, o[1].as_u64()?)))
            .ok_or_else(|| format!("tensor `{name}`: no valid data_offsets [begin, end]"))?;
        if offsets.1 > data_len && past_end.is_none_or(|(_, begin)| offsets.0 < begin) {
            past_end = Some((name, offsets.0));
        }
    }
    match past_end {
        Some((name, _)) => Err(format!(
            "tensor `{name}`: its data runs past the end of the file ({data_len} data bytes; \
             a truncated file?)"
        )),
        None => Ok(()),
    }
}

/// [`check_layout`] of the file at `path`, reading only its header.
pub fn check_file_layout(path: &Path) -> Result<(), String> {
    let mut file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let len = file.metadata().map_err(|e| e.to_string())?.len();
    let mut first = [0u8; 8];
    if len < 8 {
        return check_layout(&[], len);
    }
    file.read_exact(&mut first).map_err(|e| e.to_string())?;
    let n = u64::from_le_bytes(first);
    if n > MAX_HEADER || 8 + n > len {
        return check_layout(&first, len);
    }
    let mut bytes = first.to_vec();
    bytes.resize(8 + n as usize, 0);
    file.read_exact(&mut bytes[8..])
        .map_err(|e| e.to_string())?;
    check_layout(&bytes, len)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(header: &str, data: usize) -> Vec<u8> {
        let mut b = (header.len() as u64).to_le_bytes().to_vec();
        b.extend_from_slice(header.as_bytes());
        b.extend(std::iter::repeat_n(0u8, data));
        b
    }

    const HEADER: &str = r#"{"__metadata__":{"format":"pt"},"a":{"dtype":"F32","shape":[2],"data_offsets":[0,8]},"b":{"dtype":"F32","shape":[3],"data_offsets":[8,20]}}"#;

    #[test]
    fn a_whole_file_passes_and_a_truncated_one_names_the_first_cut_tensor() {
        let whole = file(HEADER, 20);
        assert_eq!(check_layout(&whole, whole.len() as u64), Ok(()));
        let err = check_layout(&whole, whole.len() as u64 - 4).unwrap_err();
        assert!(
            err.contains("tensor `b`") && err.contains("past the end"),
            "{err}"
        );
        let err = check_layout(&whole, whole.len() as u64 - 16).unwrap_err();
        assert!(err.contains("tensor `a`"), "{err}");
    }

    #[test]
    fn garbage_is_refused_without_panicking() {
        assert!(check_layout(b"abc", 3).is_err());
        let huge = u64::MAX.to_le_bytes();
        assert!(check_layout(&huge, 8).is_err());
        let not_json = file("{nope", 0);
        assert!(check_layout(&not_json, not_json.len() as u64)
            .unwrap_err()
            .contains("JSON"));
        let bad = file(r#"{"a":{"dtype":"F32","shape":[1]}}"#, 4);
        assert!(check_layout(&bad, bad.len() as u64)
            .unwrap_err()
            .contains("`a`"));
    }

    #[test]
    fn reads_only_the_header_of_a_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.safetensors");
        let mut bytes = file(HEADER, 20);
        std::fs::write(&p, &bytes).unwrap();
        assert_eq!(check_file_layout(&p), Ok(()));
        bytes.truncate(bytes.len() - 1);
        std::fs::write(&p, &bytes).unwrap();
        assert!(check_file_layout(&p).unwrap_err().contains("`b`"));
    }
}
