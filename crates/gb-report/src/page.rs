//! The run report's page, `report.html`: one static page (no script, no external resource)
//! with, per view, a row of images; the orbit animation; the metric table (every key of a
//! run's [`gb_eval::report::EvalReport`], unavailable ones with their reason); and figures
//! (the training curves as SVG files, [`crate::svg`]).
//!
//! Every `<img>` carries `onload` / `onerror` attributes that set `data-loaded="ok"` or
//! `data-loaded="error"`: a headless browser's `--dump-dom` then tells whether each image
//! really loaded (tests/tests/report_browser.rs).

use gb_eval::report::{EvalReport, Outcome, RegionKind, COLUMNS};

use crate::svg::escape;

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
         ST-LPIPS AlexNet shift-tolerant, D-PSNR on 8-bit max-normalised disparity, its true \
         scale with both maps over the truth's maximum). \
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
}
