//! The run report, `report.html`: one static page (no script, no external resource) with, per
//! view, the ground truth, our render, the baseline and the absolute difference side by side;
//! the orbit animation; the metric table (every key of the run's
//! [`gb_eval::report::EvalReport`], unavailable ones with their reason); and the training
//! curves (loss, PSNR, guidance gradient norms from `train_log.jsonl`) as SVG files drawn by
//! [`crate::svg`].
//!
//! Images are files next to the page (`report/*.png`, `report/*.svg`, `renders/*.png`,
//! `orbit.gif`), linked relatively, so the folder can be moved or archived as a whole. Every
//! `<img>` carries `onload` / `onerror` attributes that set `data-loaded="ok"` or
//! `data-loaded="error"`: a headless browser's `--dump-dom` then tells whether each image
//! really loaded (tests/tests/report_browser.rs).

use std::path::{Path, PathBuf};

use gb_core::RgbImage;
use gb_eval::report::{EvalReport, Outcome, RegionKind, COLUMNS};
use gb_nerf::scene::{Scene, Split};
use gb_nerf::train::data::prepare_view;
use gb_nerf::train::output::write_render_pngs;

use crate::error::InpaintError;
use crate::svg::{escape, LineChart, Series};
use crate::GuidedTrainer;
use gb_eval::suite::EvalPair;

/// One image of a view's row.
#[derive(Debug, Clone, PartialEq)]
pub struct Cell {
    /// Column heading ("ground truth", "ours", ...).
    pub label: String,
    /// Path relative to the page.
    pub src: String,
}

/// One row of images.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportView {
    /// View name.
    pub name: String,
    /// The images, left to right.
    pub cells: Vec<Cell>,
}

/// One figure (an SVG or image file next to the page).
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// Caption.
    pub title: String,
    /// Path relative to the page.
    pub src: String,
}

/// Everything the page shows.
#[derive(Debug, Clone, Default)]
pub struct Report {
    /// Page title.
    pub title: String,
    /// Key facts of the run (method, prior, preset, steps, time, ...), in order.
    pub summary: Vec<(String, String)>,
    /// Notes shown under the image rows (what the baseline column holds, ...).
    pub notes: Vec<String>,
    /// One row per view.
    pub views: Vec<ReportView>,
    /// The orbit animation, relative to the page.
    pub orbit: Option<String>,
    /// The metrics.
    pub eval: EvalReport,
    /// The training curves.
    pub figures: Vec<Figure>,
}

const STYLE: &str = "body{font-family:sans-serif;margin:1.5em;color:#222;max-width:1400px}\
table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #bbb;padding:3px 8px;\
text-align:right}th{background:#eee}td.l,th.l{text-align:left}\
.row{display:flex;flex-wrap:wrap;gap:10px;margin-bottom:1em}\
figure{margin:0}figcaption{font-size:90%;text-align:center}\
img.v{image-rendering:pixelated;width:200px;border:1px solid #999}\
.note{color:#555;font-size:90%}";

fn img_tag(src: &str, alt: &str, class: &str) -> String {
    format!(
        "<img class=\"{class}\" src=\"{}\" alt=\"{}\" \
         onload=\"this.setAttribute('data-loaded','ok')\" \
         onerror=\"this.setAttribute('data-loaded','error')\">",
        escape(src),
        escape(alt)
    )
}

/// A metric value as the table shows it.
fn cell(v: Option<&Outcome>) -> String {
    match v {
        Some(Outcome::Value(x)) if x.is_infinite() => "∞".into(),
        Some(Outcome::Value(x)) if x.abs() >= 100.0 => format!("{x:.1}"),
        Some(Outcome::Value(x)) => format!("{x:.4}"),
        Some(Outcome::Unavailable(_)) => "n/a".into(),
        None => "–".into(),
    }
}

