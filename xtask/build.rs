//! Embeds the repository's `assets/` (the built-in tiny prior and the CLIP tokenizer) into
//! the `gb-nerf` command, so that an installed command needs no source tree. Writes
//! `$OUT_DIR/assets.rs`: every file as `(relative path, include_bytes!(..))`, plus a hash of
//! the contents that names the folder they are unpacked into. Any change under `assets/`
//! rebuilds the command.

use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};

fn files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("reading {}: {e}", dir.display()))
        .map(|e| e.expect("a directory entry").path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            println!("cargo:rerun-if-changed={}", p.display());
            files(&p, out);
        } else {
            out.push(p);
        }
    }
}

fn main() {
    // read at run time, not with env!(): cargo reuses a compiled build script for the same
    // package in another clone sharing the target folder, and a compiled-in path would then
    // name the clone it was first built in
    let manifest = std::env::var_os("CARGO_MANIFEST_DIR").expect("CARGO_MANIFEST_DIR");
    let root = Path::new(&manifest).join("../assets");
    let root = root
        .canonicalize()
        .expect("the repository's assets/ folder");
    println!("cargo:rerun-if-changed={}", root.display());
    let mut all = Vec::new();
    // without the `embed-assets` feature the table is empty and the command reads
    // $GB_ASSETS (or the source tree) instead
    if std::env::var_os("CARGO_FEATURE_EMBED_ASSETS").is_some() {
        files(&root, &mut all);
    }
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    let mut table = String::from("/// The embedded assets: (path relative to `assets/`, bytes).\n");
    table.push_str("pub static FILES: &[(&str, &[u8])] = &[\n");
    for p in &all {
        println!("cargo:rerun-if-changed={}", p.display());
        let rel = p.strip_prefix(&root).expect("under assets/");
        let rel = rel.to_string_lossy().replace('\\', "/");
        rel.hash(&mut hasher);
        std::fs::read(p)
            .unwrap_or_else(|e| panic!("reading {}: {e}", p.display()))
            .hash(&mut hasher);
        table.push_str(&format!(
            "    ({rel:?}, include_bytes!({:?})),\n",
            p.display().to_string()
        ));
    }
    table.push_str("];\n");
    table.push_str(&format!(
        "/// A hash of the embedded assets' names and contents.\npub const HASH: &str = \"{:016x}\";\n",
        hasher.finish()
    ));
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("OUT_DIR")).join("assets.rs");
    std::fs::write(&out, table).expect("writing assets.rs");
}
