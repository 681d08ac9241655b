//! `cargo xtask-fuzz` (`gb-nerf fuzz` built with the `fuzz` feature): the reader properties of
//! `gb_tests::fuzz` (the ones `cargo test` runs with 64 cases) with many cases per reader,
//! recorded in `bench/results/fuzz-<date>.json`. Without the feature the command is one line
//! saying how to build it, so the installed binary carries no test code.

use std::path::PathBuf;

use anyhow::bail;

/// Arguments of `cargo xtask-fuzz`.
#[derive(clap::Args)]
pub struct Args {
    /// Cases per reader.
    #[arg(long, default_value_t = 10_000)]
    pub cases: u32,
    /// Only the readers whose name contains this text (`npy`, `toml/method`, ...).
    #[arg(long)]
    pub only: Option<String>,
    /// RNG seed (default: `GB_FUZZ_SEED`, else from the clock; recorded in the report).
    #[arg(long)]
    pub seed: Option<u64>,
    /// The report (default: `bench/results/fuzz-<YYYY-MM-DD>.json`).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Without the `fuzz` feature: the one line that says how to get the command.
#[cfg(not(feature = "fuzz"))]
pub fn run(_args: Args) -> anyhow::Result<()> {
    bail!(
        "fuzz: this gb-nerf was built without the `fuzz` feature (test code); run \
         `cargo xtask-fuzz` in the repository (or build with `--features fuzz`)"
    )
}

/// Runs every reader's properties, writes the report, and fails when any property failed.
#[cfg(feature = "fuzz")]
pub fn run(args: Args) -> anyhow::Result<()> {
    use gb_bench::report::{hostname, machine_description, today, write_report};
    let seed = args.seed.unwrap_or_else(gb_tests::fuzz::seed_from_env);
    let readers: Vec<_> = gb_tests::fuzz::readers()
        .into_iter()
        .filter(|r| args.only.as_deref().is_none_or(|o| r.name.contains(o)))
        .collect();
    if readers.is_empty() {
        bail!(
            "--only {:?} matches no reader",
            args.only.unwrap_or_default()
        );
    }
    let mut rows = Vec::new();
    let mut failed = Vec::new();
    for reader in &readers {
        let r = gb_tests::fuzz::run_reader(reader, args.cases, seed);
        tracing::info!(
            reader = r.reader,
            executed = r.executed,
            failures = r.failures,
            "{:.1} s",
            r.seconds
        );
        if let Some(f) = &r.failure {
            tracing::error!(reader = r.reader, "{f}");
            failed.push(r.reader);
        }
        rows.push(serde_json::json!({
            "reader": r.reader,
            "entry_point": r.entry_point,
            "cases": r.cases,
            "executed": r.executed,
            "failures": r.failures,
            "seconds": (r.seconds * 100.0).round() / 100.0,
            "failure": r.failure,
        }));
    }
    let date = today();
    let mut machine = machine_description();
    machine["hostname"] = hostname().into();
    let doc = serde_json::json!({
        "benchmark": "fuzz: property tests of every reader of untrusted files (proptest)",
        "date": date,
        "machine": machine,
        "profile": if cfg!(debug_assertions) { "dev (overflow checks on)" } else { "release" },
        "cases_per_reader": args.cases,
        "seed": seed,
        "total_seconds": rows.iter().filter_map(|r| r["seconds"].as_f64()).sum::<f64>(),
        "readers": rows,
    });
    let out = args
        .out
        .unwrap_or_else(|| PathBuf::from(format!("bench/results/fuzz-{date}.json")));
    let dir = out.parent().unwrap_or(std::path::Path::new("."));
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| format!("fuzz-{date}.json"));
    write_report(dir, &name, &doc)?;
    if !failed.is_empty() {
        bail!("properties failed for: {}", failed.join(", "));
    }
    Ok(())
}