/// The metric table (rows: regions; columns: metrics in the paper's order) and the reasons of
/// the unavailable metrics, as HTML.
pub fn metric_table_html(eval: &EvalReport) -> String {
    let mut out = String::from("<table><tr><th class=\"l\">region</th>");
    for c in &COLUMNS {
        let title = if c.key == "lpips" {
            "ST-LPIPS"
        } else {
            c.title
        };
        out.push_str(&format!(
            "<th>{} {}</th>",
            title,
            if c.higher_is_better { "↑" } else { "↓" }
        ));
    }
    out.push_str("</tr>\n");
    for region in RegionKind::ALL {
        let keys: Vec<String> = COLUMNS.iter().map(|c| region.key(c.key)).collect();
        if region != RegionKind::Full && keys.iter().all(|k| !eval.values.contains_key(k)) {
            continue;
        }
        out.push_str(&format!("<tr><td class=\"l\">{}</td>", region.label()));
        for k in &keys {
            let title = match eval.values.get(k) {
                Some(Outcome::Unavailable(r)) => format!(" title=\"{}\"", escape(r)),
                _ => String::new(),
            };
            out.push_str(&format!("<td{title}>{}</td>", cell(eval.values.get(k))));
        }
        out.push_str("</tr>\n");
    }
    out.push_str("</table>\n");
    let reasons: Vec<String> = eval
        .values
        .iter()
        .filter_map(|(k, v)| match v {
            Outcome::Unavailable(r) => Some(format!(
                "<li><code>{}</code> unavailable: {}</li>",
                escape(k),
                escape(r)
            )),
            Outcome::Value(_) => None,
        })
        .collect();
    if !reasons.is_empty() {
        out.push_str(&format!("<ul class=\"note\">{}</ul>\n", reasons.join("\n")));
    }
    out
}

