//! The tables of a method grid ([`crate`] runs it; this module turns the runs'
//! [`RunSummary`]s into the paper's two tables and the w3 sweep):
//!
//! - **baselines**: rows [`BASELINE_ROWS`] (no prior, SPIn-NeRF-style SDS, MVIP-NeRF, CSD,
//!   GB-NeRF, and this project's visibility-aware GB-NeRF);
//! - **ablation**: rows [`ABLATION_ROWS`]: the origin (MVIP-NeRF-like SDS on RGB and
//!   normals, no LoRA), +LoRA (`sds-lora`), +BSD (`bsd`), +LoRA+BSD (`gb-nerf`);
//! - **w3 sweep**: `csd` with w3 in a list (default [`DEFAULT_W3`]).
//!
//! Columns ([`COLUMNS`]): masked-box SSIM, masked-box ST-LPIPS (shown when at least one row
//! has it; otherwise the reason is printed under the table), masked-box D-PSNR as defined and
//! on the true scale (gb-eval's `d_psnr_true`), masked-box and full-image PSNR, training time.
//! Values come from each run's `metrics.json` `eval` block (gb-eval keys); an unavailable
//! value is `n/a` with its reason in the JSON. A scene without ground truth gets the
//! no-reference columns instead ([`NO_REFERENCE_COLUMNS`]: BRISQUE of the mask box and of the
//! whole render, on the masked training views).

use serde_json::{json, Value};

use gb_inpaint::run::RunSummary;
use gb_report::svg::{LineChart, Series};

/// Baseline comparison: (row label, method).
pub const BASELINE_ROWS: &[(&str, &str)] = &[
    ("NeRF without prior", "none"),
    ("SPIn-NeRF-style SDS (RGB)", "spin-nerf-sds"),
    ("MVIP-NeRF (SDS, RGB + normals)", "mvip-nerf"),
    ("CSD", "csd"),
    ("GB-NeRF (ours)", "gb-nerf"),
    ("GB-NeRF, unseen pixels only", "gb-nerf-unseen"),
];

/// Ablation: (row label, method).
pub const ABLATION_ROWS: &[(&str, &str)] = &[
    ("origin (SDS, no LoRA)", "mvip-nerf"),
    ("+LoRA", "sds-lora"),
    ("+BSD", "bsd"),
    ("+LoRA +BSD (GB-NeRF)", "gb-nerf"),
];

/// Default w3 values of the sweep (CSD's unconditional weight; 0 is BSD).
pub const DEFAULT_W3: &[f64] = &[-1.0, -0.5, 0.0, 0.5, 1.0];

/// One column: key in the run's `eval` block, title, whether higher is better.
pub const COLUMNS: &[(&str, &str, bool)] = &[
    ("ssim_bbox", "SSIM (mask box)", true),
    ("lpips_bbox", "ST-LPIPS (mask box)", false),
    ("d_psnr_bbox", "D-PSNR (mask box)", true),
    ("d_psnr_true_bbox", "D-PSNR, true scale (mask box)", true),
    ("psnr_bbox", "PSNR (mask box)", true),
    ("psnr", "PSNR (full)", true),
];

/// The outcome of one run of the grid.
#[derive(Debug, Clone)]
pub struct RunOutcome {
    /// Row label.
    pub label: String,
    /// Method name (or `csd-w3=X` for the sweep).
    pub method: String,
    /// Output folder, relative to the ablation's folder.
    pub dir: String,
    /// The run's summary (`metrics.json`), or the error that stopped it.
    pub result: Result<RunSummary, String>,
    /// Wall time of the whole run (training, renders, metrics, report).
    pub seconds: f64,
}

fn fmt(v: f64) -> String {
    if v.is_infinite() {
        "inf".into()
    } else if v.abs() >= 10.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.4}")
    }
}

/// The columns of a scene without ground truth (a real capture without test views), whose
/// runs are scored on their masked training views by the no-reference metric only.
pub const NO_REFERENCE_COLUMNS: &[(&str, &str, bool)] = &[
    ("brisque_bbox", "BRISQUE (mask box)", false),
    ("brisque", "BRISQUE (full)", false),
];

