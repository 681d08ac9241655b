//! `cargo xtask bench fill`: the 2D fills of `cargo xtask fill` (`gb_inpaint::fill`) against
//! the exact object-free view, and their speed.
//!
//! - **Quality.** For each scene of `--scenes` and seed of `--seeds` (default: the tuning
//!   seeds 100 and 101), the procedural scene is generated as `bench quality` generates it,
//!   and its reference view (the middle masked training view,
//!   [`gb_inpaint::reference::middle_masked_view`], the one `--reference auto` fills)
//!   is filled by each fill (`fsr`, `smooth`, `prior`). Each is scored against the scene's
//!   `clean/` view: PSNR over the masked pixels and SSIM over the mask's bounding box; the
//!   unfilled view (the object) is the reference row.
//! - **Speed.** One 512x512 image of oblique stripes with a centred square hole of 15% of its
//!   pixels, filled by `fsr` and by `smooth` (the reference), the best of three runs each.
//!   Both fills are single-threaded code.
//!
//! Writes `bench/results/fill-<date>.json` (`fill-speed-<date>.json` with `--speed-only`).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use gb_core::RgbImage;
use gb_eval::image_metrics::{psnr, ssim, Region};
use gb_inpaint::fill::{fill_view, FillOptions, FillWith};
use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};
use serde_json::{json, Value};

/// Arguments of `cargo xtask bench fill`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Comma-separated procedural scenes (stairs, fence, alcove).
    #[arg(long, value_delimiter = ',', default_value = "stairs,fence,alcove")]
    pub scenes: Vec<SceneName>,
    /// Comma-separated scene seeds.
    #[arg(long, value_delimiter = ',', default_value = "100,101")]
    pub seeds: Vec<u64>,
    /// The prior of the `prior` fill.
    #[arg(long, default_value = "tiny")]
    pub prior: String,
    /// Folder of the generated scenes and fills.
    #[arg(long, default_value = "out/bench-fill")]
    pub work: PathBuf,
    /// Folder of the report.
    #[arg(long, default_value = "bench/results")]
    pub out_dir: PathBuf,
    /// Only the speed part.
    #[arg(long)]
    pub speed_only: bool,
}

const FILLS: [FillWith; 3] = [FillWith::Fsr, FillWith::Smooth, FillWith::Prior];

/// Runs the benchmark (module docs).
pub fn run(args: Args) -> anyhow::Result<()> {
    let speed = speed()?;
    let quality = if args.speed_only {
        Value::Null
    } else {
        quality(&args)?
    };
    let doc = json!({
        "what": "2D fills of one view (cargo xtask fill --with fsr|smooth|prior): masked PSNR and \
                 mask-box SSIM against the exact object-free view, and the time of one 512x512 \
                 fill with 15% of the pixels masked",
        "machine": crate::machine_description(),
        "host": crate::hostname(),
        "date": crate::today(),
        "command": std::env::args().collect::<Vec<_>>().join(" "),
        "speed": speed,
        "quality": quality,
    });
    let what = if args.speed_only {
        "fill-speed"
    } else {
        "fill"
    };
    crate::write_report(
        &args.out_dir,
        &format!("{what}-{}.json", crate::today()),
        &doc,
    )?;
    Ok(())
}

/// Masked PSNR and mask-box SSIM of `image` against `truth`.
fn scores(image: &RgbImage, truth: &RgbImage, mask: &[bool]) -> anyhow::Result<Value> {
    let bbox = Region::bbox_of_mask(mask, truth.width).context("empty mask")?;
    Ok(json!({
        "psnr_mask": psnr(image, truth, &Region::Mask(mask.to_vec()))?,
        "ssim_bbox": ssim(image, truth, &bbox)?,
    }))
}

