//! `cargo xtask bench trade`: the speed/accuracy trade of the whole pipeline. Each preset of
//! `--presets` (default `fast,balanced`) runs the quality benchmark's method grid
//! ([`crate::quality::run_scene`]; default methods `none` and the recommended
//! `gb-nerf-unseen`) on one procedural scene and its `--seeds`, into `--work/<preset>/`. Each
//! (preset, method) pair becomes one point: the mask-box metrics (mean and sample standard
//! deviation over the seeds) against the wall time of the whole run (training, test renders
//! and scoring). Writes `bench/results/trade-<scene>-<date>.json` (the points, the machine and
//! every preset's quality report) and `trade-<scene>-<date>.svg` (one panel per metric, one
//! line per method through the presets in order), and prints the table in Markdown.
//!
//! The reference measured in the same run is the `none` row of each preset: the guided
//! method's cost and gain are read against it. `paper` (10k steps) is about 37 h a guided run
//! on 2 CPU cores; give it to `--presets` on a machine that has the time.

use std::path::PathBuf;

use anyhow::Context;
use gb_core::BackendKind;
use gb_nerf::scene::procedural::SceneName;
use gb_nerf::train::DepthSupervision;
use gb_report::svg::{self, LineChart, Series};
use serde_json::{json, Value};

/// Arguments of `cargo xtask bench trade`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The procedural scene (stairs, fence, alcove).
    #[arg(long, default_value = "alcove")]
    pub scene: SceneName,
    /// Comma-separated presets (names or TOML files), in order of cost.
    #[arg(long, value_delimiter = ',', default_value = "fast,balanced")]
    pub presets: Vec<String>,
    /// Comma-separated methods; `none` is the reference and is always run.
    #[arg(long, value_delimiter = ',', default_value = "none,gb-nerf-unseen")]
    pub methods: Vec<String>,
    /// Comma-separated seeds, each the scene's and the training's (default: 2, a reporting
    /// seed on which no choice was made).
    #[arg(long, value_delimiter = ',', default_value = "2")]
    pub seeds: Vec<u64>,
    /// The diffusion prior of the guided methods: tiny (default), a folder or a hub id.
    #[arg(long)]
    pub prior: Option<String>,
    /// Compute backend: ndarray, flex or wgpu.
    #[arg(long, value_enum)]
    pub device: Option<BackendKind>,
    /// Depth supervision of every run: sparse (the presets' default), dense or none.
    #[arg(long)]
    pub depth: Option<DepthSupervision>,
    /// Folder of the runs (one sub-folder per preset).
    #[arg(long, default_value = "out/bench-trade")]
    pub work: PathBuf,
    /// Reuse the runs of `--work` that finished instead of resuming each one (for a job cut
    /// short: run again with the same flags). Their wall times are those of their first run.
    #[arg(long)]
    pub reuse_finished: bool,
    /// Output folder of the JSON and the SVG.
    #[arg(long, default_value = "bench/results")]
    pub out: PathBuf,
}

/// The mask-box metrics of the trade, with their direction: (key, title, higher is better).
const METRICS: [(&str, &str, bool); 4] = [
    ("ssim_bbox", "SSIM (mask box)", true),
    ("lpips_bbox", "ST-LPIPS (mask box)", false),
    ("d_psnr_bbox", "D-PSNR (mask box), dB", true),
    ("psnr_bbox", "PSNR (mask box), dB", true),
];

/// The points of the trade from each preset's quality report (`(preset, report)` in order):
/// one per row of the report's baselines and ablation tables (a method in both counted
/// once), with the preset, the method, the seeds, the wall and training seconds and every
/// metric of [`METRICS`] (mean, `_std`), in preset order.
fn trade_points(reports: &[(String, Value)]) -> Vec<Value> {
    let mut points = Vec::new();
    for (preset, report) in reports {
        let mut seen = Vec::new();
        for table in ["baselines", "ablation"] {
            for row in report[table]["rows"].as_array().into_iter().flatten() {
                // a row without a method is no method's point
                let Some(method) = row["method"].as_str() else {
                    continue;
                };
                if seen.contains(&method) {
                    continue;
                }
                seen.push(method);
                let mut p = json!({
                    "preset": preset,
                    "method": method,
                    "label": row["label"],
                    "seeds": row["seeds"],
                    "seconds": row["seconds"],
                    "seconds_std": row["seconds_std"],
                    "train_seconds": row["train_seconds"],
                });
                for (key, _, _) in METRICS {
                    p[key] = row[key].clone();
                    p[format!("{key}_std")] = row[format!("{key}_std")].clone();
                }
                points.push(p);
            }
        }
    }
    points
}

/// The distinct string values of `key` over `points`, in order of first appearance.
fn distinct<'a>(points: &'a [Value], key: &str) -> Vec<&'a str> {
    let mut out: Vec<&str> = Vec::new();
    for v in points.iter().filter_map(|p| p[key].as_str()) {
        if !out.contains(&v) {
            out.push(v);
        }
    }
    out
}

