//! `cargo xtask eval`: the paper's metrics on two folders of images.
//!
//! ```text
//! cargo xtask eval --pred DIR --gt DIR [--masks DIR] [--pred-depth DIR --gt-depth DIR]
//!     [--metrics psnr,ssim,lpips,...] [--weights DIR] [--nima-weights FILE] [--json FILE]
//!     [--markdown FILE]
//! ```
//! Files pair by sorted name (see `gb_eval::eval_inputs`); the metrics are gb-eval's suite
//! (`gb_eval::suite`, the same one a run scores its test views with). The table is printed
//! on stdout and written to `--markdown`, the JSON (format in `gb_eval::report`) to `--json`.

use std::path::PathBuf;

use anyhow::Context;
use gb_core::BackendKind;
use gb_eval::disparity::DepthKind;
use gb_eval::eval_inputs::EvalInputs;
use gb_eval::suite::{evaluate, LpipsNet, Selection, SuiteOptions, FID_MIN_IMAGES};

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
    /// FID and D-FID need at least this many pairs (fewer: reported unavailable).
    #[arg(long, default_value_t = FID_MIN_IMAGES)]
    fid_min_images: usize,
    /// Write the JSON report here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Write the markdown table here.
    #[arg(long)]
    markdown: Option<PathBuf>,
    /// Backend for the network metrics.
    #[arg(long, value_enum)]
    device: Option<BackendKind>,
    /// LPIPS network: ST-LPIPS AlexNet (weights `stlpips_alex_shift_tolerant.safetensors`),
    /// or standard LPIPS with user weights `lpips_alex.safetensors` / `lpips_vgg.safetensors`
    /// (the `lpips` package's state dict) in the weights folder.
    #[arg(long, value_enum, default_value = "st-alex")]
    lpips_net: LpipsNetArg,
}

/// `--lpips-net`.
#[derive(Clone, Copy, clap::ValueEnum)]
enum LpipsNetArg {
    /// Shift-tolerant LPIPS, AlexNet.
    StAlex,
    /// Standard LPIPS, AlexNet.
    Alex,
    /// Standard LPIPS, VGG16.
    Vgg,
}

/// `--depth-kind`.
#[derive(Clone, Copy, clap::ValueEnum)]
enum DepthKindArg {
    Disparity,
    Depth,
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
    let device = args.device.unwrap_or_default();
    let options = SuiteOptions {
        metrics: match &args.metrics {
            Some(list) => Selection::parse(list)?,
            None => Selection::Available,
        },
        nima_weights: args.nima_weights.clone(),
        lpips_net: match args.lpips_net {
            LpipsNetArg::StAlex => LpipsNet::StAlex,
            LpipsNetArg::Alex => LpipsNet::Alex,
            LpipsNetArg::Vgg => LpipsNet::Vgg,
        },
        fid_min_images: args.fid_min_images,
        progress: true,
        ..SuiteOptions::new(args.weights.clone(), device)
    };
    let mut report = evaluate(&inputs, &options)?;
    report
        .context
        .insert("pred".into(), args.pred.display().to_string());
    report
        .context
        .insert("gt".into(), args.gt.display().to_string());

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
