//! `cargo xtask ablate`: the paper's method grid on one scene, and its tables.
//!
//! ```text
//! cargo xtask ablate --scene DIR [--methods LIST] [--preset P] [--prior P] [--lora FILE]
//!     [--steps N] [--seed N] [--out DIR] [--w3 LIST] [--device D] [--weights DIR]
//!     [--orbit-frames N]
//! ```
//!
//! Runs every method of the grid with the same code as `cargo xtask inpaint`
//! ([`super::inpaint::run_inpaint`], in this process), each into `OUT/METHOD/` (a complete
//! inpaint run: renders, metrics.json, config.toml, report.html), then writes:
//!
//! - `OUT/baselines.md` / `.json`: none, spin-nerf-sds, mvip-nerf, csd, gb-nerf;
//! - `OUT/ablation.md` / `.json`: origin = mvip-nerf (SDS on RGB and normals, no LoRA),
//!   +LoRA = sds-lora, +BSD = bsd, +LoRA+BSD = gb-nerf;
//! - `OUT/w3_sweep.md` / `.json` and `OUT/w3_sweep.svg`, `OUT/w3_sweep_psnr.svg`: csd with w3
//!   set to each value of `--w3` (default -1,-0.5,0,0.5,1) on both modalities, each into
//!   `OUT/csd-w3=X/` (the csd run itself is reused for the value of its config). The sweep
//!   runs when csd is in the grid or `--w3` is given.
//!
//! Columns, in `gb_inpaint::ablate`: masked-box SSIM, ST-LPIPS (when the weights exist),
//! D-PSNR, PSNR, and time. `--methods` restricts the grid (rows of methods that did not run
//! are left out). Method files and the prior / LoRA of every method are checked before the
//! first run; a run that fails later is reported in the tables and makes the command exit
//! with an error after writing them. The no-prior run goes first and is every other run's
//! `--baseline` in its report.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context};
use gb_core::BackendKind;
use gb_inpaint::ablate::{self, RunOutcome, ABLATION_ROWS, BASELINE_ROWS, DEFAULT_W3};
use gb_inpaint::{lora_for, MethodConfig};
use serde_json::json;

use super::finetune::resolve_prior;
use super::inpaint;

/// The settings of the method grid, shared by `cargo xtask ablate` and `bench quality`.
#[derive(clap::Args, Debug, Clone)]
pub struct GridArgs {
    /// Comma-separated methods (default: the whole grid: none, spin-nerf-sds, mvip-nerf,
    /// csd, gb-nerf, gb-nerf-unseen, sds-lora, bsd).
    #[arg(long, value_delimiter = ',')]
    pub methods: Option<Vec<String>>,
    /// Preset name (fast, balanced, paper) or a TOML file, for every run.
    #[arg(long, default_value = "fast")]
    pub preset: String,
    /// The diffusion prior of the guided methods: tiny (default), a folder or a hub id.
    #[arg(long)]
    pub prior: Option<String>,
    /// Override the preset's number of training steps (at least 1).
    #[arg(long, value_parser = super::parse::at_least_one)]
    pub steps: Option<usize>,
    /// Compute backend: ndarray, flex or wgpu.
    #[arg(long, value_parser = super::parse::device())]
    pub device: Option<BackendKind>,
}

/// Arguments of `cargo xtask ablate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene folder (LLFF / SPIn-NeRF or Blender layout, with masks).
    #[arg(long)]
    pub scene: PathBuf,
    /// The grid: methods, preset, prior, steps, device.
    #[command(flatten)]
    pub grid: GridArgs,
    /// LoRA file for the methods with `use_lora = true` (default: the prior's own).
    #[arg(long)]
    pub lora: Option<PathBuf>,
    /// Override the preset's training seed in every run.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Output folder.
    #[arg(long, default_value = "out/ablate")]
    pub out: PathBuf,
    /// Comma-separated w3 values of the CSD sweep (e.g. `--w3 -1,0,1`; default -1,-0.5,0,0.5,1).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub w3: Option<Vec<f64>>,
    /// Folder of metric weights (default `$GB_TEST_DATA/weights` when it exists).
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Frames of each run's orbit animation (0: none).
    #[arg(long, default_value_t = 0)]
    pub orbit_frames: usize,
}

/// The grid's methods in run order (none first: it is every report's baseline).
fn grid(selected: Option<&[String]>) -> Vec<String> {
    let mut all: Vec<String> = Vec::new();
    for (_, m) in BASELINE_ROWS.iter().chain(ABLATION_ROWS) {
        if !all.iter().any(|x| x == m) {
            all.push(m.to_string());
        }
    }
    match selected {
        None => all,
        Some(list) => {
            let mut out: Vec<String> = all
                .iter()
                .filter(|m| list.iter().any(|s| s.trim() == m.as_str()))
                .cloned()
                .collect();
            for s in list {
                let s = s.trim().to_string();
                if !s.is_empty() && !out.contains(&s) {
                    out.push(s);
                }
            }
            out
        }
    }
}

