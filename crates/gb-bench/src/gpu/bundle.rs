//! `bench gpu --prepare DIR`: everything the GPU benchmark needs on a lent GPU machine that
//! reaches no package registry and has no Rust toolchain, in one folder under the repository
//! root (git-ignored) that travels with the working tree:
//! - `gb-nerf.xz`: the running binary, stripped and xz-compressed (Python's `lzma`
//!   unpacks it there, so no `xz` is needed);
//! - `debs/`: the Vulkan loader (`libvulkan1`), for a machine without one (`dpkg -x` into
//!   `/`; the NVIDIA driver brings the ICD);
//! - `site.tar.xz`: the pinned diffusers and what the machine's Python lacks of its needs
//!   (`tools/bench/gpu_wheels.txt`; pure Python), unpacked from their wheels into one
//!   folder that goes on `PYTHONPATH` there, so torch and transformers come from the
//!   machine. One solid xz archive instead of the wheels themselves (zip, compressed file by
//!   file) because size is what limits the bundle: 1.9 MB instead of 6.4 MB for diffusers
//!   0.42.1; and no pip is needed there;
//! - `tools/bench/unet_bench.py`: the diffusers reference script, at the path `bench gpu`
//!   runs it from;
//! - `run.sh`: unpacks all of it and runs `bench gpu --no-setup` from the bundle folder, with
//!   the report under `$OUT`, so nothing of the source tree is needed there;
//! - `manifest.json`: what is in it, from which binary, and the sizes;
//! - `assets/` with `--with-assets` only: the built-in assets, for a binary built without
//!   them (`--no-default-features`, what the lent machine gets: see below) that runs away
//!   from the repository. `run.sh` points `$GB_ASSETS` at this copy, else at the
//!   repository's `assets/` beside the bundle.
//!
//! The binary to carry is built without the embedded assets (xtask's `embed-assets` feature
//! off), since the tracked tree that travels with the bundle holds `assets/` already: the
//! two copies would not fit together.
//!
//! The working tree that travels (tracked files, and the bundle named in `carry`) must stay
//! under the device tool's 64 MiB: the bundle is refused with both sizes when it would not.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context};
use serde_json::{json, Value};

/// The wheels' pins (pure Python; see the module docs).
pub const WHEELS_FILE: &str = "tools/bench/gpu_wheels.txt";

/// The diffusers reference script, relative to the repository root and to the bundle.
const REFERENCE_SCRIPT: &str = "tools/bench/unet_bench.py";

/// The Vulkan loader's Debian package.
const LOADER_PACKAGE: &str = "libvulkan1";

/// What `prepare` takes.
#[derive(Debug, Clone)]
pub struct Options {
    /// The bundle folder (made; its earlier contents are replaced).
    pub dir: PathBuf,
    /// The binary carried (the running `gb-nerf`).
    pub binary: PathBuf,
    /// The loader's `.deb` files from this folder instead of `apt-get download`.
    pub debs: Option<PathBuf>,
    /// The wheels from this folder instead of `pip download`.
    pub wheels: Option<PathBuf>,
    /// xz's preset (0 to 9).
    pub xz_level: u32,
    /// The most that the tracked tree and the bundle may hold together.
    pub limit_bytes: u64,
    /// Copies the built-in assets into the bundle, for a binary without them run away from
    /// the repository (on the lent machine the tracked tree brings `assets/`).
    pub with_assets: bool,
}

