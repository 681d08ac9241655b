//! The assets embedded in the command (`xtask/build.rs`): the built-in tiny prior and the
//! CLIP tokenizer, unpacked once into a cache folder named by their hash, so that an
//! installed `gb-nerf` runs without the source tree it was built from.
//!
//! The folder is `$GB_NERF_CACHE/assets-<hash>` (default `$XDG_CACHE_HOME/gb-nerf` or
//! `~/.cache/gb-nerf`). `$GB_ASSETS` still wins: it names an assets folder to use instead.

use std::path::{Path, PathBuf};

use anyhow::Context;

mod embedded {
    include!(concat!(env!("OUT_DIR"), "/assets.rs"));
}

/// The cache root of the command.
fn cache_root() -> Option<PathBuf> {
    let env = |k: &str| {
        std::env::var_os(k)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    env("GB_NERF_CACHE")
        .or_else(|| env("XDG_CACHE_HOME").map(|d| d.join("gb-nerf")))
        .or_else(|| env("HOME").map(|d| d.join(".cache/gb-nerf")))
}

/// Writes every embedded file under `dir` (a fresh folder).
fn unpack(dir: &Path) -> anyhow::Result<()> {
    for (rel, bytes) in embedded::FILES {
        let path = dir.join(rel);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("creating {}", parent.display()))?;
        }
        std::fs::write(&path, bytes).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// The unpacked assets folder, unpacking it first when needed (into a temporary sibling,
/// renamed into place, so a concurrent or interrupted unpack never leaves a partial folder).
pub fn unpacked() -> anyhow::Result<PathBuf> {
    let root = cache_root().context(
        "no cache folder for the built-in assets: set GB_NERF_CACHE (or HOME), or GB_ASSETS",
    )?;
    let dir = root.join(format!("assets-{}", embedded::HASH));
    if dir.join("tiny-prior/model_index.json").is_file() {
        return Ok(dir);
    }
    std::fs::create_dir_all(&root).with_context(|| format!("creating {}", root.display()))?;
    let tmp = tempfile::Builder::new()
        .prefix(".assets-")
        .tempdir_in(&root)
        .with_context(|| format!("creating a folder in {}", root.display()))?;
    unpack(tmp.path())?;
    match std::fs::rename(tmp.path(), &dir) {
        Ok(()) => {
            let _ = tmp.keep();
        }
        // another process unpacked the same assets first
        Err(_) if dir.join("tiny-prior/model_index.json").is_file() => {}
        Err(e) => return Err(e).with_context(|| format!("moving the assets to {}", dir.display())),
    }
    tracing::debug!(dir = %dir.display(), "unpacked the built-in assets");
    Ok(dir)
}

/// Points `gb_core::assets_dir` at the embedded assets, unless `$GB_ASSETS` is set or the
/// command was built without them (the `embed-assets` feature off: `gb_core::assets_dir`
/// then names `$GB_ASSETS` or the source tree's `assets/`).
pub fn install() -> anyhow::Result<()> {
    if std::env::var_os("GB_ASSETS").is_some() || embedded::FILES.is_empty() {
        return Ok(());
    }
    gb_core::assets::use_assets_dir(unpacked()?);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_embedded_assets_equal_the_repository_and_unpack_once() {
        let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets");
        assert!(embedded::FILES.len() > 10, "{}", embedded::FILES.len());
        for (rel, bytes) in embedded::FILES {
            assert_eq!(std::fs::read(src.join(rel)).unwrap(), *bytes, "{rel}");
        }
        let cache = tempfile::tempdir().unwrap();
        let dir = cache.path().join(format!("assets-{}", embedded::HASH));
        unpack(&dir).unwrap();
        for (rel, bytes) in embedded::FILES {
            assert_eq!(std::fs::read(dir.join(rel)).unwrap(), *bytes, "{rel}");
        }
    }
}
