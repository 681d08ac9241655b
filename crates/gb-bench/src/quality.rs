//! `cargo xtask bench quality`: the object-removal quality of every method on the procedural
//! scenes with ground truth, written to `bench/results/quality-<scene>-<timestamp>.json`.
//!
//! For each scene of `--scenes` (default `stairs,fence,alcove`, generated with seed 0) it runs
//! the method grid of `cargo xtask ablate` (`gb_inpaint::grid`, in this process) on `--methods` (default: the baselines
//! table, none first, plus the ablation rows) without the w3 sweep, into `--work/<scene>/`,
//! and records the baseline and ablation tables with the machine. The reference is the
//! `none` run of the same job: `vs_none` gives, for each method and each column, whether it
//! beats no prior (masked-box SSIM up, ST-LPIPS down, D-PSNR up, ...).
//!
//! `--seeds 2,3,4` repeats the grid per seed `s`: the scene generated with seed `s` (another
//! layout of the same scene: object, cameras, texture) and trained with seed `s`
//! (`inpaint --seed`), into `--work/<scene>/seed-<s>/`. Choose hyper-parameters on one set of
//! seeds (tuning: 100 and up) and report on another that no choice was made on. A seed moves
//! the no-prior scores about as much as the methods differ (fence: mask-box SSIM 0.487 and
//! 0.517 for training seeds 0 and 1), so the recorded tables are then the mean over seeds,
//! each cell with its sample standard deviation and per-seed values, `vs_none` compares the
//! means, and `wins_vs_none` counts the seeds on which each method beats that seed's `none`.
//! Each seed's entry of `per_seed` also keeps, under `auto`, the pseudo-hole, trials, scores
//! and choice of every run with `"auto"` weights, so the report holds them after `--work` is
//! gone.
//!
//! `--oracle reference` adds the row `reference-oracle`, an upper bound that no real capture has: the
//! `none` method with one reference view ([`gb_inpaint::reference`]) taken from the scene's
//! `clean/` (the middle masked training view rendered without the object, exact ground
//! truth). It answers whether the pipeline carries a perfect 2D fill of one view into 3D.
//! `--oracle prior` adds `prior-oracle`: `gb-nerf-unseen` (the guided method at fixed
//! weights) with its prior personalised on `clean/`, every training view without the
//! object, so that the prior knows the hidden region exactly and nothing else supervises
//! it. It answers whether the distillation carries a strong prior's knowledge into 3D, if personalisation makes the prior strong (with the
//! tiny prior it does not: README). `--oracle score` adds `score-oracle`:
//! `gb-nerf-unseen` with its RGB score replaced by the exact score of the object-free images
//! ([`gb_inpaint::oracle`]), the strongest prior there is; it separates the prior from the
//! distillation for certain. Bare `--oracle` adds all three.
//! `--fill-reference` adds `reference-fill`: the same view filled in 2D by the grid's prior
//! (`cargo xtask fill`, its default settings, the prior's own LoRA) as the reference, which
//! is what a user without a clean plate or a 2D tool runs.
//! `--auto-reference` adds `reference-auto`: the same view filled by frequency-selective
//! reconstruction, as `inpaint --reference auto` fills it, no weights;
//! `--auto-reference-unseen` adds `reference-auto-unseen`, the same with `[reference]
//! skip_observed` (only the reference pixels that no other view observes are supervised and
//! carried).

use std::path::{Path, PathBuf};

use anyhow::Context;
use gb_inpaint::grid::{self, Grid};
use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};
use serde_json::{json, Value};

