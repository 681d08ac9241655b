//! Checks of a `.npy` header that must pass before the bytes go to `npyz`, which panics
//! (or allocates what the file declares) on some malformed headers: a shape whose element
//! count overflows `u64`, a header length past the end of the file, or a header nested
//! thousands of levels deep (its Python-literal parser recurses).
//!
//! Headers that pass can still be invalid; `npyz` reports those as errors.

/// The deepest bracket nesting accepted in a header (real ones nest at most 4 levels).
pub const MAX_HEADER_DEPTH: usize = 16;

/// Returns why `bytes` (a whole `.npy` file) must not be given to `npyz`, if anything.
pub fn check_npy_header(bytes: &[u8]) -> Result<(), String> {
    if bytes.len() < 10 || !bytes.starts_with(b"\x93NUMPY") {
        return Ok(()); // npyz reports the missing magic
    }
    let (start, len): (usize, usize) = match bytes[6] {
        1 => (10, u16::from_le_bytes([bytes[8], bytes[9]]) as usize),
        2 | 3 if bytes.len() >= 12 => (
            12,
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
        ),
        _ => return Ok(()), // npyz reports the version or the short file
    };
    let Some(text) = bytes.get(start..start.saturating_add(len)) else {
        return Err(format!(
            "the header declares {len} bytes but the file has {} after its prefix",
            bytes.len() - start
        ));
    };
    let text = String::from_utf8_lossy(text);
    check_depth(&text)?;
    check_shapes(&text)
}

/// Fails when brackets outside quotes nest deeper than [`MAX_HEADER_DEPTH`].
fn check_depth(text: &str) -> Result<(), String> {
    let (mut depth, mut quote) = (0usize, None);
    for c in text.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), _) => {}
            (None, '\'' | '"') => quote = Some(c),
            (None, '(' | '[' | '{') => {
                depth += 1;
                if depth > MAX_HEADER_DEPTH {
                    return Err(format!(
                        "the header nests more than {MAX_HEADER_DEPTH} levels deep"
                    ));
                }
            }
            (None, ')' | ']' | '}') => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    Ok(())
}

/// Fails when the integers of a `'shape': (...)` entry multiply past `u64` (zeros aside:
/// `npyz` multiplies in order, so `(2**40, 2**40, 0)` overflows too).
fn check_shapes(text: &str) -> Result<(), String> {
    for key in ["'shape'", "\"shape\""] {
        for (at, _) in text.match_indices(key) {
            let rest = text[at + key.len()..].trim_start();
            let Some(rest) = rest.strip_prefix(':') else {
                continue;
            };
            let rest = rest.trim_start();
            let end = rest.find([')', ']']).unwrap_or(rest.len());
            let dims = &rest[..end];
            let mut count: u64 = 1;
            for token in dims.split(|c: char| !c.is_ascii_digit()) {
                if token.is_empty() {
                    continue;
                }
                let d = token
                    .parse::<u64>()
                    .map_err(|_| format!("shape dimension {token} does not fit in 64 bits"))?;
                if d == 0 {
                    continue;
                }
                count = count.checked_mul(d).ok_or_else(|| {
                    format!(
                        "shape {}) has more elements than fit in 64 bits",
                        dims.trim()
                    )
                })?;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn npy(header: &str) -> Vec<u8> {
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend((header.len() as u16).to_le_bytes());
        b.extend(header.bytes());
        b
    }

    #[test]
    fn accepts_real_headers_and_leaves_garbage_to_npyz() {
        let ok = "{'descr': '<f4', 'fortran_order': False, 'shape': (20, 17), }\n";
        assert_eq!(check_npy_header(&npy(ok)), Ok(()));
        let records = "{'descr': [('a', '<f4', (2, 3))], 'fortran_order': False, 'shape': (0,), }";
        assert_eq!(check_npy_header(&npy(records)), Ok(()));
        assert_eq!(check_npy_header(b"nonsense"), Ok(()));
        assert_eq!(check_npy_header(b""), Ok(()));
    }

    #[test]
    fn rejects_overflowing_shapes_deep_nesting_and_short_files() {
        let big =
            "{'descr': '<f4', 'fortran_order': False, 'shape': (4294967296, 4294967296, 0), }";
        let e = check_npy_header(&npy(big)).unwrap_err();
        assert!(e.contains("64 bits"), "{e}");
        let huge = "{'shape': [18446744073709551616], }";
        assert!(check_npy_header(&npy(huge)).is_err());
        let deep = format!("{{'shape': {}1{}}}", "(".repeat(100), ")".repeat(100));
        let e = check_npy_header(&npy(&deep)).unwrap_err();
        assert!(e.contains("16 levels"), "{e}");
        let mut short = npy("{'shape': (2,), }");
        short[8] = 0xff;
        let e = check_npy_header(&short).unwrap_err();
        assert!(e.contains("declares 255 bytes"), "{e}");
    }
}
