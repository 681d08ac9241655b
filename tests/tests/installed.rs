//! The command as `cargo install --path xtask` leaves it: the `gb-nerf` binary alone in a
//! `bin/` folder, run from an unrelated folder, with a fresh cache and without Cargo's
//! environment. The default job (the built-in tiny prior and the CLIP tokenizer, the
//! generated stairs scene) must run from the assets embedded in the binary, and nothing it
//! writes may name the source tree the binary was built from.
//!
//! Slow on purpose (about 100 s on 2 cores): it runs the whole default job, export and test
//! renders included, because the property is about everything that job writes.

use std::path::Path;
use std::process::Command;

use gb_tests::{workspace_root, xtask_binary};

/// Every file under `dir` whose text mentions `needle`.
fn files_naming(dir: &Path, needle: &str) -> Vec<String> {
    let mut hits = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if std::fs::read(&p)
                .map(|b| String::from_utf8_lossy(&b).contains(needle))
                .unwrap_or(false)
            {
                hits.push(p.display().to_string());
            }
        }
    }
    hits
}

#[test]
fn the_installed_command_runs_the_default_job_without_the_source_tree() {
    let root = tempfile::tempdir().unwrap();
    let bin = root.path().join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    let exe = bin.join(format!("gb-nerf{}", std::env::consts::EXE_SUFFIX));
    std::fs::copy(xtask_binary(), &exe).unwrap();
    let (home, work) = (root.path().join("home"), root.path().join("work"));
    std::fs::create_dir_all(&work).unwrap();
    let mut cmd = Command::new(&exe);
    cmd.current_dir(&work)
        .env_clear()
        .env("HOME", &home)
        .env("PATH", std::env::var_os("PATH").unwrap_or_default())
        .args([
            "inpaint",
            "--steps",
            "1",
            "--orbit-frames",
            "0",
            "--export",
            "full",
            "--out",
            "run",
        ]);
    let out = cmd.output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");

    // the built-in prior came from the unpacked copy in the fresh cache
    let run = work.join("run");
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["method"], "gb-nerf-unseen");
    let prior = metrics["prior"].as_str().unwrap();
    let cache = home.join(".cache/gb-nerf");
    assert!(
        prior.starts_with(&cache.display().to_string()) && prior.ends_with("tiny-prior"),
        "{prior}"
    );
    let config = std::fs::read_to_string(run.join("config.toml")).unwrap();
    assert!(config.contains("--prior tiny"), "{config}");
    // its reproducing command is the installed command, not `cargo xtask`
    assert!(
        config.contains("\n#   gb-nerf inpaint --scene "),
        "{config}"
    );
    assert!(!config.contains("cargo xtask"), "{config}");

    // nothing written names the source tree
    let source = workspace_root().canonicalize().unwrap();
    let hits = files_naming(&run, &source.display().to_string());
    assert!(
        hits.is_empty(),
        "files naming {}: {hits:?}",
        source.display()
    );

    // a second run reuses the unpacked assets
    let unpacked: Vec<_> = std::fs::read_dir(&cache).unwrap().collect();
    assert_eq!(unpacked.len(), 1, "{unpacked:?}");
    let help = Command::new(&exe)
        .env_clear()
        .env("HOME", &home)
        .arg("--help")
        .output();
    let help = String::from_utf8_lossy(&help.unwrap().stdout).to_string();
    assert!(help.contains("Usage: gb-nerf <COMMAND>"), "{help}");
}
