//! The tables of `bench quality`: the mean over seeds, the comparison against `none`, the
//! wins per seed, and the choices of the `"auto"` runs.

use std::path::Path;

use anyhow::Context;
use serde_json::{json, Value};

/// For each row, whether it beats the `none` row on each column.
pub(super) fn vs_none(table: &Value) -> Value {
    let cols = table["columns"].as_array().cloned().unwrap_or_default();
    let rows = table["rows"].as_array().cloned().unwrap_or_default();
    let Some(none) = rows.iter().find(|r| r["method"] == "none") else {
        return Value::Null;
    };
    let mut out = serde_json::Map::new();
    for r in rows.iter().filter(|r| r["method"] != "none") {
        let mut m = serde_json::Map::new();
        for c in &cols {
            let key = c["key"].as_str().unwrap_or_default();
            let hi = c["higher_is_better"].as_bool().unwrap_or(true);
            if let (Some(a), Some(b)) = (r[key].as_f64(), none[key].as_f64()) {
                m.insert(key.into(), json!(if hi { a > b } else { a < b }));
            }
        }
        out.insert(r["label"].as_str().unwrap_or_default().into(), m.into());
    }
    out.into()
}

/// For each row, on how many tables (one per seed) it beats that table's `none` row, per
/// column: `{"label": {"key": {"wins": k, "of": n}}}`.
pub(super) fn wins_vs_none(tables: &[Value]) -> Value {
    let mut out: std::collections::BTreeMap<String, serde_json::Map<String, Value>> =
        Default::default();
    for t in tables {
        let Value::Object(per_row) = vs_none(t) else {
            continue;
        };
        for (label, cols) in per_row {
            let entry = out.entry(label).or_default();
            for (key, beats) in cols.as_object().into_iter().flatten() {
                let cell = entry
                    .entry(key.clone())
                    .or_insert_with(|| json!({"wins": 0, "of": 0}));
                let wins = cell["wins"].as_u64().unwrap_or(0) + u64::from(beats == &json!(true));
                let of = cell["of"].as_u64().unwrap_or(0) + 1;
                *cell = json!({"wins": wins, "of": of});
            }
        }
    }
    Value::Object(
        out.into_iter()
            .map(|(label, cols)| (label, Value::Object(cols)))
            .collect(),
    )
}

/// The mean of ablate tables of the same grid over seeds: each row (matched by label, in the
/// first table's order) gets, per column, the mean of the seeds that have a value, with
/// `<key>_std` (sample standard deviation, 0 for one value) and `<key>_values`; `seeds` says
/// how many tables had the row.
pub(super) fn mean_table(tables: &[Value]) -> Value {
    let Some(first) = tables.first() else {
        return Value::Null;
    };
    let columns = first["columns"].as_array().cloned().unwrap_or_default();
    let mut keys: Vec<String> = columns
        .iter()
        .filter_map(|c| c["key"].as_str().map(String::from))
        .collect();
    keys.extend(["seconds".to_string(), "train_seconds".to_string()]);
    let rows_of = |t: &Value| t["rows"].as_array().cloned().unwrap_or_default();
    let mut labels: Vec<String> = Vec::new();
    for t in tables {
        for r in rows_of(t) {
            let l = r["label"].as_str().unwrap_or_default().to_string();
            if !labels.contains(&l) {
                labels.push(l);
            }
        }
    }
    let mut rows = Vec::new();
    for label in labels {
        let found: Vec<Value> = tables
            .iter()
            .filter_map(|t| rows_of(t).into_iter().find(|r| r["label"] == *label))
            .collect();
        let mut row = json!({"label": label, "method": found[0]["method"], "seeds": found.len()});
        for key in &keys {
            let values: Vec<f64> = found.iter().filter_map(|r| r[key].as_f64()).collect();
            if values.is_empty() {
                row[key] = Value::Null;
                continue;
            }
            let n = values.len() as f64;
            let mean = values.iter().sum::<f64>() / n;
            let var = if values.len() > 1 {
                values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)
            } else {
                0.0
            };
            row[key] = json!(mean);
            row[format!("{key}_std")] = json!(var.sqrt());
            row[format!("{key}_values")] = json!(values);
        }
        let errors: Vec<&str> = found.iter().filter_map(|r| r["error"].as_str()).collect();
        if !errors.is_empty() {
            row["errors"] = json!(errors);
        }
        rows.push(row);
    }
    json!({
        "title": format!("{} (mean of {} seed(s))", first["title"].as_str().unwrap_or(""), tables.len()),
        "columns": columns,
        "rows": rows,
    })
}