/// Arguments of `cargo xtask bench quality`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Comma-separated procedural scenes (stairs, fence, alcove).
    #[arg(long, value_delimiter = ',', default_value = "stairs,fence,alcove")]
    pub scenes: Vec<SceneName>,
    /// The grid: methods (default: the whole grid, without the w3 sweep), preset, prior,
    /// steps, device.
    #[command(flatten)]
    pub grid: crate::GridArgs,
    /// Comma-separated seeds, each the scene's and the training's; the tables are their mean
    /// (default: scene seed 0 and the preset's training seed).
    #[arg(long, value_delimiter = ',')]
    pub seeds: Option<Vec<u64>>,
    /// Folder of the runs.
    #[arg(long, default_value = "out/bench-quality")]
    pub work: PathBuf,
    /// Reuse the runs of `--work` that finished (their `metrics.json` and `cell-time.json`
    /// exist) instead of resuming each one (which renders and scores it again): for a job
    /// cut short, run again with the same flags.
    #[arg(long)]
    pub reuse_finished: bool,
    /// Output folder of the JSON.
    #[arg(long, default_value = "bench/results")]
    pub out: PathBuf,
    /// Add oracle rows (module docs), comma-separated: `reference`, `prior`, `score`; bare
    /// `--oracle` adds all three. Each is labelled as an oracle, never a method a user can
    /// run on a real capture without clean plates.
    #[arg(long, value_enum, value_delimiter = ',', num_args = 0.., default_missing_value = "reference,prior,score")]
    pub oracle: Option<Vec<OracleRow>>,
    /// Add the row `reference-fill` (module docs): the `none` method with a reference that
    /// the grid's prior fills in 2D (`cargo xtask fill`).
    #[arg(long)]
    pub fill_reference: bool,
    /// Add the row `reference-auto` (module docs): the `none` method with `--reference auto`,
    /// the reference filled by frequency-selective reconstruction, no weights.
    #[arg(long)]
    pub auto_reference: bool,
    /// Add the row `reference-auto-unseen` (module docs): `reference-auto` with `[reference]
    /// skip_observed`, supervised only where no other view observes.
    #[arg(long)]
    pub auto_reference_unseen: bool,
}

/// An oracle row of `bench quality --oracle` (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OracleRow {
    /// `reference-oracle`: one exact reference view.
    Reference,
    /// `prior-oracle`: the prior personalised on every exact object-free view.
    Prior,
    /// `score-oracle`: the exact RGB score of the object-free views.
    Score,
}

/// The extra rows of `bench quality` beside the method grid.
#[derive(Debug, Clone, Default)]
pub struct ExtraRows {
    /// The oracle rows (`--oracle`).
    pub oracle: Vec<OracleRow>,
    /// `reference-fill` (`--fill-reference`).
    pub fill: bool,
    /// `reference-auto` (`--auto-reference`).
    pub auto: bool,
    /// `reference-auto-unseen` (`--auto-reference-unseen`).
    pub auto_unseen: bool,
}

/// The name of the oracle row of `--oracle`.
pub const REFERENCE_ORACLE: &str = "reference-oracle";

/// The name of the second oracle row of `--oracle`.
pub const PRIOR_ORACLE: &str = "prior-oracle";

/// The name of the third oracle row of `--oracle`.
pub const SCORE_ORACLE: &str = "score-oracle";

/// What `score-oracle` is, in the JSON.
pub const SCORE_ORACLE_NOTE: &str = "ORACLE, not a method: gb-nerf-unseen whose RGB score is \
    the exact one of each guided view's object-free image (the scene's clean/; SDS with \
    guidance scale 1, lambda_rgb 1e-4), the normal term unchanged; no direct supervision";

/// AdamW steps of the `prior-oracle` personalisation.
pub const PRIOR_ORACLE_STEPS: usize = 300;

/// The name of the row of `--fill-reference`.
pub const REFERENCE_FILL: &str = "reference-fill";

/// The name of the row of `--auto-reference`.
pub const REFERENCE_AUTO: &str = "reference-auto";

/// The name of the second row of `--auto-reference`: `reference-auto` with `[reference]
/// skip_observed`.
pub const REFERENCE_AUTO_UNSEEN: &str = "reference-auto-unseen";

/// The middle masked training view of a generated scene: the reference view of the
/// `reference-*` rows.
pub fn reference_view(scene: &procedural::GeneratedScene) -> Option<&procedural::GeneratedView> {
    let train: Vec<&procedural::GeneratedView> = scene
        .views
        .iter()
        .filter(|v| v.split == gb_nerf::scene::Split::Train && v.mask.data.iter().any(|b| *b))
        .collect();
    train.get(train.len() / 2).copied()
}

