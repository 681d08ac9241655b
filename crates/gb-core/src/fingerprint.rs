//! 64-bit FNV-1a fingerprints for caches: of words, of bytes, and of a file or folder's
//! contents (so that a cache follows what a file holds, not where it lies).

use std::io::Read;
use std::path::Path;

/// An FNV-1a hasher over 64-bit words.
#[derive(Debug, Clone, Copy)]
pub struct Fnv64(u64);

impl Default for Fnv64 {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv64 {
    /// Mixes one word in.
    pub fn word(&mut self, w: u64) {
        self.0 ^= w;
        self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
    }

    /// Mixes bytes in, eight at a time (the tail zero-padded), then their count.
    pub fn bytes(&mut self, b: &[u8]) {
        let mut chunks = b.chunks_exact(8);
        for c in &mut chunks {
            self.word(word_of(c));
        }
        let rest = chunks.remainder();
        if !rest.is_empty() {
            let mut pad = [0u8; 8];
            pad[..rest.len()].copy_from_slice(rest);
            self.word(u64::from_le_bytes(pad));
        }
        self.word(b.len() as u64);
    }

    /// The fingerprint.
    pub fn finish(&self) -> u64 {
        self.0
    }
}

/// The little-endian word of eight bytes.
fn word_of(eight: &[u8]) -> u64 {
    let mut w = [0u8; 8];
    w.copy_from_slice(eight);
    u64::from_le_bytes(w)
}

/// The fingerprint of the contents of `path`: a file's bytes, or every file under a folder
/// (in sorted order, each with its path relative to the folder). Symbolic links are
/// followed.
pub fn contents(path: &Path) -> std::io::Result<u64> {
    let mut h = Fnv64::default();
    add_contents(&mut h, path, Path::new(""))?;
    Ok(h.finish())
}

fn add_contents(h: &mut Fnv64, path: &Path, rel: &Path) -> std::io::Result<()> {
    if path.is_dir() {
        let mut entries: Vec<_> = std::fs::read_dir(path)?
            .map(|e| e.map(|e| e.file_name()))
            .collect::<Result<_, _>>()?;
        entries.sort();
        for name in entries {
            add_contents(h, &path.join(&name), &rel.join(&name))?;
        }
        return Ok(());
    }
    h.bytes(rel.to_string_lossy().as_bytes());
    let mut file = std::fs::File::open(path)?;
    let mut buf = vec![0u8; 1 << 20];
    // whole words only: a word never straddles two reads, whatever their sizes
    let (mut carry, mut held, mut total) = ([0u8; 8], 0usize, 0u64);
    loop {
        let n = file.read(&mut buf)?;
        if n == 0 {
            break;
        }
        total += n as u64;
        let mut rest = &buf[..n];
        // finish a word the last read began, then whole words, then keep the tail
        while held > 0 && !rest.is_empty() {
            carry[held] = rest[0];
            held += 1;
            rest = &rest[1..];
            if held == 8 {
                h.word(u64::from_le_bytes(carry));
                held = 0;
            }
        }
        let mut words = rest.chunks_exact(8);
        for w in &mut words {
            h.word(word_of(w));
        }
        for &byte in words.remainder() {
            carry[held] = byte;
            held += 1;
        }
    }
    if held > 0 {
        carry[held..].fill(0);
        h.word(u64::from_le_bytes(carry));
    }
    h.word(total);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_contents_anywhere_give_the_same_fingerprint_and_a_change_another() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a"), dir.path().join("b"));
        for d in [&a, &b] {
            std::fs::create_dir_all(d.join("unet")).unwrap();
            std::fs::write(d.join("unet/w.bin"), vec![7u8; 3_000_001]).unwrap();
            std::fs::write(d.join("config.json"), b"{}").unwrap();
        }
        assert_eq!(contents(&a).unwrap(), contents(&b).unwrap());
        let mut changed = vec![7u8; 3_000_001];
        changed[2_500_000] = 8;
        std::fs::write(b.join("unet/w.bin"), changed).unwrap();
        assert_ne!(contents(&a).unwrap(), contents(&b).unwrap());
        // a renamed file is another folder
        std::fs::write(b.join("unet/w.bin"), vec![7u8; 3_000_001]).unwrap();
        std::fs::rename(b.join("config.json"), b.join("config2.json")).unwrap();
        assert_ne!(contents(&a).unwrap(), contents(&b).unwrap());
    }
}