fn inpaint_args(
    args: &Args,
    method: &str,
    out: PathBuf,
    baseline: Option<PathBuf>,
) -> inpaint::Args {
    inpaint::Args {
        scene: Some(args.scene.clone()),
        method: Some(method.to_string()),
        preset: args.grid.preset.clone(),
        prior: Some(args.grid.prior.clone().unwrap_or_else(|| "tiny".into())),
        lora: None,
        prompt: None,
        negative_prompt: None,
        normal_prompt: None,
        out,
        device: args.grid.device,
        resume: false,
        steps: args.grid.steps,
        seed: args.seed,
        baseline,
        weights: args.weights.clone(),
        orbit_frames: args.orbit_frames,
    }
}

/// Checks every method and, for the guided ones, the prior and LoRA, before any training.
fn check(args: &Args, methods: &[MethodConfig]) -> anyhow::Result<()> {
    let mut prior_dir: Option<PathBuf> = None;
    for m in methods {
        if !m.needs_prior() {
            continue;
        }
        if prior_dir.is_none() {
            let spec = args.grid.prior.as_deref().unwrap_or("tiny");
            prior_dir = Some(
                resolve_prior(spec).with_context(|| format!("method {} needs a prior", m.name))?,
            );
        }
        if let Some(dir) = &prior_dir {
            let explicit = args.lora.as_deref().filter(|_| m.use_lora);
            lora_for(m, dir, explicit)?;
        }
    }
    Ok(())
}

/// Runs one method into `OUT/DIR` (errors become the outcome).
fn run_one(
    args: &Args,
    label: &str,
    method: &str,
    dir: &str,
    use_lora: bool,
    baseline: Option<PathBuf>,
) -> RunOutcome {
    let mut a = inpaint_args(args, method, args.out.join(dir), baseline);
    if use_lora {
        a.lora = args.lora.clone();
    }
    tracing::info!(method, out = %a.out.display(), "ablate: running");
    let start = Instant::now();
    let result = inpaint::run_inpaint(&a).map_err(|e| format!("{e:#}"));
    if let Err(e) = &result {
        tracing::error!(method, "ablate: the run failed: {e}");
    }
    RunOutcome {
        label: label.to_string(),
        method: method.to_string(),
        dir: dir.to_string(),
        result,
        seconds: start.elapsed().as_secs_f64(),
    }
}