/// Writes `dir/NAME.toml`: the `none` method with the reference `VIEW.png=IMAGE`, described
/// by `comment`. Returns its path.
fn write_reference_method(
    dir: &Path,
    name: &str,
    comment: &str,
    view: &str,
    image: &Path,
) -> anyhow::Result<PathBuf> {
    let mut method = gb_inpaint::MethodConfig::load("none")?;
    method.name = name.into();
    method.description = comment.into();
    let image = std::path::absolute(image)?;
    method.reference.images = vec![format!("{view}.png={}", image.display())];
    write_method(dir, &method)
}

/// Writes `dir/reference-oracle.toml` (module docs): the `none` method with the middle
/// masked training view of `scene` as its reference, from the scene's `clean/`.
pub fn write_reference_oracle(
    scene: &procedural::GeneratedScene,
    scene_dir: &Path,
    dir: &Path,
) -> anyhow::Result<PathBuf> {
    let view = reference_view(scene)
        .ok_or_else(|| anyhow::anyhow!("{}: no masked training view", scene_dir.display()))?;
    write_reference_method(
        dir,
        REFERENCE_ORACLE,
        "ORACLE, not a method: no prior; one training view without the object (exact ground \
         truth from the scene's clean/) is the reference",
        &view.name,
        &scene_dir.join("clean").join(format!("{}.png", view.name)),
    )
}

/// Writes `dir/prior-oracle.toml` (module docs): the guided method at fixed weights
/// ([`gb_inpaint::run::DEFAULT_METHOD`]) with its prior personalised
/// ([`gb_inpaint::personalize`], [`PRIOR_ORACLE_STEPS`] steps) on the scene's `clean/`, every
/// training view without the object: the prior then knows what the hole holds, and only the
/// distillation carries it into the NeRF (no reference, no direct supervision).
pub fn write_prior_oracle(scene_dir: &Path, dir: &Path) -> anyhow::Result<PathBuf> {
    let mut method = gb_inpaint::MethodConfig::load(gb_inpaint::run::DEFAULT_METHOD)?;
    method.name = PRIOR_ORACLE.into();
    method.description = format!(
        "ORACLE, not a method: {} with its prior personalised on every training view without \
         the object (exact ground truth from the scene's clean/)",
        gb_inpaint::run::DEFAULT_METHOD
    );
    method.personalize.steps = PRIOR_ORACLE_STEPS;
    method.personalize.object_free = Some(std::path::absolute(scene_dir.join("clean"))?);
    write_method(dir, &method)
}

/// Writes `dir/score-oracle.toml` (module docs, [`SCORE_ORACLE_NOTE`]): the guided method
/// with its RGB score replaced by the exact score of the object-free images
/// ([`gb_inpaint::oracle`]): SDS at guidance scale 1, so that the direction is exactly the
/// pull of the crop's latents to the truth's, at `lambda_rgb = 1e-4` (ten times the
/// gb-nerf-unseen's: the exact direction has no noise in it and is smaller than BSD's; the one
/// weight tried, on tuning seed 100).
pub fn write_score_oracle(scene_dir: &Path, dir: &Path) -> anyhow::Result<PathBuf> {
    use gb_diffusion::distill::{Branch, GuidanceMethod};
    let mut method = gb_inpaint::MethodConfig::load(gb_inpaint::run::DEFAULT_METHOD)?;
    method.name = SCORE_ORACLE.into();
    method.description = SCORE_ORACLE_NOTE.into();
    method.lambda_rgb = 1e-4.into();
    let rgb = method
        .rgb
        .as_mut()
        .ok_or_else(|| anyhow::anyhow!("the guided method has no RGB guidance"))?;
    rgb.guidance = GuidanceMethod::Sds {
        guidance_scale: 1.0,
    };
    method.oracle = gb_inpaint::oracle::OracleSettings {
        clean: Some(std::path::absolute(scene_dir.join("clean"))?),
        branches: vec![Branch::Text, Branch::Unconditional],
    };
    write_method(dir, &method)
}

