//! `cargo xtask bench quality`: the object-removal quality of every method on the procedural
//! scenes with ground truth, written to `bench/results/quality-<scene>-<timestamp>.json`.
//!
//! For each scene of `--scenes` (default `stairs,fence`, generated with seed 0) it runs
//! `cargo xtask ablate` (same code, this process) on `--methods` (default: the baselines
//! table, none first, plus the ablation rows) without the w3 sweep, into `--work/<scene>/`,
//! and records the baseline and ablation tables with the machine. The reference is the
//! `none` run of the same job: `vs_none` gives, for each method and each column, whether it
//! beats no prior (masked-box SSIM up, ST-LPIPS down, D-PSNR up, ...).

use std::path::PathBuf;

use anyhow::Context;
use gb_core::BackendKind;
use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};
use serde_json::{json, Value};

/// Arguments of `cargo xtask bench quality`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Comma-separated procedural scenes (stairs, fence).
    #[arg(long, value_delimiter = ',', default_value = "stairs,fence")]
    pub scenes: Vec<SceneName>,
    /// Comma-separated methods (default: the whole grid without the w3 sweep).
    #[arg(long, value_delimiter = ',')]
    pub methods: Option<Vec<String>>,
    /// Preset for every run.
    #[arg(long, default_value = "fast")]
    pub preset: String,
    /// The prior of the guided methods (default: tiny).
    #[arg(long)]
    pub prior: Option<String>,
    /// Override the preset's number of steps.
    #[arg(long)]
    pub steps: Option<usize>,
    /// Compute backend.
    #[arg(long)]
    pub device: Option<BackendKind>,
    /// Folder of the runs.
    #[arg(long, default_value = "out/bench-quality")]
    pub work: PathBuf,
    /// Output folder of the JSON.
    #[arg(long, default_value = "bench/results")]
    pub out: PathBuf,
}

/// For each row, whether it beats the `none` row on each column.
fn vs_none(table: &Value) -> Value {
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

/// Runs the benchmark.
pub fn run(args: Args) -> anyhow::Result<()> {
    let stamp = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)?
        .as_secs();
    for &name in &args.scenes {
        let scene_dir = args.work.join(format!("{name}-scene"));
        let opts = ProceduralOptions {
            name,
            ..Default::default()
        };
        procedural::write(&opts, &scene_dir)
            .with_context(|| format!("generating {name} into {}", scene_dir.display()))?;
        let runs = args.work.join(name.to_string());
        let started = std::time::Instant::now();
        let outcome = super::ablate::run(super::ablate::Args {
            scene: scene_dir.clone(),
            methods: args.methods.clone(),
            preset: args.preset.clone(),
            prior: args.prior.clone(),
            lora: None,
            steps: args.steps,
            out: runs.clone(),
            w3: Some(Vec::new()),
            device: args.device,
            weights: None,
            orbit_frames: 0,
        });
        let read = |file: &str| -> anyhow::Result<Value> {
            let p = runs.join(file);
            let text =
                std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))?;
            serde_json::from_str(&text).with_context(|| format!("parsing {}", p.display()))
        };
        let baselines = read("baselines.json")?;
        let ablation = read("ablation.json")?;
        let report = json!({
            "benchmark": "quality",
            "machine": super::bench::machine_description(),
            "scene": format!("{name} (procedural, seed 0, {}x{})", opts.width, opts.height),
            "preset": args.preset,
            "prior": args.prior.clone().unwrap_or_else(|| "tiny".into()),
            "device": args.device.unwrap_or_default().name(),
            "wall_seconds": started.elapsed().as_secs_f64(),
            "baselines": baselines,
            "ablation": ablation,
            "baselines_vs_none": vs_none(&baselines),
            "ablation_vs_none": vs_none(&ablation),
            "runs": runs.display().to_string(),
            "error": outcome.as_ref().err().map(|e| format!("{e:#}")),
        });
        let path = args.out.join(format!("quality-{name}-{stamp}.json"));
        gb_core::write_atomic(&path, &serde_json::to_vec_pretty(&report)?)
            .with_context(|| format!("writing {}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
