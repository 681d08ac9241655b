//! Helpers for the end-to-end tests in `tests/tests/`.
//!
//! The tests run the `xtask` binary that `cargo test --workspace` builds (the xtask package has
//! an integration test, so Cargo builds its binary before any test runs). Running the binary
//! directly, rather than a nested `cargo run`, avoids waiting on Cargo's build-directory lock.

use std::path::PathBuf;
use std::process::{Command, Output};

pub mod fuzz;

/// The workspace root.
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The path of the command's binary (`gb-nerf`, what `cargo xtask` runs) built beside the
/// running test executable.
pub fn xtask_binary() -> PathBuf {
    let exe = std::env::current_exe().expect("no current executable");
    // target/<profile>/deps/<test>-<hash> -> target/<profile>/gb-nerf
    let profile_dir = exe
        .parent()
        .and_then(|deps| deps.parent())
        .expect("test executable is not inside target/<profile>/deps");
    let bin = profile_dir.join(format!("gb-nerf{}", std::env::consts::EXE_SUFFIX));
    assert!(
        bin.exists(),
        "{} not found: run the tests with `cargo test --workspace`, which builds it",
        bin.display()
    );
    bin
}

/// Runs `cargo xtask ARGS` (the built binary) from the workspace root and returns its output.
pub fn xtask(args: &[&str]) -> Output {
    Command::new(xtask_binary())
        .current_dir(workspace_root())
        .args(args)
        .output()
        .expect("cannot start the xtask binary")
}

/// Runs `cargo xtask ARGS` like [`xtask`], with `env` added to its environment.
pub fn xtask_with_env(args: &[&str], env: &[(&str, &str)]) -> Output {
    Command::new(xtask_binary())
        .current_dir(workspace_root())
        .args(args)
        .envs(env.iter().copied())
        .output()
        .expect("cannot start the xtask binary")
}

/// The committed tiny SD-inpainting fixture (resolution 32), the prior of the end-to-end runs.
pub const FIXTURE_PRIOR: &str = "crates/gb-diffusion/tests/fixtures/sd_image/pipeline";

/// The fixture U-Net LoRA that fits [`FIXTURE_PRIOR`].
pub const FIXTURE_LORA: &str =
    "crates/gb-diffusion/tests/fixtures/sd_text/lora/unet_lora.safetensors";

/// The flags of the small method grid of the grid tests: `none` and `mvip-nerf` on `scene`
/// with the fixture prior and LoRA, `preset`, 2 steps, on flex.
pub fn small_grid_flags<'a>(scene: &'a str, preset: &'a str) -> Vec<&'a str> {
    vec![
        "--scene",
        scene,
        "--methods",
        "none,mvip-nerf",
        "--prior",
        FIXTURE_PRIOR,
        "--lora",
        FIXTURE_LORA,
        "--preset",
        preset,
        "--steps",
        "2",
        "--device",
        "flex",
    ]
}

/// Whether a Slurm answers here: `SLURM_CONF` is set and `sinfo` runs
/// (`tools/slurm/single_node.sh` starts one).
pub fn slurm_available() -> bool {
    std::env::var_os("SLURM_CONF").is_some()
        && std::process::Command::new("sinfo")
            .arg("-h")
            .output()
            .is_ok_and(|o| o.status.success())
}

/// A path as `&str` (test paths are UTF-8).
pub fn path_str(p: &std::path::Path) -> &str {
    p.to_str().expect("non-UTF-8 test path")
}

/// Fails with the command's stderr when `out` is not a success.
pub fn assert_success(out: &Output, what: &str) {
    assert!(
        out.status.success(),
        "{what} failed ({:?}):\n{}",
        out.status.code(),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Generates a small procedural `stairs` scene (5 views, 1 test view, seed 3) of
/// `width x height` with the mask grown by `dilate` pixels at `dir/scene`.
pub fn small_stairs(dir: &std::path::Path, width: usize, height: usize, dilate: usize) -> PathBuf {
    let scene = dir.join("scene");
    let (w, h, d) = (width.to_string(), height.to_string(), dilate.to_string());
    let out = xtask(&[
        "scene",
        "--name",
        "stairs",
        "--width",
        &w,
        "--height",
        &h,
        "--views",
        "5",
        "--test-views",
        "1",
        "--dilate",
        &d,
        "--seed",
        "3",
        "--out",
        path_str(&scene),
    ]);
    assert_success(&out, "scene");
    scene
}

/// Writes `dir/small.toml`: the `fast` preset with 128 rays of 16 samples per step, and a
/// checkpoint every `checkpoint_every` steps when given.
pub fn small_preset(dir: &std::path::Path, checkpoint_every: Option<usize>) -> PathBuf {
    let mut fast = std::fs::read_to_string(workspace_root().join("configs/presets/fast.toml"))
        .expect("configs/presets/fast.toml")
        .replace("rays_per_batch = 512", "rays_per_batch = 128")
        .replace("samples_per_ray = 40", "samples_per_ray = 16");
    assert!(fast.contains("rays_per_batch = 128") && fast.contains("samples_per_ray = 16"));
    if let Some(k) = checkpoint_every {
        fast = fast.replace("checkpoint_every = 200", &format!("checkpoint_every = {k}"));
        assert!(fast.contains(&format!("checkpoint_every = {k}")));
    }
    let preset = dir.join("small.toml");
    std::fs::write(&preset, fast).expect("writing small.toml");
    preset
}

/// Every file under `dir` (recursively), as paths relative to it, sorted.
pub fn files_under(dir: &std::path::Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).expect("reading a test folder") {
            let path = entry.expect("reading a test folder").path();
            if path.is_dir() {
                stack.push(path);
            } else {
                out.push(path.strip_prefix(dir).expect("under dir").to_path_buf());
            }
        }
    }
    out.sort();
    out
}