/// Writes `dir/NAME.toml` for `method`, headed by its description. Returns its path.
fn write_method(dir: &Path, method: &gb_inpaint::MethodConfig) -> anyhow::Result<PathBuf> {
    let text = format!("# {}\n{}", method.description, toml::to_string(method)?);
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join(format!("{}.toml", method.name));
    gb_core::write_atomic(&path, text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

/// Writes `dir/reference-fill.toml` (module docs): the `none` method with the middle masked
/// training view of `scene` filled by `prior` (`gb_inpaint::fill`, its default settings) as
/// its reference, the fill saved beside it.
pub fn write_reference_fill(
    scene: &procedural::GeneratedScene,
    scene_dir: &Path,
    dir: &Path,
    prior: &str,
    device: gb_core::BackendKind,
) -> anyhow::Result<PathBuf> {
    let view = reference_view(scene)
        .ok_or_else(|| anyhow::anyhow!("{}: no masked training view", scene_dir.display()))?;
    let png = dir.join(format!("{REFERENCE_FILL}-{}.png", view.name));
    if !png.is_file() {
        let opts = gb_inpaint::fill::FillOptions {
            with: gb_inpaint::fill::FillWith::Prior,
            prior: prior.to_string(),
            device,
            ..Default::default()
        };
        let filled = gb_inpaint::fill::fill(scene_dir, &view.name, &opts)?;
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        gb_core::write_rgb_png(&png, &filled.image)
            .with_context(|| format!("writing {}", png.display()))?;
    }
    write_reference_method(
        dir,
        REFERENCE_FILL,
        &format!(
            "no prior in the NeRF; one training view filled in 2D by the prior '{prior}' \
             (cargo xtask fill) is the reference"
        ),
        &view.name,
        &png,
    )
}

/// Writes `dir/reference-auto.toml` and `dir/reference-auto-unseen.toml` (module docs): the
/// `none` method with the reference that `inpaint --reference auto` makes
/// ([`gb_inpaint::fill::auto_reference`]: the middle masked training view filled by
/// frequency-selective reconstruction), the fill saved beside it; the second supervises and
/// carries only the reference pixels that no other view observes (`[reference]
/// skip_observed`).
pub fn write_reference_auto(scene_dir: &Path, dir: &Path) -> anyhow::Result<[PathBuf; 2]> {
    let (_, scene) = gb_nerf::scene::load(scene_dir, &gb_nerf::scene::LoadOptions::default())?;
    let (_, auto) = gb_inpaint::fill::auto_reference(&scene, scene_dir, dir)?;
    let png = dir.join(format!("reference-auto-{}.png", auto.view));
    let all = write_reference_method(
        dir,
        REFERENCE_AUTO,
        "no prior in the NeRF; one training view filled in 2D by frequency-selective \
         reconstruction (inpaint --reference auto, no weights) is the reference",
        &auto.view,
        &png,
    )?;
    let mut method = gb_inpaint::MethodConfig::load(all.to_str().context("a non-UTF-8 path")?)?;
    method.name = REFERENCE_AUTO_UNSEEN.into();
    method.description = format!(
        "{}, on the pixels no other training view observes",
        method.description
    );
    method.reference.skip_observed = true;
    Ok([all, write_method(dir, &method)?])
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

/// For each row, on how many tables (one per seed) it beats that table's `none` row, per
/// column: `{"label": {"key": {"wins": k, "of": n}}}`.
fn wins_vs_none(tables: &[Value]) -> Value {
    let mut out = serde_json::Map::new();
    for t in tables {
        let Value::Object(per_row) = vs_none(t) else {
            continue;
        };
        for (label, cols) in per_row {
            let entry = out
                .entry(label)
                .or_insert_with(|| Value::Object(Default::default()));
            for (key, beats) in cols.as_object().into_iter().flatten() {
                let cell = entry
                    .as_object_mut()
                    .expect("an object")
                    .entry(key.clone())
                    .or_insert_with(|| json!({"wins": 0, "of": 0}));
                let wins = cell["wins"].as_u64().unwrap_or(0) + u64::from(beats == &json!(true));
                let of = cell["of"].as_u64().unwrap_or(0) + 1;
                *cell = json!({"wins": wins, "of": of});
            }
        }
    }
    out.into()
}

/// The mean of ablate tables of the same grid over seeds: each row (matched by label, in the
/// first table's order) gets, per column, the mean of the seeds that have a value, with
/// `<key>_std` (sample standard deviation, 0 for one value) and `<key>_values`; `seeds` says
/// how many tables had the row.
fn mean_table(tables: &[Value]) -> Value {
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
fn auto_choices(runs: &Path) -> anyhow::Result<Value> {
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

/// Runs the benchmark.
pub fn run(args: Args) -> anyhow::Result<()> {
    let stamp = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)?
        .as_secs();
    for &name in &args.scenes {
        let report = run_scene(
            name,
            &args.grid,
            args.seeds.as_deref(),
            &args.work,
            args.reuse_finished,
            ExtraRows {
                oracle: args.oracle.clone().unwrap_or_default(),
                fill: args.fill_reference,
                auto: args.auto_reference,
                auto_unseen: args.auto_reference_unseen,
            },
        )?;
        let path = args.out.join(format!("quality-{name}-{stamp}.json"));
        gb_core::write_atomic(&path, &serde_json::to_vec_pretty(&report)?)
            .with_context(|| format!("writing {}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// The quality report of one scene: the method grid of `grid` on each of `seeds` (none: scene
/// seed 0 and the preset's training seed), run into `work` (reusing finished runs when
/// `reuse_finished`), as the mean tables over seeds with their comparison against `none`.
/// A run that fails is recorded in the report's `error`; a scene that cannot be generated or
/// a grid whose tables cannot be read is an error. `extra` adds the `reference-*` rows
/// (module docs).
pub fn run_scene(
    name: SceneName,
    grid: &crate::GridArgs,
    seeds: Option<&[u64]>,
    work: &Path,
    reuse_finished: bool,
    extra: ExtraRows,
) -> anyhow::Result<Value> {
    let depth = match grid.depth {
        Some(d) => d,
        None => {
            gb_nerf::train::NerfConfig::preset(&grid.preset)?
                .train
                .depth
        }
    };
    let seeds: Vec<Option<u64>> = match seeds {
        Some(list) if !list.is_empty() => list.iter().copied().map(Some).collect(),
        _ => vec![None],
    };
    let started = std::time::Instant::now();
    let mut per_seed = Vec::new();
    let mut errors = Vec::new();
    let mut opts = ProceduralOptions {
        name,
        ..Default::default()
    };
    for seed in &seeds {
        opts.seed = seed.unwrap_or(0);
        let (scene_dir, runs) = match seed {
            Some(s) => (
                work.join(format!("{name}-scene-seed-{s}")),
                work.join(name.to_string()).join(format!("seed-{s}")),
            ),
            None => (
                work.join(format!("{name}-scene")),
                work.join(name.to_string()),
            ),
        };
        let generated = procedural::write(&opts, &scene_dir)
            .with_context(|| format!("generating {name} into {}", scene_dir.display()))?;
        let mut methods = grid.methods.clone();
        let mut extra_files = Vec::new();
        for row in &extra.oracle {
            extra_files.push(match row {
                OracleRow::Reference => write_reference_oracle(&generated, &scene_dir, &runs)?,
                OracleRow::Prior => write_prior_oracle(&scene_dir, &runs)?,
                OracleRow::Score => write_score_oracle(&scene_dir, &runs)?,
            });
        }
        if extra.fill {
            let prior = grid.prior.clone().unwrap_or_else(|| "tiny".into());
            let device = grid.device.unwrap_or_default();
            extra_files.push(write_reference_fill(
                &generated, &scene_dir, &runs, &prior, device,
            )?);
        }
        if extra.auto || extra.auto_unseen {
            let [all, unseen] = write_reference_auto(&scene_dir, &runs)?;
            if extra.auto {
                extra_files.push(all);
            }
            if extra.auto_unseen {
                extra_files.push(unseen);
            }
        }
        if !extra_files.is_empty() {
            let mut list = methods.unwrap_or_else(|| grid::grid_methods(None));
            list.extend(extra_files.iter().map(|f| f.display().to_string()));
            methods = Some(list);
        }
        // the method grid without the w3 sweep, run in this process
        let outcome = Grid::plan(
            grid.settings(scene_dir.clone(), *seed),
            methods.as_deref(),
            Some(&[]),
            &runs,
        )
        .and_then(|g| g.write(&runs).map(|_| g))
        .and_then(|g| {
            for (i, cell) in g.cells.iter().enumerate() {
                let dir = runs.join(&cell.dir);
                if reuse_finished && grid::cell_finished(&dir) {
                    tracing::info!(cell = %dir.display(), "reusing the finished run");
                } else {
                    grid::run_cell(&runs, i)?;
                }
            }
            grid::merge(&runs)
        })
        .map_err(anyhow::Error::from)
        .and_then(|merged| {
            let failed: Vec<String> = merged
                .failed
                .iter()
                .map(|(d, e)| format!("{d}: {e}"))
                .collect();
            if failed.is_empty() {
                Ok(())
            } else {
                Err(anyhow::anyhow!("run(s) failed: {}", failed.join("; ")))
            }
        });
        if let Err(e) = &outcome {
            errors.push(format!("seed {seed:?}: {e:#}"));
        }
        let read = |file: &str| -> anyhow::Result<Value> {
            let p = runs.join(file);
            let text =
                std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))?;
            serde_json::from_str(&text).with_context(|| format!("parsing {}", p.display()))
        };
        per_seed.push(json!({
            "seed": seed,
            "runs": runs.display().to_string(),
            "baselines": read("baselines.json")?,
            "ablation": read("ablation.json")?,
            "auto": auto_choices(&runs)?,
        }));
    }
    let tables = |key: &str| -> Vec<Value> { per_seed.iter().map(|s| s[key].clone()).collect() };
    let baselines = mean_table(&tables("baselines"));
    let ablation = mean_table(&tables("ablation"));
    Ok(json!({
        "benchmark": "quality",
        "machine": super::machine_description(),
        "scene": format!("{name} (procedural, {}x{})", opts.width, opts.height),
        "scene_seeds": seeds.iter().map(|s| s.unwrap_or(0)).collect::<Vec<_>>(),
        "depth": depth.name(),
        "preset": grid.preset,
        "prior": grid.prior.clone().unwrap_or_else(|| "tiny".into()),
        "device": grid.device.unwrap_or_default().name(),
        "oracle_rows": if extra.oracle.is_empty() {
            Value::Null
        } else {
            extra
                .oracle
                .iter()
                .map(|row| match row {
                    OracleRow::Reference => (REFERENCE_ORACLE.to_string(), json!(
                        "ORACLE, not a method: the none method with one training view's exact \
                         object-free image (the scene's clean/) as its reference view")),
                    OracleRow::Prior => (PRIOR_ORACLE.to_string(), json!(format!(
                        "ORACLE, not a method: gb-nerf-unseen with its prior personalised \
                         ({PRIOR_ORACLE_STEPS} steps) on every training view's exact object-free \
                         image (the scene's clean/); no direct supervision"))),
                    OracleRow::Score => (SCORE_ORACLE.to_string(), json!(SCORE_ORACLE_NOTE)),
                })
                .collect::<serde_json::Map<_, _>>()
                .into()
        },
        "training_seeds": seeds,
        "wall_seconds": started.elapsed().as_secs_f64(),
        "baselines": baselines,
        "ablation": ablation,
        "baselines_vs_none": vs_none(&baselines),
        "ablation_vs_none": vs_none(&ablation),
        "baselines_wins_vs_none": wins_vs_none(&tables("baselines")),
        "ablation_wins_vs_none": wins_vs_none(&tables("ablation")),
        "per_seed": per_seed,
        "error": if errors.is_empty() { Value::Null } else { json!(errors.join("; ")) },
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_oracle_rows_are_the_default_method_with_the_scenes_clean_views() {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("scene");
        let prior = gb_inpaint::MethodConfig::load(
            write_prior_oracle(&scene, dir.path())
                .unwrap()
                .to_str()
                .unwrap(),
        )
        .unwrap();
        assert_eq!(prior.name, PRIOR_ORACLE);
        assert_eq!(prior.personalize.steps, PRIOR_ORACLE_STEPS);
        assert!(prior
            .personalize
            .object_free
            .unwrap()
            .ends_with("scene/clean"));
        assert!(prior.oracle.clean.is_none());
        let score = gb_inpaint::MethodConfig::load(
            write_score_oracle(&scene, dir.path())
                .unwrap()
                .to_str()
                .unwrap(),
        )
        .unwrap();
        let default = gb_inpaint::MethodConfig::load(gb_inpaint::run::DEFAULT_METHOD).unwrap();
        assert_eq!(score.name, SCORE_ORACLE);
        assert!(score.oracle.clean.unwrap().ends_with("scene/clean"));
        assert_eq!(score.lambda_rgb.value(), 1e-4);
        assert_eq!(
            (score.lambda_normal, &score.normal, &score.visibility),
            (default.lambda_normal, &default.normal, &default.visibility)
        );
        assert_eq!(score.rgb.unwrap().guidance.name(), "sds");
        let reference = gb_inpaint::MethodConfig::load(
            write_reference_method(dir.path(), "r", "a note", "view_003", &scene.join("x.png"))
                .unwrap()
                .to_str()
                .unwrap(),
        )
        .unwrap();
        assert_eq!(
            (reference.name.as_str(), reference.rgb.is_none()),
            ("r", true)
        );
        assert_eq!(reference.reference.images.len(), 1);
        assert!(reference.reference.images[0].starts_with("view_003.png="));
        assert!(reference.reference.images[0].ends_with("scene/x.png"));
    }

    /// `reference-auto` is `none` with the fsr fill of the view that the reference oracle
    /// uses: the fill is written, it matches the view outside the mask and is closer to the
    /// clean view than the object inside it.
    #[test]
    fn the_auto_reference_row_fills_the_oracle_s_view_by_fsr() {
        let dir = tempfile::tempdir().unwrap();
        let scene_dir = dir.path().join("scene");
        let opts = ProceduralOptions {
            width: 64,
            height: 48,
            views: 8,
            test_views: 2,
            ..Default::default()
        };
        let generated = procedural::write(&opts, &scene_dir).unwrap();
        let view = reference_view(&generated).unwrap();
        let [path, unseen] = write_reference_auto(&scene_dir, &dir.path().join("runs")).unwrap();
        let method = gb_inpaint::MethodConfig::load(path.to_str().unwrap()).unwrap();
        let unseen = gb_inpaint::MethodConfig::load(unseen.to_str().unwrap()).unwrap();
        assert_eq!(unseen.name, REFERENCE_AUTO_UNSEEN);
        assert!(unseen.reference.skip_observed && !method.reference.skip_observed);
        assert_eq!(unseen.reference.images, method.reference.images);
        assert_eq!(
            (method.name.as_str(), method.rgb.is_none()),
            (REFERENCE_AUTO, true)
        );
        assert_eq!(method.reference.images.len(), 1);
        let (name, png) = method.reference.images[0].split_once('=').unwrap();
        assert_eq!(name, format!("{}.png", view.name));
        let filled = gb_core::read_rgb(std::path::Path::new(png), None).unwrap();
        let clean = gb_core::read_rgb(
            &scene_dir.join("clean").join(format!("{}.png", view.name)),
            None,
        )
        .unwrap();
        let object = gb_core::read_rgb(
            &scene_dir
                .join("images_1")
                .join(format!("{}.png", view.name)),
            None,
        )
        .unwrap();
        let (mut err_fill, mut err_object) = (0.0f64, 0.0f64);
        for (i, &m) in view.mask.data.iter().enumerate() {
            for c in 0..3 {
                let k = 3 * i + c;
                if m {
                    err_fill += (filled.data[k] - clean.data[k]).powi(2) as f64;
                    err_object += (object.data[k] - clean.data[k]).powi(2) as f64;
                } else {
                    assert_eq!(filled.data[k], object.data[k], "pixel {i} outside the mask");
                }
            }
        }
        assert!(err_fill < 0.5 * err_object, "{err_fill} vs {err_object}");
    }

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