/// One chart per metric of [`METRICS`]: for each method, its points in preset order, the
/// metric against the wall time of a run in minutes; the x label names the presets in order.
fn trade_charts(points: &[Value], scene: &str) -> Vec<LineChart> {
    let (methods, presets) = (distinct(points, "method"), distinct(points, "preset"));
    let x_label = format!("wall time per run, min (presets: {})", presets.join(" → "));
    METRICS
        .iter()
        .map(|(key, title, higher)| {
            let arrow = if *higher { "↑" } else { "↓" };
            let mut chart =
                LineChart::new(format!("{scene}: {title} {arrow}"), x_label.clone(), *title);
            for m in &methods {
                let xy: Vec<(f64, f64)> = points
                    .iter()
                    .filter(|p| p["method"] == *m)
                    .map(|p| {
                        (
                            p["seconds"].as_f64().unwrap_or(f64::NAN) / 60.0,
                            p[*key].as_f64().unwrap_or(f64::NAN),
                        )
                    })
                    .collect();
                chart.push(Series::new(*m, xy).with_markers());
            }
            chart
        })
        .collect()
}

/// The trade as a Markdown table: one row per point, each metric `mean ± sd` (the mean alone
/// for one seed).
fn markdown(points: &[Value]) -> String {
    let mut out = String::from("| preset | method | wall per run (min) |");
    for (_, title, higher) in METRICS {
        out.push_str(&format!(" {title} {} |", if higher { "↑" } else { "↓" }));
    }
    out.push_str("\n|---|---|---:|");
    out.push_str(&"---:|".repeat(METRICS.len()));
    out.push('\n');
    let cell = |v: &Value, sd: &Value, digits: usize, spread: bool| match v.as_f64() {
        Some(x) => match sd.as_f64().filter(|_| spread) {
            Some(s) => format!("{x:.digits$} ± {s:.digits$}"),
            None => format!("{x:.digits$}"),
        },
        None => "n/a".into(),
    };
    for p in points {
        // a spread over one seed is no spread
        let spread = p["seeds"].as_u64().is_none_or(|n| n > 1);
        let minutes = |k: &str| json!(p[k].as_f64().map(|s| s / 60.0));
        out.push_str(&format!(
            "| {} | {} | {} |",
            p["preset"].as_str().unwrap_or("n/a"),
            p["method"].as_str().unwrap_or("n/a"),
            cell(&minutes("seconds"), &minutes("seconds_std"), 1, spread)
        ));
        for (key, _, _) in METRICS {
            let digits = if key.contains("psnr") { 2 } else { 3 };
            out.push_str(&format!(
                " {} |",
                cell(&p[key], &p[format!("{key}_std")], digits, spread)
            ));
        }
        out.push('\n');
    }
    out
}

/// A preset's name in the trade (its folder, its rows): the name given, or a TOML file's stem.
fn preset_label(preset: &str) -> String {
    let path = std::path::Path::new(preset);
    match (path.extension(), path.file_stem()) {
        (Some(ext), Some(stem)) if ext == "toml" => stem.to_string_lossy().into_owned(),
        _ => preset.to_string(),
    }
}

