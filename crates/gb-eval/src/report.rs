//! Evaluation reports: the JSON file and the paper's markdown table.
//!
//! # Keys
//! One key per metric and region: `psnr`, `ssim`, `lpips`, `fid`, `nima`, `brisque`, `d_fid`,
//! `d_psnr`, `d_psnr_true` (D-PSNR on the true scale, not in the paper), each optionally
//! suffixed `_bbox` (over the mask's bounding box) or `_mask` (over the mask's pixels). A metric fills the keys it computes with [`Outcome::Value`], or with
//! [`Outcome::Unavailable`] and the reason (missing weights, images too small, ...): a report
//! never holds a made-up number.
//!
//! # JSON
//! ```json
//! { "n_images": 3, "pred": "...", "gt": "...",
//!   "psnr": 27.1, "psnr_mask": "inf", "lpips": null,
//!   "unavailable": { "lpips": "weights not found: ..." },
//!   "per_image": [ { "name": "000.png", "psnr": 26.0 } ] }
//! ```
//! Set-level means sit at the top level; an unavailable metric is `null` there, with its
//! reason under `"unavailable"`. **Infinity** (PSNR of identical images) is written as the
//! string `"inf"` (and `"-inf"`); NaN as `null`. [`json_number`] does the encoding.
//!
//! # Markdown
//! One row per region (all pixels, mask bounding box, mask), one column per metric in the
//! paper's order, PSNR, SSIM, FID, NIMA, BRISQUE, D-FID, D-PSNR, then D-PSNR on the true scale
//! and LPIPS (which the paper does not report), with arrows for the better direction; `n/a`
//! marks an unavailable metric, whose reason follows the table; `-` a metric that was not run.
//!
//! # Adding a metric
//! The columns are already in [`COLUMNS`]; a metric only has to put its values into an
//! [`EvalReport`] under its keys (see [`crate::suite`] for the metric table).

use std::collections::BTreeMap;

use serde_json::{json, Map, Value};

/// The value of one metric key, or why there is none.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// The computed value (may be `f64::INFINITY` for PSNR).
    Value(f64),
    /// The metric could not run; the reason is reported instead of a number.
    Unavailable(String),
}

/// Which pixels a key covers; the key suffix.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RegionKind {
    /// Whole image: no suffix.
    Full,
    /// Mask bounding box: `_bbox`.
    BBox,
    /// Mask pixels: `_mask`.
    Mask,
}

impl RegionKind {
    /// All regions, in table row order.
    pub const ALL: [RegionKind; 3] = [RegionKind::Full, RegionKind::BBox, RegionKind::Mask];

    /// The key for metric `base` over this region (`psnr`, `psnr_bbox`, `psnr_mask`).
    pub fn key(self, base: &str) -> String {
        match self {
            RegionKind::Full => base.to_string(),
            RegionKind::BBox => format!("{base}_bbox"),
            RegionKind::Mask => format!("{base}_mask"),
        }
    }

    /// The row label in the markdown table.
    pub fn label(self) -> &'static str {
        match self {
            RegionKind::Full => "full image",
            RegionKind::BBox => "mask bbox",
            RegionKind::Mask => "mask",
        }
    }
}

/// One column of the table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Column {
    /// Base JSON key.
    pub key: &'static str,
    /// Column title.
    pub title: &'static str,
    /// Whether a higher value is better.
    pub higher_is_better: bool,
}

/// The table's columns in the paper's order (D-PSNR on the true scale and LPIPS, not in the
/// paper, last).
pub const COLUMNS: [Column; 9] = [
    Column {
        key: "psnr",
        title: "PSNR",
        higher_is_better: true,
    },
    Column {
        key: "ssim",
        title: "SSIM",
        higher_is_better: true,
    },
    Column {
        key: "fid",
        title: "FID",
        higher_is_better: false,
    },
    Column {
        key: "nima",
        title: "NIMA",
        higher_is_better: true,
    },
    Column {
        key: "brisque",
        title: "BRISQUE",
        higher_is_better: false,
    },
    Column {
        key: "d_fid",
        title: "D-FID",
        higher_is_better: false,
    },
    Column {
        key: "d_psnr",
        title: "D-PSNR",
        higher_is_better: true,
    },
    Column {
        key: "d_psnr_true",
        title: "D-PSNR (true scale)",
        higher_is_better: true,
    },
    Column {
        key: "lpips",
        title: "LPIPS",
        higher_is_better: false,
    },
];