/// Writes the bundle (module docs) and returns its manifest.
pub fn prepare(options: &Options) -> anyhow::Result<Value> {
    let dir = &options.dir;
    if dir.exists() {
        std::fs::remove_dir_all(dir)
            .with_context(|| format!("--prepare {}: cannot clear the folder", dir.display()))?;
    }
    std::fs::create_dir_all(dir.join("debs"))
        .with_context(|| format!("--prepare {}: cannot create the folder", dir.display()))?;

    let binary = pack_binary(&options.binary, &dir.join("gb-nerf.xz"), options.xz_level)?;
    let debs = match &options.debs {
        Some(from) => copy_files(from, &dir.join("debs"), "deb", "--debs")?,
        None => download_loader(&dir.join("debs"))?,
    };
    let pins = read_pins(Path::new(WHEELS_FILE))?;
    let downloads = tempfile::tempdir()?;
    let wheels = match &options.wheels {
        Some(from) => copy_files(from, downloads.path(), "whl", "--wheels")?,
        None => download_wheels(&pins, downloads.path())?,
    };
    let site = (!wheels.is_empty())
        .then(|| pack_site(downloads.path(), &wheels, &dir.join("site.tar.xz")))
        .transpose()?;
    write_file(&dir.join("run.sh"), RUN_SH)?;
    let script = dir.join(REFERENCE_SCRIPT);
    std::fs::create_dir_all(script.parent().unwrap_or(dir))?;
    std::fs::copy(REFERENCE_SCRIPT, &script).with_context(|| {
        format!("{REFERENCE_SCRIPT}: cannot copy (run from the repository root)")
    })?;

    if options.with_assets {
        copy_tree(&gb_core::assets::assets_dir(), &dir.join("assets"))?;
    }
    let bundle_bytes = folder_bytes(dir)?;
    let tree_bytes = tracked_tree_bytes();
    let manifest = json!({
        "made_by": "gb-nerf bench gpu --prepare",
        "binary": binary,
        "vulkan_feature": cfg!(feature = "vulkan"),
        "shader_compiler": super::WGPU_COMPILER,
        "profile": if cfg!(debug_assertions) { "dev (deps at opt-level 3)" } else { "release" },
        "commit": git_commit(),
        "debs": debs,
        "wheel_pins": pins,
        "wheels": wheels,
        "site_tar_xz_bytes": site,
        "bundle_bytes": bundle_bytes,
        "tracked_tree_bytes": tree_bytes,
        "carry_limit_bytes": options.limit_bytes,
        "assets_in_bundle": options.with_assets,
    });
    write_file(
        &dir.join("manifest.json"),
        &(serde_json::to_string_pretty(&manifest)? + "\n"),
    )?;
    let total = bundle_bytes + tree_bytes.unwrap_or(0);
    if total > options.limit_bytes {
        bail!(
            "--prepare {}: the bundle ({:.1} MiB) and the tracked tree ({:.1} MiB) come to {:.1} \
             MiB, over the {:.0} MiB that travel to a GPU machine",
            dir.display(),
            mib(bundle_bytes),
            mib(tree_bytes.unwrap_or(0)),
            mib(total),
            mib(options.limit_bytes)
        );
    }
    if !cfg!(feature = "vulkan") {
        tracing::warn!(
            "this gb-nerf was built without the `vulkan` feature: the GPU runs WGSL kernels, \
             not SPIR-V with tensor cores (cargo build --release -p xtask --no-default-features \
             --features vulkan)"
        );
    }
    if cfg!(debug_assertions) {
        tracing::warn!(
            "this gb-nerf is a dev build (our code at opt-level 1): a release build measures \
             the host-side code as users run it"
        );
    }
    Ok(manifest)
}

/// The device tool's call for this bundle, in words: the `carry` list and the command.
pub fn device_instructions(dir: &Path, manifest: &Value) -> String {
    format!(
        "bundle written to {dir} ({bytes:.1} MiB; the tracked tree {tree:.1} MiB)\n\
         On the lent GPU machine (the device tool's run), from the repository root:\n  \
         carry: [\"{dir}\"]\n  command: bash {dir}/run.sh\n\
         The report and the log come back as $OUT/gpu-bench.json and $OUT/gpu-bench.log.",
        dir = dir.display(),
        bytes = mib(manifest["bundle_bytes"].as_u64().unwrap_or(0)),
        tree = mib(manifest["tracked_tree_bytes"].as_u64().unwrap_or(0)),
    )
}

/// The script that runs on the GPU machine (module docs).
const RUN_SH: &str = r#"#!/usr/bin/env bash
# Written by `gb-nerf bench gpu --prepare` (manifest.json says from which binary). Runs the GPU
# benchmark on a machine without a package registry or a Rust toolchain, from anywhere (it
# needs nothing but this folder): bash BUNDLE/run.sh [bench gpu flags]. The report:
# $OUT/gpu-bench.json (or BUNDLE/out/ when OUT is unset), the log beside it.
set -uo pipefail
bundle="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
out="${OUT:-$bundle/out}"
work="${GB_BUNDLE_WORK:-/tmp/gb-gpu-bundle}"
mkdir -p "$out" "$work"
out="$(cd "$out" && pwd)"
work="$(cd "$work" && pwd)"
log="$out/gpu-bench.log"
: > "$log"
say() { echo "run.sh: $*" | tee -a "$log" >&2; }