/// Runs the benchmark.
pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(
        !args.presets.is_empty(),
        "--presets: give at least one preset"
    );
    let mut methods = args.methods.clone();
    if !methods.iter().any(|m| m == "none") {
        methods.insert(0, "none".into());
    }
    let labels: Vec<String> = args.presets.iter().map(|p| preset_label(p)).collect();
    for (i, label) in labels.iter().enumerate() {
        anyhow::ensure!(
            !labels[..i].contains(label),
            "--presets: two presets are named {label}; give each its own name"
        );
    }
    let started = std::time::Instant::now();
    let mut reports = Vec::new();
    for preset in &args.presets {
        let grid = crate::GridArgs {
            methods: Some(methods.clone()),
            preset: preset.clone(),
            prior: args.prior.clone(),
            steps: None,
            device: args.device,
            depth: args.depth,
            probe: false,
        };
        let label = preset_label(preset);
        let report = crate::quality::run_scene(
            args.scene,
            &grid,
            Some(&args.seeds),
            &args.work.join(&label),
            args.reuse_finished,
            crate::quality::ExtraRows::default(),
        )
        .with_context(|| format!("preset {preset}"))?;
        reports.push((label, report));
    }
    let points = trade_points(&reports);
    let scene = args.scene.to_string();
    let stem = format!("trade-{scene}-{}", super::today());
    let svg_path = args.out.join(format!("{stem}.svg"));
    gb_core::write_atomic(
        &svg_path,
        svg::tile(&trade_charts(&points, &scene), 2).as_bytes(),
    )
    .with_context(|| format!("writing {}", svg_path.display()))?;
    let errors: Vec<String> = reports
        .iter()
        .filter_map(|(p, r)| r["error"].as_str().map(|e| format!("{p}: {e}")))
        .collect();
    let report = json!({
        "benchmark": "trade",
        "machine": super::machine_description(),
        "scene": scene,
        "seeds": args.seeds,
        "presets": args.presets,
        "preset_labels": reports.iter().map(|(p, _)| p.clone()).collect::<Vec<_>>(),
        "methods": methods,
        "reference": "the none row of each preset, run in the same job",
        "wall_seconds": started.elapsed().as_secs_f64(),
        "points": points,
        "figure": svg_path.display().to_string(),
        "quality": reports.iter().map(|(p, r)| (p.clone(), r.clone())).collect::<serde_json::Map<_, _>>(),
        "error": if errors.is_empty() { Value::Null } else { json!(errors.join("; ")) },
    });
    let path = args.out.join(format!("{stem}.json"));
    gb_core::write_atomic(&path, &serde_json::to_vec_pretty(&report)?)
        .with_context(|| format!("writing {}", path.display()))?;
    println!("{}", markdown(&points));
    println!("wrote {} and {}", path.display(), svg_path.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(none_ssim: f64, unseen_ssim: f64, none_s: f64, unseen_s: f64) -> Value {
        let row = |label: &str, method: &str, ssim: f64, s: f64| {
            json!({"label": label, "method": method, "seeds": 3, "ssim_bbox": ssim,
                   "ssim_bbox_std": 0.0, "lpips_bbox": 0.3, "d_psnr_bbox": null,
                   "psnr_bbox": 20.0, "seconds": s, "seconds_std": 0.0, "train_seconds": s / 2.0})
        };
        json!({
            "baselines": {"rows": [row("none", "none", none_ssim, none_s),
                                   row("unseen", "gb-nerf-unseen", unseen_ssim, unseen_s)]},
            "ablation": {"rows": [row("unseen", "gb-nerf-unseen", 0.0, 0.0)]},
        })
    }

    fn two_presets() -> Vec<Value> {
        trade_points(&[
            ("fast".into(), report(0.31, 0.21, 120.0, 600.0)),
            ("balanced".into(), report(0.40, 0.35, 1200.0, 3600.0)),
        ])
    }

    #[test]
    fn each_preset_and_method_is_one_point_in_preset_order() {
        let points = two_presets();
        let keys: Vec<(String, String)> = points
            .iter()
            .map(|p| (p["preset"].to_string(), p["method"].to_string()))
            .collect();
        assert_eq!(
            keys,
            [
                ("\"fast\"", "\"none\""),
                ("\"fast\"", "\"gb-nerf-unseen\""),
                ("\"balanced\"", "\"none\""),
                ("\"balanced\"", "\"gb-nerf-unseen\""),
            ]
            .map(|(a, b)| (a.to_string(), b.to_string()))
        );
        // the ablation table's repeat of a method is not a second point
        assert_eq!(points[1]["ssim_bbox"], json!(0.21));
        assert_eq!(points[3]["seconds"], json!(3600.0));
        assert_eq!(points[2]["train_seconds"], json!(600.0));
        assert_eq!(points[0]["d_psnr_bbox"], Value::Null);
    }

    #[test]
    fn charts_draw_each_method_through_its_presets_in_minutes() {
        let charts = trade_charts(&two_presets(), "alcove");
        assert_eq!(charts.len(), METRICS.len());
        let ssim = &charts[0];
        assert_eq!(ssim.title, "alcove: SSIM (mask box) ↑");
        assert_eq!(ssim.series.len(), 2);
        assert_eq!(ssim.series[0].name, "none");
        assert_eq!(
            ssim.x_label,
            "wall time per run, min (presets: fast → balanced)"
        );
        assert_eq!(ssim.series[0].points, vec![(2.0, 0.31), (20.0, 0.40)]);
        assert_eq!(ssim.series[1].points, vec![(10.0, 0.21), (60.0, 0.35)]);
        assert_eq!(charts[1].title, "alcove: ST-LPIPS (mask box) ↓");
        // a metric without a value is not drawn
        assert!(charts[2].series[0].points.iter().all(|p| p.1.is_nan()));
    }

    #[test]
    fn a_preset_file_is_named_by_its_stem() {
        assert_eq!(preset_label("balanced"), "balanced");
        assert_eq!(preset_label("my-presets/my-fast.toml"), "my-fast");
        assert_eq!(preset_label("configs/presets/paper.toml"), "paper");
    }

    #[test]
    fn the_markdown_table_has_a_row_per_point() {
        let md = markdown(&two_presets());
        let lines: Vec<&str> = md.lines().collect();
        assert_eq!(lines.len(), 6, "{md}");
        assert_eq!(
            lines[3],
            "| fast | gb-nerf-unseen | 10.0 ± 0.0 | 0.210 ± 0.000 | 0.300 | n/a | 20.00 |"
        );
        let mut one_seed = two_presets();
        one_seed[1]["seeds"] = json!(1);
        assert_eq!(
            markdown(&one_seed).lines().nth(3).unwrap(),
            "| fast | gb-nerf-unseen | 10.0 | 0.210 | 0.300 | n/a | 20.00 |"
        );
    }
}