/// The page.
pub fn render_html(r: &Report) -> String {
    let mut h = String::new();
    h.push_str("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">");
    h.push_str(&format!("<title>{}</title>", escape(&r.title)));
    h.push_str(&format!("<style>{STYLE}</style></head>\n<body>\n"));
    h.push_str(&format!("<h1>{}</h1>\n<table>\n", escape(&r.title)));
    for (k, v) in &r.summary {
        h.push_str(&format!(
            "<tr><th class=\"l\">{}</th><td class=\"l\">{}</td></tr>\n",
            escape(k),
            escape(v)
        ));
    }
    h.push_str("</table>\n<h2>Views</h2>\n");
    if r.views.is_empty() {
        h.push_str("<p class=\"note\">no view to show</p>\n");
    }
    for v in &r.views {
        h.push_str(&format!(
            "<h3>{}</h3>\n<div class=\"row\">\n",
            escape(&v.name)
        ));
        for c in &v.cells {
            h.push_str(&format!(
                "<figure>{}<figcaption>{}</figcaption></figure>\n",
                img_tag(&c.src, &format!("{}: {}", v.name, c.label), "v"),
                escape(&c.label)
            ));
        }
        h.push_str("</div>\n");
    }
    for n in &r.notes {
        h.push_str(&format!("<p class=\"note\">{}</p>\n", escape(n)));
    }
    if let Some(o) = &r.orbit {
        h.push_str("<h2>Orbit</h2>\n<div class=\"row\"><figure>");
        h.push_str(&img_tag(o, "orbit animation of the trained field", "v"));
        h.push_str("<figcaption>the trained field along a closed path through the input cameras</figcaption></figure></div>\n");
    }
    h.push_str("<h2>Metrics</h2>\n");
    h.push_str(&format!(
        "<p class=\"note\">{} test view(s); gb-eval conventions (PSNR/SSIM as scikit-image, \
         ST-LPIPS AlexNet shift-tolerant, D-PSNR on 8-bit max-normalised disparity). \
         Hover an n/a cell for its reason.</p>\n",
        r.eval.n_images
    ));
    h.push_str(&metric_table_html(&r.eval));
    h.push_str("<h2>Training curves</h2>\n<div class=\"row\">\n");
    for f in &r.figures {
        h.push_str(&format!(
            "<figure>{}<figcaption>{}</figcaption></figure>\n",
            img_tag(&f.src, &f.title, "c"),
            escape(&f.title)
        ));
    }
    h.push_str("</div>\n</body></html>\n");
    h
}

/// `|a - b|` per channel (sizes must match).
pub fn abs_diff(a: &RgbImage, b: &RgbImage) -> Result<RgbImage, InpaintError> {
    if (a.width, a.height) != (b.width, b.height) {
        return Err(InpaintError::Io {
            path: "difference image".into(),
            source: std::io::Error::other(format!(
                "sizes differ: {}x{} vs {}x{}",
                a.width, a.height, b.width, b.height
            )),
        });
    }
    Ok(RgbImage {
        width: a.width,
        height: a.height,
        data: a
            .data
            .iter()
            .zip(&b.data)
            .map(|(x, y)| (x - y).abs())
            .collect(),
    })
}

/// The image with the mask's pixels replaced by a grey / magenta checkerboard (what a method
/// without a prior sees of the view).
pub fn masked_input(img: &RgbImage, mask: &[bool]) -> RgbImage {
    let mut out = img.clone();
    if mask.len() != img.width * img.height {
        return out;
    }
    for y in 0..img.height {
        for x in 0..img.width {
            if mask[y * img.width + x] {
                let c = if (x / 4 + y / 4) % 2 == 0 {
                    [0.5, 0.5, 0.5]
                } else {
                    [0.8, 0.2, 0.8]
                };
                out.set(x, y, c);
            }
        }
    }
    out
}

/// At most `max` points: means over equal buckets of steps.
fn thin(points: Vec<(f64, f64)>, max: usize) -> Vec<(f64, f64)> {
    if points.len() <= max || max == 0 {
        return points;
    }
    let per = points.len().div_ceil(max);
    points
        .chunks(per)
        .map(|c| {
            let n = c.len() as f64;
            let finite: Vec<&(f64, f64)> = c.iter().filter(|p| p.1.is_finite()).collect();
            let y = if finite.is_empty() {
                f64::NAN
            } else {
                finite.iter().map(|p| p.1).sum::<f64>() / finite.len() as f64
            };
            (c.iter().map(|p| p.0).sum::<f64>() / n, y)
        })
        .collect()
}

/// The training curves of a `train_log.jsonl`: `(file stem, chart)` for the loss (log scale),
/// the training-batch PSNR, and, when the method has guidance, the latent gradient norm of
/// each guidance term (log scale). Unparsable lines are skipped.
pub fn charts_from_log(path: &Path) -> Result<Vec<(String, LineChart)>, InpaintError> {
    let text = std::fs::read_to_string(path).map_err(|e| InpaintError::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    let (mut loss, mut recon, mut psnr) = (Vec::new(), Vec::new(), Vec::new());
    let mut norms: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for line in text.lines() {
        let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else {
            continue;
        };
        let Some(step) = v["step"].as_f64() else {
            continue;
        };
        let num = |k: &str| v[k].as_f64().unwrap_or(f64::NAN);
        loss.push((step, num("loss")));
        recon.push((step, num("recon_loss")));
        psnr.push((step, num("psnr")));
        for t in v["guidance"].as_array().into_iter().flatten() {
            let name = t["modality"].as_str().unwrap_or("guidance").to_string();
            let g = t["grad_norm"].as_f64().unwrap_or(f64::NAN);
            match norms.iter_mut().find(|(n, _)| *n == name) {
                Some((_, pts)) => pts.push((step, g)),
                None => norms.push((name, vec![(step, g)])),
            }
        }
    }
    const MAX_POINTS: usize = 800;
    let mut out = Vec::new();
    let mut c = LineChart::new("training loss", "step", "loss").log_y(true);
    c.push(Series::new("total loss", thin(loss, MAX_POINTS)));
    c.push(Series::new(
        "reconstruction (unmasked)",
        thin(recon, MAX_POINTS),
    ));
    out.push(("loss".to_string(), c));
    let mut c = LineChart::new("training-batch PSNR", "step", "PSNR (dB)");
    c.push(Series::new("PSNR", thin(psnr, MAX_POINTS)));
    out.push(("psnr".to_string(), c));
    if !norms.is_empty() {
        let mut c = LineChart::new(
            "guidance: latent gradient norm",
            "step",
            "|grad| of the latents",
        )
        .log_y(true);
        for (name, pts) in norms {
            c.push(Series::new(name, thin(pts, MAX_POINTS)));
        }
        out.push(("guidance_grad_norm".to_string(), c));
    }
    Ok(out)
}

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn page_has_every_image_with_load_hooks_and_the_table() {
        let mut eval = EvalReport::new(&["v".to_string()]);
        eval.set("psnr", 21.5);
        eval.set("psnr_bbox", f64::INFINITY);
        eval.set_unavailable("lpips", "weights <missing>");
        let r = Report {
            title: "run & test".into(),
            summary: vec![("method".into(), "none".into())],
            views: vec![ReportView {
                name: "v".into(),
                cells: vec![
                    Cell {
                        label: "ground truth".into(),
                        src: "report/v_gt.png".into(),
                    },
                    Cell {
                        label: "ours".into(),
                        src: "renders/v_rgb.png".into(),
                    },
                ],
            }],
            orbit: Some("orbit.gif".into()),
            eval,
            figures: vec![Figure {
                title: "loss".into(),
                src: "report/loss.svg".into(),
            }],
            notes: vec!["baseline: n/a".into()],
        };
        let html = render_html(&r);
        assert_eq!(html.matches("<img ").count(), 4);
        assert_eq!(html.matches("onload=").count(), 4);
        assert!(html.contains("run &amp; test"));
        assert!(html.contains(">21.5000<") && html.contains(">∞<"), "{html}");
        assert!(html.contains("weights &lt;missing&gt;"));
        assert!(html.contains("src=\"report/v_gt.png\""));
        assert!(
            !html.contains("<script") && !html.contains("http://") && !html.contains("https://")
        );
    }

    #[test]
    fn charts_read_the_log_and_diff_is_absolute() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("train_log.jsonl");
        std::fs::write(
            &p,
            "{\"step\":0,\"loss\":0.5,\"recon_loss\":0.4,\"psnr\":10.0,\"guidance\":[{\"modality\":\"rgb\",\"grad_norm\":0.1}]}\n\
             {\"step\":1,\"loss\":null,\"recon_loss\":null,\"psnr\":11.0,\"guidance\":[]}\n\
             not json\n",
        )
        .unwrap();
        let charts = charts_from_log(&p).unwrap();
        let names: Vec<&str> = charts.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["loss", "psnr", "guidance_grad_norm"]);
        assert_eq!(charts[1].1.series[0].points, vec![(0.0, 10.0), (1.0, 11.0)]);
        assert!(charts[0].1.series[0].points[1].1.is_nan());

        let a = RgbImage::filled(2, 1, [0.2, 0.5, 1.0]);
        let b = RgbImage::filled(2, 1, [0.5, 0.5, 0.0]);
        let d = abs_diff(&a, &b).unwrap();
        assert!((d.data[0] - 0.3).abs() < 1e-6 && d.data[1] == 0.0 && d.data[2] == 1.0);
        assert!(abs_diff(&a, &RgbImage::filled(1, 1, [0.0; 3])).is_err());
        let m = masked_input(&a, &[true, false]);
        assert_eq!(m.get(0, 0), [0.5, 0.5, 0.5]);
        assert_eq!(m.get(1, 0), a.get(1, 0));
        assert_eq!(thin((0..10).map(|i| (i as f64, 1.0)).collect(), 5).len(), 5);
    }
}
