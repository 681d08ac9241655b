//! The metric suite: every metric of this crate over the pairs of a [`PairSource`], as one
//! [`EvalReport`]. `cargo xtask eval` runs it on folders ([`crate::eval_inputs::EvalInputs`])
//! and a run on its test views ([`PairSet`]); both get the same keys, regions, weights rule
//! and reasons.
//!
//! | metric | keys | needs |
//! |---|---|---|
//! | PSNR, SSIM | `psnr`, `ssim` + `_bbox`, `_mask` | ground truth |
//! | LPIPS (ST-LPIPS AlexNet by default, [`LpipsNet`]) | `lpips`, `lpips_bbox` | ground truth, weights |
//! | D-PSNR (8-bit max-normalised disparity) | `d_psnr` + `_bbox`, `_mask` | depth |
//! | D-PSNR, true scale (both over the truth's max) | `d_psnr_true` + `_bbox`, `_mask` | depth |
//! | FID, D-FID (at least [`FID_MIN_IMAGES`] pairs) | `fid`, `d_fid` | ground truth (+ depth), weights |
//! | BRISQUE, NIMA (no reference) | `brisque`, `nima` + `_bbox` (the mask box's crop) | weights |
//!
//! `_bbox` keys cover the mask's bounding box and `_mask` keys its pixels, when the source
//! has masks. The weights are files in one folder (`$GB_TEST_DATA/weights` by default,
//! [`crate::default_weights_dir`]). A metric that cannot be computed is recorded unavailable
//! with its reason, never as a number; only an unreadable input file is an error.
//!
//! # Adding a metric
//! One entry in the `METRICS` table (its name, the regions it covers, the inputs it needs) and its
//! function in `metrics.rs`; its name must be one of [`crate::report::COLUMNS`].

mod lpips_net;
mod metrics;
mod source;
mod values;

use std::path::PathBuf;

use gb_core::Devices;
use indicatif::{ProgressBar, ProgressStyle};

pub use lpips_net::{LpipsModel, LpipsNet};
pub use source::{Disparity, EvalPair, Images, Input, PairSet, PairSource};
pub use values::{bbox_crop, NO_REFERENCE_MIN_CROP};

use crate::eval_inputs::InputError;
use crate::report::{EvalReport, RegionKind, COLUMNS};

/// FID and D-FID need at least this many pairs by default: the Frechet distance of a
/// handful of 2048-dimensional features is dominated by the covariance estimate's noise.
pub const FID_MIN_IMAGES: usize = 8;

/// Sets with at least this many pairs get progress bars (when asked for).
const PROGRESS_MIN: usize = 8;

/// Which metrics to run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Selection {
    /// Every metric; one whose inputs the source lacks is unavailable, with the reason.
    All,
    /// Every metric whose inputs the source has.
    Available,
    /// These metrics (names of [`crate::report::COLUMNS`]), in this order.
    Only(Vec<String>),
}

impl Selection {
    /// A `--metrics` list: names are trimmed, lower-cased, `-` read as `_`, duplicates
    /// dropped; an unknown name is an error listing the known ones.
    pub fn parse(list: &[String]) -> Result<Self, SuiteError> {
        let known: Vec<&str> = COLUMNS.iter().map(|c| c.key).collect();
        let mut out = Vec::new();
        for raw in list {
            let name = raw.trim().to_ascii_lowercase().replace('-', "_");
            if !known.contains(&name.as_str()) {
                return Err(SuiteError::UnknownMetric {
                    name: raw.clone(),
                    known: known.join(", "),
                });
            }
            if !out.contains(&name) {
                out.push(name);
            }
        }
        Ok(Selection::Only(out))
    }
}

/// How the suite runs.
#[derive(Debug, Clone)]
pub struct SuiteOptions {
    /// Which metrics.
    pub metrics: Selection,
    /// The weights folder, if any.
    pub weights: Option<PathBuf>,
    /// NIMA's weights file, when not the weights folder's
    /// `nima_inception_resnet_v2_ava.safetensors` (none ship with the project).
    pub nima_weights: Option<PathBuf>,
    /// The devices of the network metrics (they run on `device.plain`).
    pub device: Devices,
    /// The LPIPS network.
    pub lpips_net: LpipsNet,
    /// Minimum number of pairs for FID / D-FID.
    pub fid_min_images: usize,
    /// Draw progress bars on sets of 8 pairs or more.
    pub progress: bool,
}

impl SuiteOptions {
    /// Every metric, weights from `weights` or else [`crate::default_weights_dir`], ST-LPIPS,
    /// FID from [`FID_MIN_IMAGES`] pairs, no progress bars.
    pub fn new(weights: Option<PathBuf>, device: impl Into<Devices>) -> Self {
        Self {
            metrics: Selection::All,
            weights: weights.or_else(crate::default_weights_dir),
            nima_weights: None,
            device: device.into(),
            lpips_net: LpipsNet::default(),
            fid_min_images: FID_MIN_IMAGES,
            progress: false,
        }
    }
}