# 1. The Vulkan loader, unless the machine has one; the NVIDIA driver's ICD when the
#    loader would not find it by itself.
# (grep reads all of ldconfig's output: with -q it would stop early, and pipefail would then
# count ldconfig's broken pipe as no loader)
if ! ldconfig -p 2>/dev/null | grep 'libvulkan\.so\.1' > /dev/null; then
    for f in "$bundle"/debs/*.deb; do
        [ -e "$f" ] || continue
        say "unpacking $(basename "$f") into /"
        dpkg -x "$f" / || say "dpkg -x $f failed"
    done
    ldconfig || true
fi
icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
if [ -z "${VK_DRIVER_FILES:-}" ] && [ -f "$icd" ]; then
    export VK_DRIVER_FILES="$icd"
fi

# The built-in assets (the tiny prior, the tokenizer) for a binary built without them: the
# bundle's own copy (--with-assets), else the repository's beside the bundle.
if [ -z "${GB_ASSETS:-}" ]; then
    for d in "$bundle/assets" "$bundle/../assets"; do
        if [ -f "$d/tiny-prior/model_index.json" ]; then
            GB_ASSETS="$(cd "$d" && pwd)"
            export GB_ASSETS
            break
        fi
    done
fi

# 2. The binary.
python3 - "$bundle/gb-nerf.xz" "$work/gb-nerf" <<'PY' || { say "cannot unpack gb-nerf.xz"; exit 1; }
import lzma, shutil, sys
with lzma.open(sys.argv[1]) as src, open(sys.argv[2], "wb") as dst:
    shutil.copyfileobj(src, dst)
PY
chmod +x "$work/gb-nerf"

# 3. diffusers and the rest of site.tar.xz (torch and transformers come from the machine's
#    Python).
python=none
if [ -f "$bundle/site.tar.xz" ]; then
    if python3 - "$bundle/site.tar.xz" "$work/site" <<'PY' >> "$log" 2>&1; then
import sys, tarfile
with tarfile.open(sys.argv[1], "r:xz") as t:
    try:
        t.extractall(sys.argv[2], filter="data")
    except TypeError:  # Python before 3.11.4
        t.extractall(sys.argv[2])
PY
        export PYTHONPATH="$work/site${PYTHONPATH:+:$PYTHONPATH}"
        python=python3
    else
        say "site.tar.xz did not unpack: no diffusers reference"
    fi
fi

# 4. The benchmark, from the bundle folder (its tools/bench/unet_bench.py is the reference).
cd "$bundle" || exit 1
nvidia-smi --query-gpu=name,driver_version,memory.used,memory.total --format=csv >> "$log" 2>&1 || true
"$work/gb-nerf" bench gpu --no-setup --python "$python" --out "$out/gpu-bench.json" "$@" 2>&1 \
    | tee -a "$log"
status=${PIPESTATUS[0]}
say "bench gpu exited with $status"
exit "$status"
"#;

/// Strips a copy of `binary` (`strip`, when there is one) and xz-compresses it into `to`;
/// the manifest's `binary` entry.
pub fn pack_binary(binary: &Path, to: &Path, level: u32) -> anyhow::Result<Value> {
    let original = std::fs::metadata(binary)
        .with_context(|| format!("{}: cannot read the binary", binary.display()))?
        .len();
    let stripped = to.with_extension("stripped");
    std::fs::copy(binary, &stripped)
        .with_context(|| format!("{}: cannot copy the binary", binary.display()))?;
    let was_stripped = Command::new("strip")
        .arg(&stripped)
        .status()
        .is_ok_and(|s| s.success());
    if !was_stripped {
        tracing::warn!("`strip` did not run (binutils): the binary travels with its symbols");
    }
    let stripped_bytes = std::fs::metadata(&stripped)?.len();
    let file =
        std::fs::File::create(to).with_context(|| format!("{}: cannot create", to.display()))?;
    // -9e at 9: size is what limits the bundle (module docs)
    let preset = match level.min(9) {
        9 => "-9e".to_string(),
        l => format!("-{l}"),
    };
    let status = Command::new("xz")
        .args([preset.as_str(), "-c"])
        .arg(&stripped)
        .stdout(file)
        .status()
        .context("cannot start xz (Debian's xz-utils)")?;
    std::fs::remove_file(&stripped).ok();
    if !status.success() {
        bail!("xz failed on {} ({status})", binary.display());
    }
    Ok(json!({
        "from": binary.display().to_string(),
        "bytes": original,
        "stripped": was_stripped,
        "stripped_bytes": stripped_bytes,
        "xz_bytes": std::fs::metadata(to)?.len(),
        "xz_level": level.min(9),
    }))
}

/// Unpacks the wheels `names` of `from` into one folder and packs it as a solid xz tar at
/// `to` (Python's `zipfile` and `tarfile`); its size.
fn pack_site(from: &Path, names: &[String], to: &Path) -> anyhow::Result<u64> {
    const SCRIPT: &str = r#"
import lzma, os, sys, tarfile, tempfile, zipfile
out, wheels = sys.argv[1], sys.argv[2:]
with tempfile.TemporaryDirectory() as site:
    for w in wheels:
        zipfile.ZipFile(w).extractall(site)
    with tarfile.open(out, "w:xz", preset=9 | lzma.PRESET_EXTREME) as t:
        for name in sorted(os.listdir(site)):
            t.add(os.path.join(site, name), arcname=name)
"#;
    let out = Command::new("python3")
        .args(["-c", SCRIPT])
        .arg(to)
        .args(names.iter().map(|n| from.join(n)))
        .output()
        .context("cannot start python3 (it unpacks the wheels)")?;
    if !out.status.success() {
        bail!(
            "packing the wheels {} failed: {}",
            names.join(", "),
            last_line(&out.stderr)
        );
    }
    Ok(std::fs::metadata(to)?.len())
}

/// The `NAME==VERSION` lines of a pins file (comments and blank lines left out).
pub fn read_pins(path: &Path) -> anyhow::Result<Vec<String>> {
    let text = std::fs::read_to_string(path).with_context(|| {
        format!(
            "{}: cannot read (run from the repository root)",
            path.display()
        )
    })?;
    let pins: Vec<String> = text
        .lines()
        .map(|l| l.split('#').next().unwrap_or("").trim())
        .filter(|l| !l.is_empty())
        .map(str::to_string)
        .collect();
    if let Some(bad) = pins.iter().find(|p| !p.contains("==")) {
        bail!("{}: '{bad}' is not pinned as NAME==VERSION", path.display());
    }
    Ok(pins)
}

/// `apt-get download` of the loader into `to`; the files.
fn download_loader(to: &Path) -> anyhow::Result<Vec<String>> {
    let out = Command::new("apt-get")
        .args(["download", LOADER_PACKAGE])
        .current_dir(to)
        .output()
        .context("cannot start apt-get: pass --debs DIR with libvulkan1's .deb")?;
    if !out.status.success() {
        bail!(
            "apt-get download {LOADER_PACKAGE} failed ({}): pass --debs DIR with its .deb",
            last_line(&out.stderr)
        );
    }
    file_names(to, "deb")
}

/// `pip download` of the pinned wheels for the GPU machine's Python (3.12, x86-64) into `to`;
/// the files.
fn download_wheels(pins: &[String], to: &Path) -> anyhow::Result<Vec<String>> {
    let out = Command::new("python3")
        .args([
            "-m",
            "pip",
            "download",
            "--quiet",
            "--no-deps",
            "--only-binary=:all:",
        ])
        .args(["--python-version", "3.12", "--implementation", "cp"])
        .args(["--platform", "manylinux2014_x86_64", "--dest"])
        .arg(to)
        .args(pins)
        .output()
        .context("cannot start python3 -m pip: pass --wheels DIR")?;
    if !out.status.success() {
        bail!(
            "pip download {} failed ({}): pass --wheels DIR with those wheels",
            pins.join(" "),
            last_line(&out.stderr)
        );
    }
    file_names(to, "whl")
}

/// Copies the `*.ext` files of `from` into `to`; their names. `flag` names the option in
/// errors.
fn copy_files(from: &Path, to: &Path, ext: &str, flag: &str) -> anyhow::Result<Vec<String>> {
    let entries = std::fs::read_dir(from)
        .with_context(|| format!("{flag} {}: cannot read the folder", from.display()))?;
    for entry in entries {
        let path = entry?.path();
        if path.extension().is_some_and(|e| e == ext) {
            let name = path.file_name().context("a file without a name")?;
            std::fs::copy(&path, to.join(name))
                .with_context(|| format!("{flag}: cannot copy {}", path.display()))?;
        }
    }
    file_names(to, ext)
}

/// Copies the folder `from` into `to`, recursively (links stay links on Unix).
fn copy_tree(from: &Path, to: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(to).with_context(|| format!("{}: cannot create", to.display()))?;
    let entries =
        std::fs::read_dir(from).with_context(|| format!("{}: cannot read", from.display()))?;
    for entry in entries {
        let entry = entry?;
        let target = to.join(entry.file_name());
        #[cfg(unix)]
        if entry.file_type()?.is_symlink() {
            // assets/tiny-prior/tokenizer -> ../clip-tokenizer: kept a link, as in the tree
            std::os::unix::fs::symlink(std::fs::read_link(entry.path())?, &target)
                .with_context(|| format!("{}: cannot link", target.display()))?;
            continue;
        }
        if std::fs::metadata(entry.path())?.is_dir() {
            copy_tree(&entry.path(), &target)?;
        } else {
            std::fs::copy(entry.path(), &target)
                .with_context(|| format!("{}: cannot copy", entry.path().display()))?;
        }
    }
    Ok(())
}

/// The sorted names of the `*.ext` files in `dir`.
fn file_names(dir: &Path, ext: &str) -> anyhow::Result<Vec<String>> {
    let mut names: Vec<String> = std::fs::read_dir(dir)?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == ext))
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    names.sort();
    Ok(names)
}

/// The bytes of the files below `dir`.
fn folder_bytes(dir: &Path) -> anyhow::Result<u64> {
    let mut total = 0;
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let meta = entry.metadata()?;
        total += if meta.is_dir() {
            folder_bytes(&entry.path())?
        } else {
            meta.len()
        };
    }
    Ok(total)
}

/// The bytes of the files git tracks here (what travels besides the bundle), when this is a
/// git checkout.
fn tracked_tree_bytes() -> Option<u64> {
    let out = Command::new("git").args(["ls-files", "-z"]).output().ok()?;
    if !out.status.success() {
        return None;
    }
    let total = out
        .stdout
        .split(|b| *b == 0)
        .filter(|p| !p.is_empty())
        .filter_map(|p| std::fs::metadata(String::from_utf8_lossy(p).as_ref()).ok())
        .map(|m| m.len())
        .sum();
    Some(total)
}

/// `git rev-parse HEAD` here, when it answers.
fn git_commit() -> Option<String> {
    let out = Command::new("git")
        .args(["rev-parse", "HEAD"])
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// The last line a command wrote (its error, for one-line messages).
fn last_line(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes)
        .lines()
        .last()
        .unwrap_or("")
        .to_string()
}

fn write_file(path: &Path, text: &str) -> anyhow::Result<()> {
    gb_core::write_atomic(path, text.as_bytes())
        .with_context(|| format!("{}: cannot write", path.display()))
}

fn mib(bytes: u64) -> f64 {
    bytes as f64 / (1u64 << 20) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_packed_binary_unpacks_to_a_program_that_runs() {
        let dir = tempfile::tempdir().unwrap();
        let xz = dir.path().join("true.xz");
        let entry = pack_binary(Path::new("/bin/true"), &xz, 0).unwrap();
        assert_eq!(
            entry["bytes"],
            json!(std::fs::metadata("/bin/true").unwrap().len())
        );
        let xz_bytes = entry["xz_bytes"].as_u64().unwrap();
        assert!(xz_bytes > 0 && xz_bytes < entry["stripped_bytes"].as_u64().unwrap());
        // unpacked as run.sh does it (Python's lzma), then run
        let unpacked = dir.path().join("true");
        let status = Command::new("python3")
            .args(["-c", "import lzma,shutil,sys; shutil.copyfileobj(lzma.open(sys.argv[1]), open(sys.argv[2],'wb'))"])
            .arg(&xz)
            .arg(&unpacked)
            .status()
            .unwrap();
        assert!(status.success());
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&unpacked, std::fs::Permissions::from_mode(0o755)).unwrap();
        assert!(Command::new(&unpacked).status().unwrap().success());
    }

    #[test]
    fn pins_are_name_equals_version_and_diffusers_agrees_with_the_bench_venv() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let pins = read_pins(&root.join(WHEELS_FILE)).unwrap();
        let diffusers = pins.iter().find(|p| p.starts_with("diffusers==")).unwrap();
        let venv = read_pins(&root.join("tools/bench/requirements.txt")).unwrap();
        assert!(
            venv.contains(diffusers),
            "{diffusers} is not in tools/bench/requirements.txt"
        );

        let dir = tempfile::tempdir().unwrap();
        let bad = dir.path().join("pins.txt");
        std::fs::write(&bad, "# comment\ndiffusers\n").unwrap();
        let err = read_pins(&bad).unwrap_err().to_string();
        assert!(err.contains("'diffusers' is not pinned"), "{err}");
    }
}
