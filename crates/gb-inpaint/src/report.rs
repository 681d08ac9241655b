//! The run report, `report.html`: one static page (no script, no external resource) with, per
//! view, the ground truth, our render, the baseline and the absolute difference side by side;
//! the orbit animation; the metric table (every key of the run's
//! [`gb_eval::report::EvalReport`], unavailable ones with their reason); and the training
//! curves (loss, PSNR, guidance gradient norms from `train_log.jsonl`) as SVG files drawn by
//! [`gb_report::svg`]. The page itself, its images and curves are gb-report's ([`gb_report::page`]);
//! this module fills them with the run.
//!
//! Images are files next to the page (`report/*.png`, `report/*.svg`, `renders/*.png`,
//! `orbit.gif`), linked relatively, so the folder can be moved or archived as a whole. Every
//! `<img>` carries `onload` / `onerror` attributes that set `data-loaded="ok"` or
//! `data-loaded="error"`: a headless browser's `--dump-dom` then tells whether each image
//! really loaded (tests/tests/report_browser.rs).

use std::path::{Path, PathBuf};

use gb_core::RgbImage;
use gb_eval::report::EvalReport;
use gb_nerf::scene::{Scene, Split};
use gb_nerf::train::data::prepare_view;
use gb_nerf::train::output::write_render_pngs;

use crate::error::InpaintError;
use crate::GuidedTrainer;
use gb_eval::suite::EvalPair;
use gb_report::curves::charts_from_log;
use gb_report::images::{abs_diff, masked_input};
use gb_report::page::{render_html, Cell, Figure, Report, ReportView};

/// The inputs of [`write_run_report`].
pub struct RunPage<'a> {
    /// The run's output folder (the page is `OUT/report.html`).
    pub out: &'a Path,
    /// The scene.
    pub scene: &'a Scene,
    /// The trained field.
    pub trainer: &'a GuidedTrainer,
    /// The evaluated test views (renders already in `OUT/renders/`).
    pub pairs: &'a [EvalPair],
    /// For a scene without test views: its rendered masked training views
    /// ([`render_masked_train_views`]), shown instead.
    pub train_views: &'a [TrainViewRender],
    /// Their metrics.
    pub eval: &'a EvalReport,
    /// The run's `metrics.json` (the summary table reads it).
    pub metrics: &'a serde_json::Value,
    /// Another run's folder (or its `renders/`) whose renders are the baseline column.
    pub baseline: Option<&'a Path>,
    /// Whether `OUT/orbit.gif` was written.
    pub orbit: bool,
}

/// Views shown for a scene without test views (the masked training views).
pub const MAX_TRAIN_VIEWS_SHOWN: usize = 3;

/// A masked training view rendered for a scene without ground truth.
#[derive(Debug, Clone)]
pub struct TrainViewRender {
    /// The view's name in the scene.
    pub view: String,
    /// The captured image (object present).
    pub input: RgbImage,
    /// The render, named `train_<view>` (its PNGs are `OUT/renders/train_<view>_*.png`),
    /// without a ground truth.
    pub render: EvalPair,
}

/// Renders the first [`MAX_TRAIN_VIEWS_SHOWN`] masked training views into `OUT/renders/`
/// (RGB, depth, normals): what a scene without test views shows and is scored on.
pub fn render_masked_train_views(
    out: &Path,
    scene: &Scene,
    trainer: &GuidedTrainer,
) -> Result<Vec<TrainViewRender>, InpaintError> {
    let renders = out.join("renders");
    let masked = scene
        .split(Split::Train)
        .filter(|v| v.mask.as_ref().is_some_and(|m| m.bbox().is_some()))
        .take(MAX_TRAIN_VIEWS_SHOWN);
    let mut views = Vec::new();
    for view in masked {
        let v = prepare_view(view, trainer.config.train.image_downscale);
        let r = trainer.render(&v.camera).map_err(InpaintError::from)?;
        let stem = format!("train_{}", view.name);
        write_render_pngs(&renders, &stem, &r).map_err(InpaintError::from)?;
        views.push(TrainViewRender {
            view: view.name.clone(),
            input: v.image,
            render: EvalPair {
                name: stem,
                pred: r.rgb,
                gt: None,
                mask: v.mask.map(|m| m.data),
                disparity: None,
            },
        });
    }
    Ok(views)
}