fn write_text(path: &Path, text: &str) -> anyhow::Result<()> {
    gb_core::write_atomic(path, text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}

fn write_table(
    out: &Path,
    stem: &str,
    title: &str,
    rows: &[(String, &RunOutcome)],
) -> anyhow::Result<String> {
    let (md, js) = ablate::table(title, rows);
    write_text(&out.join(format!("{stem}.md")), &md)?;
    write_text(
        &out.join(format!("{stem}.json")),
        &(serde_json::to_string_pretty(&js)? + "\n"),
    )?;
    Ok(md)
}

/// Runs the command.
pub fn run(args: Args) -> anyhow::Result<()> {
    if !args.scene.is_dir() {
        bail!("--scene {}: not a folder", args.scene.display());
    }
    let methods = grid(args.grid.methods.as_deref());
    if methods.is_empty() {
        bail!("--methods: empty list");
    }
    let configs: Vec<MethodConfig> = methods
        .iter()
        .map(|m| MethodConfig::load(m).with_context(|| format!("--methods: {m}")))
        .collect::<anyhow::Result<_>>()?;
    let sweep_w3: Vec<f64> = match &args.w3 {
        Some(list) => list.clone(),
        None if methods.iter().any(|m| m == "csd") => DEFAULT_W3.to_vec(),
        None => Vec::new(),
    };
    let csd = MethodConfig::load("csd")?;
    let mut to_check = configs.clone();
    if !sweep_w3.is_empty() {
        to_check.push(csd.clone());
    }
    check(&args, &to_check)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;

    let total = Instant::now();
    let mut runs: Vec<RunOutcome> = Vec::new();
    let mut baseline: Option<PathBuf> = None;
    for m in &configs {
        let r = run_one(
            &args,
            &m.name,
            &m.name,
            &m.name,
            m.use_lora,
            baseline.clone(),
        );
        if m.name == "none" && r.result.is_ok() {
            baseline = Some(args.out.join("none"));
        }
        runs.push(r);
    }

    // the w3 sweep: csd with w3 on both modalities
    let mut sweep: Vec<(f64, RunOutcome)> = Vec::new();
    let csd_w3 = csd.rgb.w3.map(f64::from);
    for &w3 in &sweep_w3 {
        let reuse = runs
            .iter()
            .find(|r| r.method == "csd")
            .filter(|_| csd_w3 == Some(w3) && csd.normal.w3.map(f64::from) == Some(w3));
        if let Some(r) = reuse {
            sweep.push((w3, r.clone()));
            continue;
        }
        let name = format!("csd-w3={w3}");
        let mut m = csd.clone();
        m.name = name.clone();
        m.description = format!("CSD with w3 = {w3} on RGB and normal maps (w3 sweep)");
        m.rgb.w3 = Some(w3 as f32);
        m.normal.w3 = Some(w3 as f32);
        let file = args.out.join(format!("{name}.toml"));
        write_text(&file, &toml::to_string(&m)?)?;
        let mut r = run_one(
            &args,
            &name,
            &file.display().to_string(),
            &name,
            true,
            baseline.clone(),
        );
        r.method = name;
        sweep.push((w3, r));
    }

    // the tables
    let find = |m: &str| runs.iter().find(|r| r.method == m);
    let ran: BTreeSet<&str> = runs.iter().map(|r| r.method.as_str()).collect();
    let mut baseline_rows: Vec<(String, &RunOutcome)> = BASELINE_ROWS
        .iter()
        .filter_map(|(label, m)| find(m).map(|r| (label.to_string(), r)))
        .collect();
    for r in &runs {
        let in_tables = BASELINE_ROWS
            .iter()
            .chain(ABLATION_ROWS)
            .any(|(_, m)| *m == r.method);
        if !in_tables {
            baseline_rows.push((r.method.clone(), r));
        }
    }
    let ablation_rows: Vec<(String, &RunOutcome)> = ABLATION_ROWS
        .iter()
        .filter_map(|(label, m)| find(m).map(|r| (label.to_string(), r)))
        .collect();
    let scene = args.scene.display().to_string();
    let mut summary = String::new();
    let md = write_table(
        &args.out,
        "baselines",
        &format!("Baseline comparison on {scene}"),
        &baseline_rows,
    )?;
    summary.push_str(&md);
    let md = write_table(
        &args.out,
        "ablation",
        &format!("Ablation (origin / +LoRA / +BSD / +LoRA+BSD) on {scene}"),
        &ablation_rows,
    )?;
    summary.push_str(&md);
    let mut missing: Vec<&str> = ABLATION_ROWS
        .iter()
        .map(|(_, m)| *m)
        .filter(|m| !ran.contains(m))
        .collect();
    missing.dedup();
    if !missing.is_empty() {
        tracing::info!(
            ?missing,
            "ablation rows left out (methods not in --methods)"
        );
    }
    if sweep.is_empty() {
        let text =
            "## CSD w3 sweep\n\nNot run: csd is not among --methods and no --w3 was given.\n";
        write_text(&args.out.join("w3_sweep.md"), text)?;
        write_text(
            &args.out.join("w3_sweep.json"),
            &(serde_json::to_string_pretty(
                &json!({"title": "CSD w3 sweep", "rows": [], "note": "not run"}),
            )? + "\n"),
        )?;
        summary.push_str(text);
    } else {
        let rows: Vec<(String, &RunOutcome)> = sweep
            .iter()
            .map(|(w3, r)| (format!("w3 = {w3}"), r))
            .collect();
        let mut md = write_table(
            &args.out,
            "w3_sweep",
            &format!("CSD w3 sweep on {scene} (w1, w2 of csd.toml; w3 = 0 is BSD)"),
            &rows,
        )?;
        let pairs: Vec<(f64, &RunOutcome)> = sweep.iter().map(|(w, r)| (*w, r)).collect();
        for (stem, chart) in ablate::w3_charts(&pairs) {
            write_text(&args.out.join(format!("{stem}.svg")), &chart.to_svg())?;
            md.push_str(&format!("\n![{}]({stem}.svg)\n", chart.title));
        }
        write_text(&args.out.join("w3_sweep.md"), &md)?;
        summary.push_str(&md);
    }
    println!("{summary}");
    println!(
        "ablate: {} run(s) in {:.1} s; tables in {}",
        runs.len()
            + sweep
                .iter()
                .filter(|(_, r)| r.method.starts_with("csd-w3"))
                .count(),
        total.elapsed().as_secs_f64(),
        args.out.display()
    );
    let failed: Vec<&str> = runs
        .iter()
        .chain(sweep.iter().map(|(_, r)| r))
        .filter(|r| r.result.is_err())
        .map(|r| r.method.as_str())
        .collect();
    if !failed.is_empty() {
        bail!(
            "{} run(s) failed: {} (see the tables in {})",
            failed.len(),
            failed.join(", "),
            args.out.display()
        );
    }
    Ok(())
}
