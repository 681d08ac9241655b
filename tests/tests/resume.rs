//! The exact resume, with a real `kill -9`: a run of `cargo xtask inpaint` (method `none`,
//! and the guided `gb-nerf-unseen` with the committed fixture prior and LoRA, whose
//! visibility maps and guidance counters are state too) and of `cargo xtask finetune
//! --synthetic` is started as a child process, SIGKILLed once its first checkpoint exists,
//! and resumed with `--resume`; its outputs must equal an uninterrupted run's bit for bit,
//! but for wall-time fields. Plus the `--resume` edge cases: no checkpoint (a warning, a
//! fresh start) and a checkpoint of another method or preset (refused, exit 2, naming the
//! file and the field).
//!
//! The kill is made deterministic by headroom, not by a test hook: a checkpoint every few
//! steps of a run many times longer, and the killed run must not have finished (no
//! `metrics.json` / LoRA file) while its checkpoint lies strictly inside the run.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use gb_tests::{assert_success, path_str as s, small_preset, small_stairs};
use gb_tests::{workspace_root, xtask, xtask_binary};
use gb_tests::{FIXTURE_LORA as LORA, FIXTURE_PRIOR as PRIOR};
use serde_json::Value;

/// The wall-time fields of `metrics.json` (at any depth; `seconds` is the orbit's, and a
/// log line's or a guidance term's in `train_log.jsonl`) and of `finetune`'s summary: the
/// only fields in which a resumed run may differ from an uninterrupted one. Every other
/// field must be equal bit for bit.
const WALL_TIME_FIELDS: &[&str] = &[
    "train_seconds_this_run",
    "unguided_seconds",
    "render_seconds",
    "eval_seconds",
    "seconds_per_guided_step",
    "seconds_per_unguided_step",
    "seconds",
    "train_seconds",
    "steps_per_second",
];

/// `v` without the [`WALL_TIME_FIELDS`], at any depth.
fn strip_wall_time(v: &mut Value) {
    match v {
        Value::Object(map) => {
            for key in WALL_TIME_FIELDS {
                map.remove(*key);
            }
            map.values_mut().for_each(strip_wall_time);
        }
        Value::Array(items) => items.iter_mut().for_each(strip_wall_time),
        _ => {}
    }
}

fn read_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The lines of a JSONL file without their wall-time fields.
fn jsonl_without_wall_time(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .map(|l| {
            let mut v: Value = serde_json::from_str(l).unwrap();
            strip_wall_time(&mut v);
            v
        })
        .collect()
}

/// Runs `cargo xtask ARGS` as a child process, waits until `file` exists (polling), then
/// kills it with SIGKILL (`Child::kill`) and reaps it. Fails when the child ends first.
fn kill_once_written(args: &[&str], file: &Path) {
    let mut child = Command::new(xtask_binary())
        .current_dir(workspace_root())
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("cannot start the xtask binary");
    let start = Instant::now();
    while !file.exists() {
        if let Some(status) = child.try_wait().unwrap() {
            panic!("the run ended ({status}) before {} existed", file.display());
        }
        // a safety net against a hung child, not a timing assertion
        if start.elapsed() > Duration::from_secs(900) {
            child.kill().ok();
            panic!("{} did not appear within 15 minutes", file.display());
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().expect("SIGKILL");
    let status = child.wait().unwrap();
    assert!(
        !status.success(),
        "the child was killed, not finished: {status}"
    );
}

/// The `step` of a checkpoint's JSON metadata (the first section after `magic`: a
/// little-endian `u64` length, then the JSON).
fn checkpoint_step(path: &Path, magic: &[u8]) -> usize {
    let bytes = std::fs::read(path).unwrap();
    assert!(
        bytes.starts_with(magic),
        "{}: not {magic:?}",
        path.display()
    );
    let at = magic.len();
    let len = u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()) as usize;
    let meta: Value = serde_json::from_slice(&bytes[at + 8..at + 8 + len]).unwrap();
    meta["step"].as_u64().unwrap() as usize
}

/// A `.safetensors` file as its JSON header (a value: the metadata's key order, which the
/// writer takes from a hash map, does not matter) and its tensor bytes.
fn safetensors_parts(path: &Path) -> (Value, Vec<u8>) {
    let bytes = std::fs::read(path).unwrap();
    let len = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header = serde_json::from_slice(&bytes[8..8 + len]).unwrap();
    (header, bytes[8 + len..].to_vec())
}

/// `resumed_from_step` of a run's `config.toml`.
fn resumed_from_step(out: &Path) -> usize {
    let cfg = std::fs::read_to_string(out.join("config.toml")).unwrap();
    cfg.lines()
        .find_map(|l| l.strip_prefix("resumed_from_step = "))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("no resumed_from_step in config.toml:\n{cfg}"))
}

