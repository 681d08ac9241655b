//! The sectioned container of the workspace's checkpoints (gb-nerf's training checkpoint,
//! gb-finetune's): a magic line naming the format and its version, then each section as its
//! length (`u64`, little-endian) and its bytes. The callers name the sections, write the file
//! atomically ([`crate::write_atomic`]) and wrap the messages below with its path.

/// `magic`, then each of `sections` with its length.
pub fn encode(magic: &[u8], sections: &[&[u8]]) -> Vec<u8> {
    let total = magic.len() + sections.iter().map(|s| 8 + s.len()).sum::<usize>();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(magic);
    for section in sections {
        out.extend_from_slice(&(section.len() as u64).to_le_bytes());
        out.extend_from_slice(section);
    }
    out
}

/// The sections `names` of `bytes`, in order, when it starts with `magic`. A file that starts
/// with one of `old_magics` is refused as written by an older version (one that cannot resume
/// exactly); any other as not a `kind` checkpoint; a short one names the section it lacks.
pub fn decode(
    bytes: &[u8],
    magic: &[u8],
    old_magics: &[&[u8]],
    kind: &str,
    names: &[&str],
) -> Result<Vec<Vec<u8>>, String> {
    if let Some(old) = old_magics.iter().find(|m| bytes.starts_with(m)) {
        return Err(format!(
            "written by an older version ({}) that cannot resume exactly; this version reads \
             {}: start the run afresh (without --resume, or delete the file)",
            String::from_utf8_lossy(old).trim(),
            String::from_utf8_lossy(magic).trim()
        ));
    }
    if !bytes.starts_with(magic) {
        return Err(format!("not a {kind} checkpoint (bad magic)"));
    }
    let mut pos = magic.len();
    let mut sections = Vec::with_capacity(names.len());
    for name in names {
        let len_bytes: [u8; 8] = bytes
            .get(pos..pos + 8)
            .and_then(|s| s.try_into().ok())
            .ok_or_else(|| format!("truncated before the {name} section"))?;
        let len = u64::from_le_bytes(len_bytes) as usize;
        pos += 8;
        let body = bytes
            .get(pos..pos.saturating_add(len))
            .ok_or_else(|| format!("truncated {name} section"))?;
        sections.push(body.to_vec());
        pos += len;
    }
    Ok(sections)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MAGIC: &[u8] = b"TESTCK2\n";
    const OLD: &[&[u8]] = &[b"TESTCK1\n"];
    const NAMES: &[&str] = &["metadata", "model"];

    #[test]
    fn sections_round_trip() {
        let bytes = encode(MAGIC, &[b"{}", b"weights"]);
        assert_eq!(bytes.len(), MAGIC.len() + 8 + 2 + 8 + 7);
        let back = decode(&bytes, MAGIC, OLD, "test", NAMES).unwrap();
        assert_eq!(back, vec![b"{}".to_vec(), b"weights".to_vec()]);
    }

    #[test]
    fn each_bad_file_says_why() {
        let bytes = encode(MAGIC, &[b"{}", b"weights"]);
        let e = decode(&bytes[..bytes.len() - 1], MAGIC, OLD, "test", NAMES).unwrap_err();
        assert_eq!(e, "truncated model section");
        let e = decode(&bytes[..MAGIC.len() + 4], MAGIC, OLD, "test", NAMES).unwrap_err();
        assert_eq!(e, "truncated before the metadata section");
        let e = decode(b"TESTCK1\nrest", MAGIC, OLD, "test", NAMES).unwrap_err();
        assert!(
            e.contains("older version (TESTCK1)") && e.contains("reads TESTCK2"),
            "{e}"
        );
        let e = decode(b"garbage", MAGIC, OLD, "test", NAMES).unwrap_err();
        assert_eq!(e, "not a test checkpoint (bad magic)");
        // a length that overflows the file is a truncation, not a panic
        let mut huge = MAGIC.to_vec();
        huge.extend(u64::MAX.to_le_bytes());
        let e = decode(&huge, MAGIC, OLD, "test", NAMES).unwrap_err();
        assert_eq!(e, "truncated metadata section");
    }
}