fn io_err(path: &Path, e: impl std::fmt::Display) -> InpaintError {
    InpaintError::Io {
        path: path.to_path_buf(),
        source: std::io::Error::other(e.to_string()),
    }
}

fn write_png(path: &Path, img: &RgbImage) -> Result<(), InpaintError> {
    gb_core::write_rgb_png(path, img).map_err(|e| io_err(path, e))
}

/// The baseline's render of `stem` (`DIR/renders/STEM_rgb.png` or `DIR/STEM_rgb.png`) when
/// it exists and has the size of `like`.
fn baseline_image(dir: &Path, stem: &str, like: &RgbImage) -> Result<RgbImage, String> {
    let candidates = [
        dir.join("renders").join(format!("{stem}_rgb.png")),
        dir.join(format!("{stem}_rgb.png")),
    ];
    let Some(path) = candidates.iter().find(|p| p.is_file()) else {
        return Err(format!("{} not found", candidates[0].display()));
    };
    let img = gb_core::read_rgb(path, None).map_err(|e| format!("{}: {e}", path.display()))?;
    if (img.width, img.height) != (like.width, like.height) {
        return Err(format!(
            "{} is {}x{}, this run renders {}x{}",
            path.display(),
            img.width,
            img.height,
            like.width,
            like.height
        ));
    }
    Ok(img)
}