/// The `auto` section (pseudo-hole, trials, scores, choice) of each run folder under `runs`
/// whose `metrics.json` has one, keyed by the folder's name, so that a report keeps the
/// weights each `"auto"` run chose after its scratch folder is gone. A folder without
/// `metrics.json` (a cell that did not finish) is left out; one that cannot be read or
/// parsed is an error naming it.
pub(super) fn auto_choices(runs: &Path) -> anyhow::Result<Value> {
    let mut dirs = Vec::new();
    for entry in std::fs::read_dir(runs).with_context(|| format!("reading {}", runs.display()))? {
        let entry = entry.with_context(|| format!("reading {}", runs.display()))?;
        if entry.file_type().is_ok_and(|t| t.is_dir()) {
            dirs.push((
                entry.file_name().to_string_lossy().into_owned(),
                entry.path(),
            ));
        }
    }
    dirs.sort();
    let mut out = serde_json::Map::new();
    for (name, dir) in dirs {
        let path = dir.join("metrics.json");
        let text = match std::fs::read_to_string(&path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
        };
        let metrics: Value =
            serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        if metrics["auto"].is_object() {
            out.insert(name, metrics["auto"].clone());
        }
    }
    Ok(out.into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_choices_keep_each_auto_runs_choice_by_folder() {
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str, body: &str| {
            std::fs::create_dir_all(dir.path().join(name)).unwrap();
            std::fs::write(dir.path().join(name).join("metrics.json"), body).unwrap();
        };
        write("none", r#"{"ssim_bbox": 0.5, "auto": null}"#);
        write(
            "gb-nerf-auto",
            r#"{"auto": {"chosen": {"lambda_rgb": 1e-5}}}"#,
        );
        std::fs::create_dir_all(dir.path().join("unfinished")).unwrap();
        std::fs::write(dir.path().join("grid.toml"), "").unwrap();
        let choices = auto_choices(dir.path()).unwrap();
        let keys: Vec<&String> = choices.as_object().unwrap().keys().collect();
        assert_eq!(keys, ["gb-nerf-auto"]);
        assert_eq!(choices["gb-nerf-auto"]["chosen"]["lambda_rgb"], 1e-5);
        // a broken metrics.json and a missing runs folder are errors naming them
        write("broken", "{");
        let err = format!("{:#}", auto_choices(dir.path()).unwrap_err());
        assert!(err.contains("broken/metrics.json"), "{err}");
        let err = format!(
            "{:#}",
            auto_choices(&dir.path().join("absent")).unwrap_err()
        );
        assert!(err.contains("absent"), "{err}");
    }

    #[test]
    fn vs_none_compares_each_column_in_its_direction() {
        let table = json!({
            "columns": [
                {"key": "ssim_bbox", "higher_is_better": true},
                {"key": "lpips_bbox", "higher_is_better": false},
                {"key": "depth_psnr", "higher_is_better": true},
            ],
            "rows": [
                {"label": "none", "method": "none", "ssim_bbox": 0.60, "lpips_bbox": 0.30, "depth_psnr": 20.0},
                {"label": "GB-NeRF", "method": "gb-nerf", "ssim_bbox": 0.65, "lpips_bbox": 0.35, "depth_psnr": null},
            ],
        });
        let v = vs_none(&table);
        assert_eq!(v["GB-NeRF"]["ssim_bbox"], json!(true));
        assert_eq!(v["GB-NeRF"]["lpips_bbox"], json!(false));
        assert!(v["GB-NeRF"].get("depth_psnr").is_none(), "{v}");
        assert!(v.get("none").is_none());
        let no_reference = json!({"columns": [], "rows": [{"label": "x", "method": "bsd"}]});
        assert_eq!(vs_none(&no_reference), Value::Null);
    }

    fn seed_table(none_ssim: f64, gb_ssim: f64, gb_lpips: Option<f64>) -> Value {
        json!({
            "title": "Baselines",
            "columns": [
                {"key": "ssim_bbox", "higher_is_better": true},
                {"key": "lpips_bbox", "higher_is_better": false},
            ],
            "rows": [
                {"label": "none", "method": "none", "ssim_bbox": none_ssim, "lpips_bbox": 0.20, "seconds": 10.0},
                {"label": "GB-NeRF", "method": "gb-nerf", "ssim_bbox": gb_ssim, "lpips_bbox": gb_lpips, "seconds": 30.0},
            ],
        })
    }

    /// Three seeds' tables: GB-NeRF beats none on SSIM on two, on ST-LPIPS on one of the two
    /// that have it.
    fn three_seeds() -> [Value; 3] {
        [
            seed_table(0.50, 0.52, Some(0.25)),
            seed_table(0.54, 0.60, None),
            seed_table(0.52, 0.50, Some(0.17)),
        ]
    }

    #[test]
    fn mean_table_averages_each_cell_over_seeds_with_its_spread() {
        let tables = three_seeds();
        let m = mean_table(&tables);
        assert_eq!(m["title"], json!("Baselines (mean of 3 seed(s))"));
        let gb = &m["rows"][1];
        assert_eq!(gb["label"], json!("GB-NeRF"));
        assert_eq!(gb["seeds"], json!(3));
        assert!(
            (gb["ssim_bbox"].as_f64().unwrap() - 0.54).abs() < 1e-12,
            "{gb}"
        );
        // sample std of 0.52, 0.60, 0.50 around 0.54: sqrt((0.0004 + 0.0036 + 0.0016) / 2)
        let std = (0.0056f64 / 2.0).sqrt();
        assert!(
            (gb["ssim_bbox_std"].as_f64().unwrap() - std).abs() < 1e-12,
            "{gb}"
        );
        assert_eq!(gb["ssim_bbox_values"], json!([0.52, 0.60, 0.50]));
        // a seed without the value is left out of that cell's mean
        assert!(
            (gb["lpips_bbox"].as_f64().unwrap() - 0.21).abs() < 1e-12,
            "{gb}"
        );
        assert_eq!(gb["lpips_bbox_values"], json!([0.25, 0.17]));
        assert!((m["rows"][0]["seconds"].as_f64().unwrap() - 10.0).abs() < 1e-12);
        assert_eq!(m["rows"][0]["seconds_std"], json!(0.0));
        // the mean beats none on SSIM (0.54 > 0.52), not on ST-LPIPS (0.21 against 0.20)
        let v = vs_none(&m);
        assert_eq!(v["GB-NeRF"]["ssim_bbox"], json!(true));
        assert_eq!(v["GB-NeRF"]["lpips_bbox"], json!(false));
        assert_eq!(mean_table(&[]), Value::Null);
    }

    #[test]
    fn wins_vs_none_counts_the_seeds_each_method_beats_its_own_none() {
        let tables = three_seeds();
        let w = wins_vs_none(&tables);
        assert_eq!(w["GB-NeRF"]["ssim_bbox"], json!({"wins": 2, "of": 3}));
        assert_eq!(w["GB-NeRF"]["lpips_bbox"], json!({"wins": 1, "of": 2}));
        assert!(w.get("none").is_none());
    }
}
