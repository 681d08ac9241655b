//! `cargo xtask scene-info`: what a scene folder holds (format detected automatically).

use gb_nerf::scene::llff::{spin_extras, SpinExtras};
use gb_nerf::scene::{load, LoadOptions, SceneFormat, SceneInfo};
use std::path::PathBuf;

/// Arguments of `cargo xtask scene-info`.
#[derive(clap::Args)]
pub struct Args {
    /// The scene folder (LLFF / SPIn-NeRF, Blender / nerfstudio, or a generated scene).
    #[arg(long)]
    scene: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
    /// LLFF: use images_F/ (default: the smallest factor present).
    #[arg(long)]
    factor: Option<u32>,
    /// Scenes without test masks: hold out every n-th view as a test view (fern: 8).
    #[arg(long)]
    holdout_every: Option<usize>,
    /// LLFF: recentre and rescale the scene (NeRF convention: min near bound -> 4/3).
    #[arg(long)]
    normalize: bool,
    /// Blender: background colour for RGBA images, "R,G,B" in [0, 1].
    #[arg(long, default_value = "1,1,1", value_parser = parse_rgb)]
    background: [f32; 3],
}

fn parse_rgb(s: &str) -> Result<[f32; 3], String> {
    let parts: Vec<f32> = s
        .split(',')
        .map(|p| p.trim().parse::<f32>().map_err(|e| format!("'{p}': {e}")))
        .collect::<Result<_, _>>()?;
    match parts[..] {
        [r, g, b] if parts.iter().all(|v| (0.0..=1.0).contains(v)) => Ok([r, g, b]),
        _ => Err(format!(
            "'{s}': expected three numbers in [0, 1] separated by commas"
        )),
    }
}

/// Loads the scene and prints its summary.
pub fn run(args: Args) -> anyhow::Result<()> {
    let mut opts = LoadOptions::default();
    opts.llff.factor = args.factor;
    opts.llff.holdout_every = args.holdout_every;
    opts.llff.normalize = args.normalize;
    opts.blender.holdout_every = args.holdout_every;
    opts.blender.background = args.background;
    let (format, scene) = load(&args.scene, &opts)?;
    let info = SceneInfo::new(format, &scene);
    let extras = match format {
        SceneFormat::Llff => spin_extras(&args.scene, args.factor),
        SceneFormat::Blender => SpinExtras::default(),
    };
    let show = |p: &Option<PathBuf>| p.as_ref().map(|p| p.display().to_string());
    if args.json {
        let mut v = serde_json::to_value(&info)?;
        v["rgb_inpainted"] = serde_json::json!(show(&extras.rgb_inpainted));
        v["depth_inpainted"] = serde_json::json!(show(&extras.depth_inpainted));
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        print!("{}", info.to_text());
        for (label, p) in [
            ("RGB_inpainted", &extras.rgb_inpainted),
            ("Depth_inpainted", &extras.depth_inpainted),
        ] {
            if let Some(p) = show(p) {
                println!("{label:<10} {p}");
            }
        }
    }
    Ok(())
}