/// Writes `OUT/report.html` and its images under `OUT/report/` (see the module docs); returns
/// the page's path.
pub fn write_run_report(p: &RunPage) -> Result<PathBuf, InpaintError> {
    let dir = p.out.join("report");
    std::fs::create_dir_all(&dir).map_err(|e| io_err(&dir, e))?;
    let mut views = Vec::new();
    let mut notes = Vec::new();
    let mut baseline_problems = Vec::new();
    let c = |label: &str, src: String| Cell {
        label: label.to_string(),
        src,
    };
    // the baseline column, or the masked input when there is no baseline
    let mut baseline_cell = |stem: &str, n: &str, like: &RgbImage, mask: Option<&[bool]>| {
        if let Some(b) = p.baseline {
            match baseline_image(b, stem, like) {
                Ok(img) => {
                    let f = format!("{n}_baseline.png");
                    write_png(&dir.join(&f), &img)?;
                    return Ok::<Cell, InpaintError>(c("baseline", format!("report/{f}")));
                }
                Err(e) => baseline_problems.push(e),
            }
        }
        let f = format!("{n}_masked_input.png");
        let img = match mask {
            Some(m) => masked_input(like, m),
            None => like.clone(),
        };
        write_png(&dir.join(&f), &img)?;
        Ok(c("masked input (no baseline)", format!("report/{f}")))
    };
    for pair in p.pairs {
        let n = &pair.name;
        let Some(gt_image) = &pair.gt else { continue };
        let gt = format!("{n}_gt.png");
        write_png(&dir.join(&gt), gt_image)?;
        let diff = format!("{n}_diff.png");
        write_png(&dir.join(&diff), &abs_diff(&pair.pred, gt_image)?)?;
        let mut cells = vec![
            c("ground truth", format!("report/{gt}")),
            c("ours", format!("renders/{n}_rgb.png")),
            baseline_cell(n, n, gt_image, pair.mask.as_deref())?,
            c("|ours − ground truth|", format!("report/{diff}")),
            c("ours: depth", format!("renders/{n}_depth.png")),
        ];
        if p.out.join(format!("renders/{n}_normal.png")).is_file() {
            cells.push(c("ours: normals", format!("renders/{n}_normal.png")));
        }
        views.push(ReportView {
            name: n.clone(),
            cells,
        });
    }
    if p.pairs.is_empty() {
        // no ground truth: show what the run removed on the masked training views
        notes.push(format!(
            "The scene has no test view with ground truth: the first {MAX_TRAIN_VIEWS_SHOWN} \
             masked training views are shown, with the object present in the input and \
             removed in our render. They are scored without a reference: BRISQUE (lower is \
             more natural) of the whole render and of the mask box, which holds the fill."
        ));
        let renders = p.out.join("renders");
        for t in p.train_views {
            let stem = &t.render.name;
            let input = format!("{stem}_input.png");
            write_png(&dir.join(&input), &t.input)?;
            let mut cells = vec![
                c("input (object present)", format!("report/{input}")),
                c("ours", format!("renders/{stem}_rgb.png")),
                baseline_cell(stem, stem, &t.input, t.render.mask.as_deref())?,
                c("ours: depth", format!("renders/{stem}_depth.png")),
            ];
            if renders.join(format!("{stem}_normal.png")).is_file() {
                cells.push(c("ours: normals", format!("renders/{stem}_normal.png")));
            }
            views.push(ReportView {
                name: format!("{} (training view)", t.view),
                cells,
            });
        }
    }
    match p.baseline {
        None => notes.push(
            "No baseline was given (--baseline DIR, another run's output folder, e.g. of \
             --method none): the baseline column shows the masked input instead, i.e. what \
             the NeRF is trained on (the checkerboard marks the pixels it never sees)."
                .into(),
        ),
        Some(b) if baseline_problems.is_empty() => {
            notes.push(format!("Baseline column: the renders of {}.", b.display()))
        }
        Some(b) => notes.push(format!(
            "Baseline {} could not be used for every view (the masked input is shown \
             instead): {}",
            b.display(),
            baseline_problems.join("; ")
        )),
    }

    let mut figures = Vec::new();
    let log = p.out.join("train_log.jsonl");
    if log.is_file() {
        for (stem, chart) in charts_from_log(&log)? {
            let f = format!("{stem}.svg");
            let path = dir.join(&f);
            gb_core::write_atomic(&path, chart.to_svg().as_bytes())
                .map_err(|e| io_err(&path, e))?;
            figures.push(Figure {
                title: chart.title.clone(),
                src: format!("report/{f}"),
            });
        }
    }

    let m = p.metrics;
    let text = |v: &serde_json::Value| match v {
        serde_json::Value::String(s) => s.clone(),
        serde_json::Value::Null => "–".into(),
        serde_json::Value::Number(n) => match n.as_f64() {
            Some(x) if x.fract() != 0.0 => format!("{x:.3}"),
            _ => n.to_string(),
        },
        other => other.to_string(),
    };
    let mut summary: Vec<(String, String)> = [
        ("scene", &m["scene"]),
        ("method", &m["method"]),
        ("prior", &m["prior"]),
        ("LoRA", &m["lora"]),
        ("preset", &m["preset"]),
        ("device", &m["device"]),
        ("steps", &m["steps"]),
        ("training time this run (s)", &m["train_seconds_this_run"]),
        ("s / guided step", &m["guidance"]["seconds_per_guided_step"]),
        (
            "s / unguided step",
            &m["guidance"]["seconds_per_unguided_step"],
        ),
    ]
    .iter()
    .map(|(k, v)| (k.to_string(), text(v)))
    .collect();
    summary.push((
        "files".into(),
        "config.toml (reproduces the run), metrics.json, train_log.jsonl, renders/".into(),
    ));
    let report = Report {
        title: format!(
            "GB-NeRF object removal: {} / {}",
            text(&m["scene"]),
            text(&m["method"])
        ),
        summary,
        notes,
        views,
        orbit: p.orbit.then(|| "orbit.gif".to_string()),
        eval: p.eval.clone(),
        figures,
    };
    let page = p.out.join("report.html");
    gb_core::write_atomic(&page, render_html(&report).as_bytes()).map_err(|e| io_err(&page, e))?;
    Ok(page)
}