/// The arguments of an inpainting run of `steps` steps into `out`.
fn inpaint_args<'a>(
    scene: &'a Path,
    preset: &'a Path,
    out: &'a Path,
    steps: &'a str,
    method: &[&'a str],
) -> Vec<&'a str> {
    let mut args = vec![
        "inpaint",
        "--scene",
        s(scene),
        "--preset",
        s(preset),
        "--out",
        s(out),
        "--device",
        "flex",
        "--steps",
        steps,
        "--orbit-frames",
        "0",
    ];
    args.extend_from_slice(method);
    args
}

/// Trains `steps` steps uninterrupted into `dir/straight`, then again into `dir/killed`
/// with a SIGKILL after its first checkpoint and a `--resume`; asserts equal outputs and
/// returns the scene, the preset and the uninterrupted run's folder.
fn killed_and_resumed_equals_uninterrupted(
    dir: &Path,
    checkpoint_every: usize,
    steps: usize,
    method: &[&str],
) -> (PathBuf, PathBuf, PathBuf) {
    let scene = small_stairs(dir, 40, 30, 1);
    let preset = small_preset(dir, Some(checkpoint_every));
    let (straight, killed) = (dir.join("straight"), dir.join("killed"));
    let n = steps.to_string();
    let run = xtask(&inpaint_args(&scene, &preset, &straight, &n, method));
    assert_success(&run, "uninterrupted run");

    let args = inpaint_args(&scene, &preset, &killed, &n, method);
    kill_once_written(&args, &killed.join("checkpoint.bin"));
    assert!(
        !killed.join("metrics.json").exists(),
        "the run finished before the kill: lengthen it"
    );
    let resume: Vec<&str> = args.iter().copied().chain(["--resume"]).collect();
    assert_success(&xtask(&resume), "resumed run");
    let from = resumed_from_step(&killed);
    assert!(
        from > 0 && from < steps && from.is_multiple_of(checkpoint_every),
        "resumed from step {from} of {steps}"
    );

    let (mut a, mut b) = (
        read_json(&straight.join("metrics.json")),
        read_json(&killed.join("metrics.json")),
    );
    assert_eq!(a["steps"], steps as u64);
    strip_wall_time(&mut a);
    strip_wall_time(&mut b);
    assert_eq!(a, b, "metrics.json of the resumed run (from step {from})");
    let (la, lb) = (
        jsonl_without_wall_time(&straight.join("train_log.jsonl")),
        jsonl_without_wall_time(&killed.join("train_log.jsonl")),
    );
    assert_eq!(la.len(), steps);
    assert_eq!(
        la, lb,
        "train_log.jsonl of the resumed run (from step {from})"
    );
    (scene, preset, straight)
}

#[test]
fn inpaint_without_guidance_resumes_exactly_after_sigkill() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, preset, straight) =
        killed_and_resumed_equals_uninterrupted(dir.path(), 4, 200, &["--method", "none"]);

    // a checkpoint of another method is refused, naming the file and the field
    let ckpt = straight.join("checkpoint.bin");
    let other = inpaint_args(
        &scene,
        &preset,
        &straight,
        "200",
        &["--method", "bsd", "--prior", PRIOR, "--resume"],
    );
    let o = xtask(&other);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    let line = err.lines().find(|l| l.starts_with("error:")).unwrap_or("");
    assert!(
        line.contains(s(&ckpt))
            && line.contains("method.name = \"none\"")
            && line.contains("\"bsd\""),
        "{err}"
    );

    // ... and so is one of another preset
    let text = std::fs::read_to_string(&preset).unwrap();
    let wider = dir.path().join("wider.toml");
    std::fs::write(
        &wider,
        text.replace("rays_per_batch = 128", "rays_per_batch = 96"),
    )
    .unwrap();
    let o = xtask(&inpaint_args(
        &scene,
        &wider,
        &straight,
        "200",
        &["--method", "none", "--resume"],
    ));
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    let line = err.lines().find(|l| l.starts_with("error:")).unwrap_or("");
    assert!(
        line.contains(s(&ckpt)) && line.contains("preset.train.rays_per_batch = 128"),
        "{err}"
    );
}

