//! `cargo xtask fuzz`: the reader properties of `gb_tests::fuzz` (the ones `cargo test` runs
//! with 64 cases) with many cases per reader, recorded in `bench/results/fuzz-<date>.json`.

use std::path::PathBuf;

use anyhow::bail;

use super::bench::{machine_description, write_report};

/// Arguments of `cargo xtask fuzz`.
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

/// Runs every reader's properties, writes the report, and fails when any property failed.
pub fn run(args: Args) -> anyhow::Result<()> {
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

/// This machine's host name (`/proc/sys/kernel/hostname`), or `unknown`.
fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::fs::read_to_string("/etc/hostname"))
        .map(|s| s.trim().to_string())
        .unwrap_or_else(|_| "unknown".into())
}

/// Today's UTC date as `YYYY-MM-DD` (civil date from days since 1970, H. Hinnant's method).
fn today() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let (y, m, d) = civil_from_days((secs / 86_400) as i64);
    format!("{y:04}-{m:02}-{d:02}")
}

fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

#[cfg(test)]
mod tests {
    use super::civil_from_days;

    #[test]
    fn civil_dates() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(19_723), (2024, 1, 1));
        assert_eq!(civil_from_days(19_782), (2024, 2, 29));
        assert_eq!(civil_from_days(-1), (1969, 12, 31));
    }
}