/// The columns shown: ST-LPIPS only when a run has it; without ground truth (no run has a
/// PSNR), the no-reference columns instead.
fn shown_columns(runs: &[&RunOutcome]) -> Vec<(&'static str, &'static str, bool)> {
    let any_has = |k: &str| {
        runs.iter()
            .any(|r| r.result.as_ref().is_ok_and(|m| m.eval_value(k).is_ok()))
    };
    if !any_has("psnr") && NO_REFERENCE_COLUMNS.iter().any(|(k, _, _)| any_has(k)) {
        return NO_REFERENCE_COLUMNS.to_vec();
    }
    COLUMNS
        .iter()
        .copied()
        .filter(|(k, _, _)| *k != "lpips_bbox" || any_has(k))
        .collect()
}

/// A table: markdown and JSON, over `rows` = (label, run).
pub fn table(title: &str, rows: &[(String, &RunOutcome)]) -> (String, Value) {
    let runs: Vec<&RunOutcome> = rows.iter().map(|(_, r)| *r).collect();
    let cols = shown_columns(&runs);
    let mut md = format!("## {title}\n\n| method | run |");
    for (_, t, hi) in &cols {
        md.push_str(&format!(" {t} {} |", if *hi { "↑" } else { "↓" }));
    }
    md.push_str(" steps | train s | s / step |\n|---|---|");
    md.push_str(&"---:|".repeat(cols.len() + 3));
    md.push('\n');
    let mut json_rows = Vec::new();
    let mut reasons: Vec<String> = Vec::new();
    for (label, r) in rows {
        md.push_str(&format!("| {label} | `{}` |", r.dir));
        let mut jr =
            json!({"label": label, "method": r.method, "dir": r.dir, "seconds": r.seconds});
        match &r.result {
            Ok(m) => {
                for (k, _, _) in &cols {
                    match m.eval_value(k) {
                        Ok(v) => {
                            md.push_str(&format!(" {} |", fmt(v)));
                            jr[*k] = gb_eval::report::json_number(v);
                        }
                        Err(why) => {
                            md.push_str(" n/a |");
                            jr[*k] = Value::Null;
                            reasons.push(format!("- {label}: `{k}` unavailable: {why}"));
                        }
                    }
                }
                let steps = m.steps as f64;
                let secs = m.train_seconds_this_run;
                md.push_str(&format!(
                    " {} | {:.1} | {:.3} |\n",
                    steps,
                    secs,
                    secs / steps.max(1.0)
                ));
                jr["steps"] = json!(steps);
                jr["train_seconds"] = json!(secs);
                jr["metrics"] = m.eval.clone();
            }
            Err(e) => {
                md.push_str(&" failed |".repeat(cols.len() + 3));
                md.push('\n');
                jr["error"] = json!(e);
                reasons.push(format!("- {label}: the run failed: {e}"));
            }
        }
        json_rows.push(jr);
    }
    if !cols.iter().any(|(k, _, _)| *k == "lpips_bbox") {
        let why = runs
            .iter()
            .find_map(|r| {
                r.result
                    .as_ref()
                    .ok()
                    .and_then(|m| m.eval_value("lpips_bbox").err())
            })
            .unwrap_or_else(|| "no run finished".into());
        reasons.insert(0, format!("- ST-LPIPS column omitted: {why}"));
    }
    reasons.dedup();
    if !reasons.is_empty() {
        md.push('\n');
        md.push_str(&reasons.join("\n"));
        md.push('\n');
    }
    md.push_str(
        "\nMask box: the bounding box of the test view's object mask (gb-eval `_bbox` keys); \
         D-PSNR: PSNR of the 8-bit max-normalised disparity; train s: this run's training wall \
         time.\n",
    );
    let columns: Vec<Value> = cols
        .iter()
        .map(|(k, t, hi)| json!({"key": k, "title": t, "higher_is_better": hi}))
        .collect();
    (
        md,
        json!({"title": title, "columns": columns, "rows": json_rows}),
    )
}