fn quality(args: &Args) -> anyhow::Result<Value> {
    let mut rows = Vec::new();
    for &name in &args.scenes {
        for &seed in &args.seeds {
            let dir = args.work.join(format!("{name}-scene-seed-{seed}"));
            let opts = ProceduralOptions {
                name,
                seed,
                ..Default::default()
            };
            procedural::write(&opts, &dir)
                .with_context(|| format!("generating {name} into {}", dir.display()))?;
            let (_, scene) = gb_nerf::scene::load(&dir, &gb_nerf::scene::LoadOptions::default())?;
            let v = gb_inpaint::reference::middle_masked_view(&scene)
                .with_context(|| format!("{}: no masked training view", dir.display()))?;
            let view = v.name.clone();
            let mask = &v.mask.as_ref().context("the reference view's mask")?.data;
            let clean_png = dir.join("clean").join(format!("{view}.png"));
            let truth = gb_core::read_rgb(&clean_png, None)
                .with_context(|| format!("reading {}", clean_png.display()))?;
            let mut row = json!({
                "scene": name.to_string(),
                "seed": seed,
                "view": view,
                "masked_pixels": mask.iter().filter(|m| **m).count(),
                "object": scores(&v.image, &truth, mask)?,
            });
            for with in FILLS {
                let opts = FillOptions {
                    with,
                    prior: args.prior.clone(),
                    ..Default::default()
                };
                let t = Instant::now();
                let filled = fill_view(&scene, &dir, &view, &opts)?;
                let seconds = t.elapsed().as_secs_f64();
                let png = args
                    .work
                    .join(format!("{name}-{seed}-{view}-{}.png", with.name()));
                gb_core::write_rgb_png(&png, &filled.image)
                    .with_context(|| format!("writing {}", png.display()))?;
                let mut s = scores(&filled.image, &truth, mask)?;
                s["seconds"] = json!(seconds);
                row[with.name()] = s;
            }
            tracing::info!(%row, "fill");
            rows.push(row);
        }
    }
    // per scene: the mean over seeds of each fill's scores
    let mut means = serde_json::Map::new();
    for name in &args.scenes {
        let of: Vec<&Value> = rows
            .iter()
            .filter(|r| r["scene"] == name.to_string())
            .collect();
        let mut m = serde_json::Map::new();
        for col in ["object", "fsr", "smooth", "prior"] {
            let mean = |key: &str| {
                of.iter().filter_map(|r| r[col][key].as_f64()).sum::<f64>() / of.len() as f64
            };
            m.insert(
                col.into(),
                json!({ "psnr_mask": mean("psnr_mask"), "ssim_bbox": mean("ssim_bbox") }),
            );
        }
        means.insert(name.to_string(), Value::Object(m));
    }
    Ok(json!({
        "prior": args.prior,
        "seeds": args.seeds,
        "rows": rows,
        "mean_over_seeds": means,
    }))
}

/// The 512x512 stripes and their 15% hole (module docs).
fn speed_case() -> (RgbImage, Vec<bool>) {
    let (w, h) = (512usize, 512usize);
    let side = ((0.15 * (w * h) as f64).sqrt()).round() as usize;
    let (x0, y0) = ((w - side) / 2, (h - side) / 2);
    let mut img = RgbImage::filled(w, h, [0.0; 3]);
    let mut mask = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let a = (2.0 * std::f32::consts::PI * (x as f32 + 0.5 * y as f32) / 23.0).sin();
            let b = (2.0 * std::f32::consts::PI * (0.3 * x as f32 - y as f32) / 11.0).cos();
            img.set(
                x,
                y,
                [0.5 + 0.25 * a + 0.15 * b, 0.5 + 0.3 * a, 0.5 - 0.2 * b],
            );
            mask[y * w + x] = (x0..x0 + side).contains(&x) && (y0..y0 + side).contains(&y);
        }
    }
    (img, mask)
}

fn speed() -> anyhow::Result<Value> {
    let (img, mask) = speed_case();
    let size = (img.width, img.height);
    let best = |f: &dyn Fn() -> anyhow::Result<RgbImage>| -> anyhow::Result<(f64, RgbImage)> {
        let mut best = f64::INFINITY;
        let mut out = None;
        for _ in 0..3 {
            let t = Instant::now();
            out = Some(f()?);
            best = best.min(t.elapsed().as_secs_f64());
        }
        Ok((best, out.expect("three runs")))
    };
    let settings = gb_fill::FsrSettings::default();
    let (fsr_s, fsr) = best(&|| Ok(gb_fill::fsr::fill(&img, &mask, size, &settings)?))?;
    let (smooth_s, smooth) = best(&|| Ok(gb_fill::smooth::fill(&img, &mask, size)?))?;
    let masked = mask.iter().filter(|m| **m).count();
    Ok(json!({
        "image": [img.width, img.height],
        "masked_pixels": masked,
        "masked_share": masked as f64 / mask.len() as f64,
        "fsr_settings": settings,
        "fsr_seconds": fsr_s,
        "smooth_seconds_reference": smooth_s,
        "fsr_over_smooth": fsr_s / smooth_s,
        "fsr_psnr_mask": psnr(&fsr, &img, &Region::Mask(mask.clone()))?,
        "smooth_psnr_mask": psnr(&smooth, &img, &Region::Mask(mask))?,
    }))
}