/// The suite could not run.
#[derive(Debug, thiserror::Error)]
pub enum SuiteError {
    /// A `--metrics` name is not a metric.
    #[error("unknown metric '{name}': expected some of {known}")]
    UnknownMetric {
        /// The name given.
        name: String,
        /// The known names.
        known: String,
    },
    /// An input file could not be read.
    #[error(transparent)]
    Input(#[from] InputError),
}

/// One entry of the metric table.
struct Metric {
    /// Base key and `--metrics` name.
    name: &'static str,
    /// The regions it covers (its keys; `_bbox` and `_mask` only where the source has masks).
    regions: &'static [RegionKind],
    /// The inputs it needs besides the renders.
    needs: &'static [Input],
    /// Computes it and fills its keys.
    run: fn(&Ctx, &Metric, &mut EvalReport) -> Result<(), InputError>,
}

const ALL: &[RegionKind] = &RegionKind::ALL;
const FULL_BBOX: &[RegionKind] = &[RegionKind::Full, RegionKind::BBox];
const SET: &[RegionKind] = &[RegionKind::Full];

/// The metric table, in the order the metrics run.
const METRICS: &[Metric] = &[
    Metric {
        name: "psnr",
        regions: ALL,
        needs: &[Input::Reference],
        run: metrics::psnr,
    },
    Metric {
        name: "ssim",
        regions: ALL,
        needs: &[Input::Reference],
        run: metrics::ssim,
    },
    Metric {
        name: "lpips",
        regions: FULL_BBOX,
        needs: &[Input::Reference],
        run: metrics::lpips,
    },
    Metric {
        name: "d_psnr",
        regions: ALL,
        needs: &[Input::Reference, Input::Depth],
        run: metrics::d_psnr,
    },
    Metric {
        name: "d_psnr_true",
        regions: ALL,
        needs: &[Input::Reference, Input::Depth],
        run: metrics::d_psnr_true,
    },
    Metric {
        name: "fid",
        regions: SET,
        needs: &[Input::Reference],
        run: metrics::fid,
    },
    Metric {
        name: "d_fid",
        regions: SET,
        needs: &[Input::Reference, Input::Depth],
        run: metrics::d_fid,
    },
    Metric {
        name: "brisque",
        regions: FULL_BBOX,
        needs: &[],
        run: metrics::brisque,
    },
    Metric {
        name: "nima",
        regions: FULL_BBOX,
        needs: &[],
        run: metrics::nima,
    },
];

/// What a metric function gets.
struct Ctx<'a> {
    source: &'a dyn PairSource,
    opts: &'a SuiteOptions,
}

impl Ctx<'_> {
    /// The regions of `metric` that apply to this source.
    fn regions(&self, metric: &Metric) -> Vec<RegionKind> {
        let masks = self.source.has_masks();
        metric
            .regions
            .iter()
            .copied()
            .filter(|r| *r == RegionKind::Full || masks)
            .collect()
    }

    /// Marks every key of `metric` unavailable.
    fn unavailable(&self, metric: &Metric, report: &mut EvalReport, reason: &str) {
        for r in self.regions(metric) {
            report.set_unavailable(r.key(metric.name), reason);
        }
    }

    /// The weights file `name`, or why it is not there.
    fn weights_file(&self, name: &str) -> Result<PathBuf, String> {
        match &self.opts.weights {
            Some(dir) if dir.join(name).is_file() => Ok(dir.join(name)),
            Some(dir) => Err(format!(
                "weights file {} not found",
                dir.join(name).display()
            )),
            None => Err(format!(
                "no weights folder (pass --weights DIR holding {name}, or set GB_TEST_DATA)"
            )),
        }
    }

    /// A progress bar over the pairs for `what` (hidden unless asked for, and on short sets).
    fn progress(&self, what: &str) -> ProgressBar {
        let len = self.source.len();
        if !self.opts.progress || len < PROGRESS_MIN {
            return ProgressBar::hidden();
        }
        let pb = gb_core::progress::bar(len as u64);
        if let Ok(style) = ProgressStyle::with_template("{msg:>8} [{bar:30}] {pos}/{len} {elapsed}")
        {
            pb.set_style(style);
        }
        pb.set_message(what.to_string());
        pb
    }
}

/// Runs the selected metrics over `source` (see the module docs). Fails only on an input
/// file that cannot be read; every other problem is an unavailable metric with its reason.
pub fn evaluate(source: &dyn PairSource, opts: &SuiteOptions) -> Result<EvalReport, SuiteError> {
    let names: Vec<String> = (0..source.len())
        .map(|i| source.name(i).to_string())
        .collect();
    let mut report = EvalReport::new(&names);
    report
        .context
        .insert("device".into(), opts.device.name().to_string());
    report
        .context
        .insert("lpips_net".into(), opts.lpips_net.name().to_string());
    if let Some(w) = &opts.weights {
        report
            .context
            .insert("weights".into(), w.display().to_string());
    }
    let ctx = Ctx { source, opts };
    let chosen: Vec<(&str, Option<&Metric>)> = match &opts.metrics {
        Selection::All | Selection::Available => {
            METRICS.iter().map(|m| (m.name, Some(m))).collect()
        }
        Selection::Only(list) => list
            .iter()
            .map(|n| (n.as_str(), METRICS.iter().find(|m| m.name == n)))
            .collect(),
    };
    tracing::info!(pairs = source.len(), metrics = ?chosen.iter().map(|c| c.0).collect::<Vec<_>>(), "evaluating");
    for (name, metric) in chosen {
        let Some(metric) = metric else {
            report.set_unavailable(name, "not implemented in this build");
            continue;
        };
        let missing = metric.needs.iter().find_map(|n| source.missing(*n));
        match missing {
            Some(_) if opts.metrics == Selection::Available => {}
            Some(reason) => ctx.unavailable(metric, &mut report, &reason),
            None => (metric.run)(&ctx, metric, &mut report)?,
        }
    }
    Ok(report)
}

#[cfg(test)]
mod tests;