/// The w3 sweep figures: masked-box SSIM and ST-LPIPS (one scale), and masked-box PSNR and
/// D-PSNR (dB), against w3.
pub fn w3_charts(runs: &[(f64, &RunOutcome)]) -> Vec<(String, LineChart)> {
    let series = |key: &str| -> Vec<(f64, f64)> {
        runs.iter()
            .map(|(w3, r)| {
                let v = r
                    .result
                    .as_ref()
                    .ok()
                    .and_then(|m| m.eval_value(key).ok())
                    .unwrap_or(f64::NAN);
                (*w3, v)
            })
            .collect()
    };
    let mut a = LineChart::new("CSD w3 sweep: masked-box similarity", "w3", "value");
    a.push(Series::new("SSIM (mask box) ↑", series("ssim_bbox")).with_markers());
    a.push(Series::new("ST-LPIPS (mask box) ↓", series("lpips_bbox")).with_markers());
    let mut b = LineChart::new("CSD w3 sweep: masked-box PSNR", "w3", "dB");
    b.push(Series::new("PSNR (mask box) ↑", series("psnr_bbox")).with_markers());
    b.push(Series::new("D-PSNR (mask box) ↑", series("d_psnr_bbox")).with_markers());
    vec![("w3_sweep".into(), a), ("w3_sweep_psnr".into(), b)]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(method: &str, ssim: f64, lpips: Option<f64>) -> RunOutcome {
        let mut eval = json!({"ssim_bbox": ssim, "psnr_bbox": 20.0, "psnr": 25.0, "d_psnr_bbox": 15.5, "d_psnr_true_bbox": 16.25, "unavailable": {}});
        match lpips {
            Some(v) => eval["lpips_bbox"] = json!(v),
            None => {
                eval["lpips_bbox"] = Value::Null;
                eval["unavailable"]["lpips_bbox"] = json!("no weights");
            }
        }
        RunOutcome {
            label: method.into(),
            method: method.into(),
            dir: method.into(),
            result: Ok(RunSummary {
                eval,
                steps: 4,
                train_seconds_this_run: 2.0,
                ..RunSummary::default()
            }),
            seconds: 3.0,
        }
    }

    #[test]
    fn tables_show_values_reasons_and_failures() {
        let (a, b) = (run("none", 0.5, None), run("gb-nerf", 0.75, None));
        let failed = RunOutcome {
            result: Err("boom".into()),
            ..run("csd", 0.0, None)
        };
        let rows = vec![
            ("none".to_string(), &a),
            ("ours".to_string(), &b),
            ("csd".to_string(), &failed),
        ];
        let (md, js) = table("Baselines", &rows);
        assert!(
            md.contains(
                "| none | `none` | 0.5000 | 15.50 | 16.25 | 20.00 | 25.00 | 4 | 2.0 | 0.500 |"
            ),
            "{md}"
        );
        assert!(md.contains("ST-LPIPS column omitted: no weights"), "{md}");
        assert!(md.contains("csd: the run failed: boom"));
        assert_eq!(js["rows"][1]["ssim_bbox"], 0.75);
        assert_eq!(js["rows"][2]["error"], "boom");
        assert_eq!(js["columns"].as_array().unwrap().len(), 5);

        let c = run("x", 0.6, Some(0.25));
        let (md, js) = table("T", &[("x".to_string(), &c)]);
        assert!(
            md.contains("ST-LPIPS (mask box) ↓") && md.contains("| 0.2500 |"),
            "{md}"
        );
        assert_eq!(js["columns"].as_array().unwrap().len(), 6);

        // a scene without ground truth: the no-reference columns
        let mut real = run("none", 0.5, None);
        if let Ok(m) = &mut real.result {
            m.eval = json!({"psnr": null, "brisque": 41.5, "brisque_bbox": 55.25,
                "unavailable": {"psnr": "the scene has no test view with ground truth"}});
        }
        let (md, js) = table("Statue", &[("none".to_string(), &real)]);
        assert!(md.contains("| none | `none` | 55.25 | 41.50 | 4 |"), "{md}");
        assert_eq!(js["columns"][0]["key"], "brisque_bbox");
        assert_eq!(js["columns"].as_array().unwrap().len(), 2);

        let charts = w3_charts(&[(-1.0, &a), (0.0, &b)]);
        assert_eq!(charts[0].1.series[0].points, vec![(-1.0, 0.5), (0.0, 0.75)]);
        assert!(charts[0].1.to_svg().contains("<circle"));
    }
}