/// The results of one evaluation run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EvalReport {
    /// Number of image pairs evaluated.
    pub n_images: usize,
    /// Free-form context written at the top of the JSON (folders, device, ...).
    pub context: BTreeMap<String, String>,
    /// Set-level values by key (`psnr`, `ssim_mask`, `fid`, ...).
    pub values: BTreeMap<String, Outcome>,
    /// Per-image values: `(file name, key -> value)`, in pairing order.
    pub per_image: Vec<(String, BTreeMap<String, f64>)>,
}

impl EvalReport {
    /// An empty report for `n_images` pairs named `names`.
    pub fn new(names: &[String]) -> Self {
        Self {
            n_images: names.len(),
            per_image: names.iter().map(|n| (n.clone(), BTreeMap::new())).collect(),
            ..Self::default()
        }
    }

    /// Records a set-level value.
    pub fn set(&mut self, key: impl Into<String>, value: f64) {
        self.values.insert(key.into(), Outcome::Value(value));
    }

    /// Records that `key` could not be computed, and why.
    pub fn set_unavailable(&mut self, key: impl Into<String>, reason: impl Into<String>) {
        self.values
            .insert(key.into(), Outcome::Unavailable(reason.into()));
    }

    /// Records per-image values of `key` (one per image, in pairing order) and their mean as
    /// the set-level value.
    pub fn set_per_image(&mut self, key: &str, values: &[f64]) {
        for ((_, map), v) in self.per_image.iter_mut().zip(values) {
            map.insert(key.to_string(), *v);
        }
        self.set(key, mean(values));
    }

    /// Records the per-image values of `key` that exist (one entry per image, in pairing
    /// order; `None` leaves that image without the key). The set-level value is the
    /// caller's.
    pub fn set_per_image_partial(&mut self, key: &str, values: &[Option<f64>]) {
        for ((_, map), v) in self.per_image.iter_mut().zip(values) {
            if let Some(v) = v {
                map.insert(key.to_string(), *v);
            }
        }
    }

    /// The JSON document (see the module docs).
    pub fn to_json(&self) -> Value {
        let mut root = Map::new();
        root.insert("n_images".into(), json!(self.n_images));
        for (k, v) in &self.context {
            root.insert(k.clone(), json!(v));
        }
        let mut unavailable = Map::new();
        for (k, v) in &self.values {
            match v {
                Outcome::Value(x) => {
                    root.insert(k.clone(), json_number(*x));
                }
                Outcome::Unavailable(reason) => {
                    root.insert(k.clone(), Value::Null);
                    unavailable.insert(k.clone(), json!(reason));
                }
            }
        }
        root.insert("unavailable".into(), Value::Object(unavailable));
        let per_image: Vec<Value> = self
            .per_image
            .iter()
            .map(|(name, vals)| {
                let mut m = Map::new();
                m.insert("name".into(), json!(name));
                for (k, v) in vals {
                    m.insert(k.clone(), json_number(*v));
                }
                Value::Object(m)
            })
            .collect();
        root.insert("per_image".into(), Value::Array(per_image));
        root.insert(
            "inf_encoding".into(),
            json!("PSNR of identical images is the string \"inf\""),
        );
        Value::Object(root)
    }

    /// The markdown table (see the module docs), with the reasons for unavailable metrics.
    pub fn to_markdown(&self) -> String {
        let mut out = String::from("| region |");
        for c in &COLUMNS {
            out.push_str(&format!(
                " {} {} |",
                c.title,
                if c.higher_is_better { "↑" } else { "↓" }
            ));
        }
        out.push_str("\n|---|");
        out.push_str(&"---:|".repeat(COLUMNS.len()));
        out.push('\n');
        for region in RegionKind::ALL {
            let keys: Vec<String> = COLUMNS.iter().map(|c| region.key(c.key)).collect();
            if region != RegionKind::Full && keys.iter().all(|k| !self.values.contains_key(k)) {
                continue;
            }
            out.push_str(&format!("| {} |", region.label()));
            for (c, key) in COLUMNS.iter().zip(&keys) {
                let cell = match self.values.get(key) {
                    Some(Outcome::Value(v)) => format_value(c.key, *v),
                    Some(Outcome::Unavailable(_)) => "n/a".to_string(),
                    None => "-".to_string(),
                };
                out.push_str(&format!(" {cell} |"));
            }
            out.push('\n');
        }
        let reasons: Vec<String> = self
            .values
            .iter()
            .filter_map(|(k, v)| match v {
                Outcome::Unavailable(r) => Some(format!("- `{k}` unavailable: {r}")),
                Outcome::Value(_) => None,
            })
            .collect();
        if !reasons.is_empty() {
            out.push('\n');
            out.push_str(&reasons.join("\n"));
            out.push('\n');
        }
        out.push_str(&format!("\n{} image pair(s).\n", self.n_images));
        out
    }
}