#[test]
fn guided_inpaint_resumes_exactly_after_sigkill() {
    let dir = tempfile::tempdir().unwrap();
    // gb-nerf-unseen: RGB and normal guidance from step 3 of 60, visibility maps from step
    // 12, so the first checkpoint (step 15) holds maps
    killed_and_resumed_equals_uninterrupted(
        dir.path(),
        15,
        60,
        &[
            "--method",
            "gb-nerf-unseen",
            "--prior",
            PRIOR,
            "--lora",
            LORA,
        ],
    );
}

#[test]
fn resume_without_a_checkpoint_starts_afresh_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let scene = small_stairs(dir.path(), 40, 30, 1);
    let preset = small_preset(dir.path(), None);
    let out = dir.path().join("out");
    let mut args = inpaint_args(&scene, &preset, &out, "2", &["--method", "none"]);
    args.push("--resume");
    let o = xtask(&args);
    assert_success(&o, "--resume without a checkpoint");
    let err = String::from_utf8_lossy(&o.stderr);
    let ckpt = out.join("checkpoint.bin");
    let notices: Vec<&str> = err
        .lines()
        .filter(|l| l.contains("WARN") && l.contains("no checkpoint at"))
        .collect();
    assert_eq!(notices.len(), 1, "{err}");
    assert!(
        notices[0].contains(s(&ckpt)) && notices[0].contains("starts afresh"),
        "{err}"
    );
    assert_eq!(read_json(&out.join("metrics.json"))["steps"], 2);
    assert_eq!(resumed_from_step(&out), 0);
}

/// `finetune --synthetic` with the fixture prior: `steps` steps, a checkpoint every
/// `every`, validation of the base and of the result on one held-out pair.
fn finetune_args<'a>(out: &'a Path, steps: &'a str, every: &'a str) -> Vec<&'a str> {
    vec![
        "finetune",
        "--synthetic",
        "--base",
        PRIOR,
        "--batch",
        "1",
        "--rank",
        "4",
        "--alpha",
        "4",
        "--resolution",
        "32",
        "--validate-every",
        "0",
        "--validation-samples",
        "1",
        "--validation-ddim-steps",
        "2",
        "--checkpoint-every",
        every,
        "--steps",
        steps,
        "--quiet",
        "--out",
        s(out),
    ]
}

#[test]
fn finetune_resumes_exactly_after_sigkill() {
    let dir = tempfile::tempdir().unwrap();
    let (straight, killed) = (dir.path().join("straight"), dir.path().join("killed"));
    let (steps, every) = (60usize, "3");
    let n = steps.to_string();
    let run = xtask(&finetune_args(&straight, &n, every));
    assert_success(&run, "uninterrupted finetune");

    let args = finetune_args(&killed, &n, every);
    kill_once_written(&args, &killed.join("checkpoint.gbft"));
    let lora = "pytorch_lora_weights.safetensors";
    assert!(
        !killed.join(lora).exists(),
        "the run finished before the kill: lengthen it"
    );
    let from = checkpoint_step(&killed.join("checkpoint.gbft"), b"GBFTCK2\n");
    assert!(
        from > 0 && from < steps,
        "checkpoint at step {from} of {steps}"
    );
    let resume: Vec<&str> = args.iter().copied().chain(["--resume"]).collect();
    let again = xtask(&resume);
    assert_success(&again, "resumed finetune");

    let (a, b) = (
        safetensors_parts(&straight.join(lora)),
        safetensors_parts(&killed.join(lora)),
    );
    assert_eq!(a.0, b.0, "LoRA header (from step {from})");
    assert!(
        a.1 == b.1,
        "the resumed LoRA's weights differ from the uninterrupted one's (from step {from})"
    );
    for file in ["validation.jsonl", "train_log.jsonl"] {
        let (x, y) = (
            jsonl_without_wall_time(&straight.join(file)),
            jsonl_without_wall_time(&killed.join(file)),
        );
        assert_eq!(x, y, "{file} of the resumed run (from step {from})");
    }
    let steps_validated: Vec<u64> = jsonl_without_wall_time(&straight.join("validation.jsonl"))
        .iter()
        .map(|v| v["step"].as_u64().unwrap())
        .collect();
    assert_eq!(steps_validated, [0, steps as u64]);
    // the printed summary too (its export path names the run's own folder)
    let summary = |out: &[u8], dir: &Path| {
        let mut v: Value = serde_json::from_slice(out).unwrap();
        assert_eq!(v["export"].as_str(), Some(s(&dir.join(lora))));
        v.as_object_mut().unwrap().remove("export");
        strip_wall_time(&mut v);
        v
    };
    let (x, y) = (
        summary(&run.stdout, &straight),
        summary(&again.stdout, &killed),
    );
    assert!(x["validation_base"].is_object(), "{x}");
    assert_eq!(x, y);
}
