//! A small SVG line-chart writer for the run report (`report.html`) and the w3 sweep figure of
//! `cargo xtask ablate`: axes, "nice" ticks, a legend, and an optional log-scale y axis.
//!
//! Issue 8 asks for the curves to be drawn "with a plotting crate". We deliberately do not
//! depend on one (plotters and friends pull a large dependency tree into a workspace whose
//! full rebuild already takes ~40 minutes on the CI machine): a static line chart is ~200
//! lines of string formatting, has no font or system-library requirements, and produces a
//! self-contained SVG that any browser displays. The output is plain SVG 1.1 (no script, no
//! external resources).

use std::fmt::Write as _;

/// One named series of `(x, y)` points; non-finite points (and, on a log axis, non-positive
/// `y`) are skipped and break the line there.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend label.
    pub name: String,
    /// The points, in drawing order.
    pub points: Vec<(f64, f64)>,
    /// Draw a marker at every point (useful for short series such as a parameter sweep).
    pub markers: bool,
}

impl Series {
    /// A series without markers.
    pub fn new(name: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Self {
            name: name.into(),
            points,
            markers: false,
        }
    }

    /// The same series with a marker at every point.
    pub fn with_markers(mut self) -> Self {
        self.markers = true;
        self
    }
}

/// A line chart (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct LineChart {
    /// Title drawn above the plot.
    pub title: String,
    /// Label of the x axis.
    pub x_label: String,
    /// Label of the y axis.
    pub y_label: String,
    /// Logarithmic (base 10) y axis.
    pub log_y: bool,
    /// The series.
    pub series: Vec<Series>,
    /// Width of the SVG in pixels.
    pub width: u32,
    /// Height of the SVG in pixels.
    pub height: u32,
}

/// Line colours, cycled over the series (colour-blind-friendly Okabe-Ito palette).
const COLOURS: [&str; 8] = [
    "#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000", "#F0E442",
];

const MARGIN_LEFT: f64 = 64.0;
const MARGIN_RIGHT: f64 = 16.0;
const MARGIN_TOP: f64 = 32.0;
const MARGIN_BOTTOM: f64 = 44.0;

