//! `cargo xtask capture`: your own photos to a scene (`gb_capture`: COLMAP, then the LLFF
//! layout this project loads).
//!
//! ```text
//! cargo xtask capture --images DIR [--masks DIR] --out SCENE [--matcher exhaustive|sequential]
//!     [--colmap PATH] [--focal PX] [--camera pinhole|radial]
//! ```

use std::path::PathBuf;

use gb_capture::{capture, CaptureOptions, Lens, Matcher};

/// Arguments of `cargo xtask capture`.
#[derive(clap::Args)]
pub struct Args {
    /// The photos (png, jpg), at least 3, overlapping.
    #[arg(long)]
    images: PathBuf,
    /// Object masks named after the photos (IMG_0001.jpg -> IMG_0001.png), white on the
    /// object; kept out of COLMAP's features and written as the scene's masks.
    #[arg(long)]
    masks: Option<PathBuf>,
    /// The scene folder to write (its images/, sparse/ and poses_bounds.npy are replaced).
    #[arg(long)]
    out: PathBuf,
    /// `exhaustive` (every pair; up to a few hundred photos) or `sequential` (video frames).
    #[arg(long, value_enum, default_value_t = MatcherArg::Exhaustive)]
    matcher: MatcherArg,
    /// The COLMAP program.
    #[arg(long, default_value = "colmap")]
    colmap: PathBuf,
    /// The focal length in pixels, when known (a calibrated camera): kept fixed instead of
    /// estimated.
    #[arg(long)]
    focal: Option<f64>,
    /// The lens: `pinhole` (no distortion, the default: phones' processed photos) or `radial`
    /// (two radial terms fitted, then the images, poses and masks undistorted to a pinhole
    /// camera: wide or uncorrected lenses).
    #[arg(long, value_enum, default_value_t = CameraArg::Pinhole)]
    camera: CameraArg,
}

/// `--camera`.
#[derive(Clone, Copy, clap::ValueEnum)]
enum CameraArg {
    Pinhole,
    Radial,
}

/// `--matcher`.
#[derive(Clone, Copy, clap::ValueEnum)]
enum MatcherArg {
    Exhaustive,
    Sequential,
}

/// Runs the capture and prints what it made.
pub fn run(args: Args) -> anyhow::Result<()> {
    let opts = CaptureOptions {
        images: args.images,
        masks: args.masks,
        out: args.out.clone(),
        matcher: match args.matcher {
            MatcherArg::Exhaustive => Matcher::Exhaustive,
            MatcherArg::Sequential => Matcher::Sequential,
        },
        colmap: args.colmap,
        focal: args.focal,
        lens: match args.camera {
            CameraArg::Pinhole => Lens::Pinhole,
            CameraArg::Radial => Lens::Radial,
        },
    };
    let report = capture(&opts, |stage| tracing::info!("capture: {stage}"))?;
    if let Some((k1, k2)) = report.distortion {
        println!("radial distortion k1 {k1:.5}, k2 {k2:.5}: undistorted to a pinhole camera");
    }
    println!(
        "wrote {}: {} of {} images registered ({} with a mask), {} points{}; next: cargo xtask inpaint --scene {}",
        args.out.display(),
        report.registered,
        report.images,
        report.masked,
        report.points,
        if report.left_out.is_empty() {
            String::new()
        } else {
            format!("; left out: {}", report.left_out.join(", "))
        },
        args.out.display()
    );
    Ok(())
}