/// Mean of the values (infinite if any is infinite; NaN for an empty slice).
pub fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// A number for JSON: finite values as numbers, `±inf` as the strings `"inf"` / `"-inf"`,
/// NaN as `null`.
pub fn json_number(v: f64) -> Value {
    if v.is_nan() {
        Value::Null
    } else if v == f64::INFINITY {
        json!("inf")
    } else if v == f64::NEG_INFINITY {
        json!("-inf")
    } else {
        json!(v)
    }
}

fn format_value(key: &str, v: f64) -> String {
    if v.is_infinite() {
        return if v > 0.0 { "inf".into() } else { "-inf".into() };
    }
    match key {
        "psnr" | "d_psnr" | "d_psnr_true" | "fid" | "d_fid" | "brisque" => format!("{v:.2}"),
        "nima" => format!("{v:.3}"),
        _ => format!("{v:.4}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_encodes_inf_and_unavailable_with_reason() {
        let mut r = EvalReport::new(&["a.png".into(), "b.png".into()]);
        r.set_per_image("psnr", &[20.0, f64::INFINITY]);
        r.set_per_image("ssim", &[0.5, 0.7]);
        r.set_unavailable("lpips", "weights not found");
        let j = r.to_json();
        assert_eq!(j["psnr"], json!("inf"));
        assert!((j["ssim"].as_f64().unwrap() - 0.6).abs() < 1e-12);
        assert_eq!(j["lpips"], Value::Null);
        assert_eq!(j["unavailable"]["lpips"], json!("weights not found"));
        assert_eq!(j["per_image"][1]["psnr"], json!("inf"));
        assert_eq!(j["per_image"][0]["name"], json!("a.png"));
    }

    #[test]
    fn columns_are_the_papers_order_with_lpips_last() {
        let keys: Vec<&str> = COLUMNS.iter().map(|c| c.key).collect();
        assert_eq!(
            keys,
            [
                "psnr",
                "ssim",
                "fid",
                "nima",
                "brisque",
                "d_fid",
                "d_psnr",
                "d_psnr_true",
                "lpips"
            ]
        );
        let mut r = EvalReport::new(&["a.png".into()]);
        r.set("nima", 5.4321);
        r.set("brisque", 20.0);
        let md = r.to_markdown();
        assert!(
            md.lines().next().unwrap().starts_with(
                "| region | PSNR ↑ | SSIM ↑ | FID ↓ | NIMA ↑ | BRISQUE ↓ | D-FID ↓ | D-PSNR ↑ | D-PSNR (true scale) ↑ | LPIPS ↓ |"
            ),
            "{md}"
        );
        assert!(
            md.contains("| full image | - | - | - | 5.432 | 20.00 | - | - | - | - |"),
            "{md}"
        );
    }

    #[test]
    fn markdown_follows_the_paper_order_and_lists_reasons() {
        let mut r = EvalReport::new(&["a.png".into()]);
        r.set("psnr", 25.0);
        r.set("ssim_mask", 0.25);
        r.set_unavailable("fid", "needs 2 images");
        let md = r.to_markdown();
        let header = md.lines().next().unwrap();
        let order: Vec<usize> = [
            "PSNR",
            "SSIM",
            "FID",
            "NIMA",
            "BRISQUE",
            "D-FID",
            "D-PSNR",
            "D-PSNR (true scale)",
            "LPIPS",
        ]
        .iter()
        .map(|t| header.find(&format!(" {t} ")).unwrap())
        .collect();
        assert!(order.windows(2).all(|w| w[0] < w[1]), "{header}");
        assert!(md.contains("| full image | 25.00 | - | n/a |"), "{md}");
        assert!(md.contains("| mask | - | 0.2500 |"), "{md}");
        assert!(!md.contains("mask bbox"), "{md}");
        assert!(md.contains("`fid` unavailable: needs 2 images"), "{md}");
    }
}