impl LineChart {
    /// An empty chart of the default size (560 x 300).
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            log_y: false,
            series: Vec::new(),
            width: 560,
            height: 300,
        }
    }

    /// Sets the log-scale y axis.
    pub fn log_y(mut self, log: bool) -> Self {
        self.log_y = log;
        self
    }

    /// Adds a series.
    pub fn push(&mut self, series: Series) {
        self.series.push(series);
    }

    fn usable(&self, (x, y): (f64, f64)) -> bool {
        x.is_finite() && y.is_finite() && (!self.log_y || y > 0.0)
    }

    /// The data range `(x0, x1, y0, y1)` (y in log10 units on a log axis), or `None` when no
    /// point is drawable.
    fn range(&self) -> Option<(f64, f64, f64, f64)> {
        let mut r: Option<(f64, f64, f64, f64)> = None;
        for s in &self.series {
            for &p in s.points.iter().filter(|p| self.usable(**p)) {
                let y = if self.log_y { p.1.log10() } else { p.1 };
                r = Some(match r {
                    None => (p.0, p.0, y, y),
                    Some((a, b, c, d)) => (a.min(p.0), b.max(p.0), c.min(y), d.max(y)),
                });
            }
        }
        r
    }

    /// The SVG document.
    pub fn to_svg(&self) -> String {
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        let (pw, ph) = (
            w - MARGIN_LEFT - MARGIN_RIGHT,
            h - MARGIN_TOP - MARGIN_BOTTOM,
        );
        let mut out = String::new();
        let _ = writeln!(
            out,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{}" height="{}" viewBox="0 0 {} {}" font-family="sans-serif" font-size="11">"#,
            self.width, self.height, self.width, self.height
        );
        let _ = writeln!(
            out,
            r#"<rect x="0" y="0" width="{w}" height="{h}" fill="white"/>"#
        );
        let _ = writeln!(
            out,
            r#"<text x="{}" y="18" text-anchor="middle" font-size="13" font-weight="bold">{}</text>"#,
            w / 2.0,
            escape(&self.title)
        );
        let Some((x0, x1, y0, y1)) = self.range() else {
            let _ = writeln!(
                out,
                r##"<text x="{}" y="{}" text-anchor="middle" fill="#666">no data</text>"##,
                w / 2.0,
                h / 2.0
            );
            out.push_str("</svg>\n");
            return out;
        };
        let (x0, x1) = widen(x0, x1);
        let (y0, y1) = if self.log_y {
            let (a, b) = widen(y0, y1);
            (a.floor(), b.ceil())
        } else {
            let (a, b) = widen(y0, y1);
            let step = nice_step((b - a) / 5.0);
            ((a / step).floor() * step, (b / step).ceil() * step)
        };
        let sx = |x: f64| MARGIN_LEFT + (x - x0) / (x1 - x0) * pw;
        let sy = |y: f64| MARGIN_TOP + ph - (y - y0) / (y1 - y0) * ph;

        // frame, grid and ticks
        let _ = writeln!(
            out,
            r##"<rect x="{MARGIN_LEFT}" y="{MARGIN_TOP}" width="{pw}" height="{ph}" fill="none" stroke="#444"/>"##
        );
        for t in ticks(x0, x1) {
            let x = sx(t);
            let _ = writeln!(
                out,
                r##"<line x1="{x:.1}" y1="{MARGIN_TOP}" x2="{x:.1}" y2="{:.1}" stroke="#ddd"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
                MARGIN_TOP + ph,
                MARGIN_TOP + ph + 14.0,
                format_tick(t)
            );
        }
        let y_ticks: Vec<(f64, String)> = if self.log_y {
            let (a, b) = (y0 as i32, y1 as i32);
            let every = ((b - a) / 6 + 1).max(1);
            (a..=b)
                .filter(|e| (e - a) % every == 0)
                .map(|e| (f64::from(e), format!("1e{e}")))
                .collect()
        } else {
            ticks(y0, y1)
                .into_iter()
                .map(|t| (t, format_tick(t)))
                .collect()
        };
        for (t, label) in y_ticks {
            let y = sy(t);
            let _ = writeln!(
                out,
                r##"<line x1="{MARGIN_LEFT}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
                MARGIN_LEFT + pw,
                MARGIN_LEFT - 4.0,
                y + 4.0,
                escape(&label)
            );
        }
        let _ = writeln!(
            out,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
            MARGIN_LEFT + pw / 2.0,
            h - 8.0,
            escape(&self.x_label)
        );
        let y_label = if self.log_y {
            format!("{} (log scale)", self.y_label)
        } else {
            self.y_label.clone()
        };
        let _ = writeln!(
            out,
            r#"<text transform="translate(14 {:.1}) rotate(-90)" text-anchor="middle">{}</text>"#,
            MARGIN_TOP + ph / 2.0,
            escape(&y_label)
        );

        // the series
        for (i, s) in self.series.iter().enumerate() {
            let colour = COLOURS[i % COLOURS.len()];
            let mut segments: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
            for &p in &s.points {
                if self.usable(p) {
                    let y = if self.log_y { p.1.log10() } else { p.1 };
                    if let Some(seg) = segments.last_mut() {
                        seg.push((sx(p.0), sy(y)));
                    }
                } else if segments.last().is_some_and(|seg| !seg.is_empty()) {
                    segments.push(Vec::new());
                }
            }
            for seg in segments.iter().filter(|s| !s.is_empty()) {
                let pts: Vec<String> = seg.iter().map(|(x, y)| format!("{x:.1},{y:.1}")).collect();
                let _ = writeln!(
                    out,
                    r#"<polyline fill="none" stroke="{colour}" stroke-width="1.5" points="{}"/>"#,
                    pts.join(" ")
                );
                if s.markers {
                    for (x, y) in seg {
                        let _ = writeln!(
                            out,
                            r#"<circle cx="{x:.1}" cy="{y:.1}" r="3" fill="{colour}"/>"#
                        );
                    }
                }
            }
        }

        // the legend, top right inside the plot
        let lx = MARGIN_LEFT + pw - 150.0;
        for (i, s) in self.series.iter().enumerate() {
            let colour = COLOURS[i % COLOURS.len()];
            let ly = MARGIN_TOP + 12.0 + 14.0 * i as f64;
            let _ = writeln!(
                out,
                r#"<line x1="{lx:.1}" y1="{ly:.1}" x2="{:.1}" y2="{ly:.1}" stroke="{colour}" stroke-width="2"/><text x="{:.1}" y="{:.1}">{}</text>"#,
                lx + 18.0,
                lx + 22.0,
                ly + 4.0,
                escape(&s.name)
            );
        }
        out.push_str("</svg>\n");
        out
    }
}

/// A degenerate range widened to a drawable one.
fn widen(a: f64, b: f64) -> (f64, f64) {
    if b - a > 1e-12 * a.abs().max(b.abs()).max(1e-300) {
        (a, b)
    } else {
        let d = if a == 0.0 { 1.0 } else { a.abs() * 0.1 };
        (a - d, b + d)
    }
}

/// One SVG document of `charts` laid out row by row, `columns` to a row (at least one), each
/// in a cell the size of the largest chart: a figure of several panels in one file.
pub fn tile(charts: &[LineChart], columns: usize) -> String {
    let columns = columns.max(1);
    let cell_w = charts.iter().map(|c| c.width).max().unwrap_or(0);
    let cell_h = charts.iter().map(|c| c.height).max().unwrap_or(0);
    let rows = charts.len().div_ceil(columns);
    let (w, h) = (
        cell_w * columns.min(charts.len()) as u32,
        cell_h * rows as u32,
    );
    let mut out = String::new();
    let _ = writeln!(
        out,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}">"#
    );
    for (i, chart) in charts.iter().enumerate() {
        let (x, y) = ((i % columns) as u32 * cell_w, (i / columns) as u32 * cell_h);
        let _ = writeln!(out, r#"<g transform="translate({x},{y})">"#);
        out.push_str(&chart.to_svg());
        out.push_str("</g>\n");
    }
    out.push_str("</svg>\n");
    out
}

/// The "nice" step (1, 2 or 5 times a power of ten) nearest above `raw`.
pub fn nice_step(raw: f64) -> f64 {
    if raw <= 0.0 || !raw.is_finite() {
        return 1.0;
    }
    let p = 10f64.powf(raw.log10().floor());
    let m = raw / p;
    let n = if m <= 1.0 {
        1.0
    } else if m <= 2.0 {
        2.0
    } else if m <= 5.0 {
        5.0
    } else {
        10.0
    };
    n * p
}

/// About five nice tick positions inside `[a, b]`.
pub fn ticks(a: f64, b: f64) -> Vec<f64> {
    let step = nice_step((b - a) / 5.0);
    let first = (a / step).ceil() * step;
    let mut out = Vec::new();
    let mut i = 0;
    loop {
        let t = first + step * f64::from(i);
        if t > b + step * 1e-9 || i > 50 {
            break;
        }
        // snap values such as 0.30000000000000004
        out.push((t / step).round() * step);
        i += 1;
    }
    out
}

fn format_tick(t: f64) -> String {
    let a = t.abs();
    if a == 0.0 {
        "0".into()
    } else if !(1e-3..1e5).contains(&a) {
        format!("{t:.0e}")
    } else if a >= 100.0 || t.fract() == 0.0 {
        format!("{t:.0}")
    } else {
        let s = format!("{t:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// Escapes text for XML / HTML.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_steps_and_ticks() {
        assert_eq!(nice_step(0.23), 0.5);
        assert_eq!(nice_step(13.0), 20.0);
        assert_eq!(nice_step(1.0), 1.0);
        let close = |a: Vec<f64>, b: &[f64]| {
            a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12)
        };
        assert!(close(ticks(0.0, 1.0), &[0.0, 0.2, 0.4, 0.6, 0.8, 1.0]));
        assert!(close(ticks(3.0, 27.0), &[5.0, 10.0, 15.0, 20.0, 25.0]));
        assert!(close(ticks(-1.0, 1.0), &[-1.0, -0.5, 0.0, 0.5, 1.0]));
        assert_eq!(format_tick(0.30000000000000004), "0.3");
        assert_eq!(format_tick(2.0e-5), "2e-5");
    }

    #[test]
    fn chart_has_axes_series_and_legend() {
        let mut c = LineChart::new("loss <train>", "step", "loss").log_y(true);
        c.push(Series::new(
            "loss",
            vec![(0.0, 1.0), (1.0, 0.1), (2.0, 0.01)],
        ));
        c.push(Series::new("bad", vec![(0.0, -1.0), (1.0, f64::NAN)]).with_markers());
        let svg = c.to_svg();
        assert!(svg.starts_with("<svg xmlns=\"http://www.w3.org/2000/svg\""));
        assert!(svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains("loss &lt;train&gt;"), "title escaped");
        assert!(svg.contains(">1e-2<") && svg.contains(">1e0<"), "{svg}");
        assert!(svg.contains("(log scale)"));
        assert_eq!(svg.matches("<polyline").count(), 1, "unusable series drawn");
        assert!(svg.contains(">bad<"), "legend lists every series");
        // first point at the left-bottom... x=0 -> left margin, y=1 -> top (1e0 is the max)
        assert!(svg.contains("points=\"64.0,32.0 "), "{svg}");
    }

    #[test]
    fn tile_places_each_chart_in_its_cell() {
        let chart = |t: &str| {
            let mut c = LineChart::new(t, "x", "y");
            c.push(Series::new("s", vec![(0.0, 1.0), (1.0, 2.0)]).with_markers());
            c
        };
        let charts = [chart("a"), chart("b"), chart("c")];
        let svg = tile(&charts, 2);
        // two columns of 560 x 300 cells, two rows
        assert!(
            svg.starts_with(r#"<svg xmlns="http://www.w3.org/2000/svg" width="1120" height="600""#),
            "{svg}"
        );
        for offset in ["translate(0,0)", "translate(560,0)", "translate(0,300)"] {
            assert_eq!(svg.matches(offset).count(), 1, "{offset} in {svg}");
        }
        assert_eq!(svg.matches("<svg ").count(), 4);
        assert_eq!(svg.matches("</svg>").count(), 4);
        assert!(svg.contains(">a<") && svg.contains(">c<"));
        assert!(tile(&[], 3).contains(r#"width="0" height="0""#));
    }

    #[test]
    fn empty_chart_says_so() {
        let svg = LineChart::new("t", "x", "y").to_svg();
        assert!(svg.contains("no data") && svg.ends_with("</svg>\n"));
    }
}
