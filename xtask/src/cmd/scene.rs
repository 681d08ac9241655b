//! `cargo xtask scene`: generate a procedural object-removal scene (SPIn-NeRF layout).

use anyhow::Context;
use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};
use gb_nerf::scene::Split;
use std::path::PathBuf;

/// Arguments of `cargo xtask scene`.
#[derive(clap::Args)]
pub struct Args {
    /// Scene: stairs, fence, alcove or wall.
    #[arg(long)]
    name: SceneName,
    /// Output folder (absent, empty, or an earlier generated scene).
    #[arg(long)]
    out: PathBuf,
    /// Seed of textures, object placement and camera wobble.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Image width in pixels (8 to 8192).
    #[arg(long, default_value_t = 200, value_parser = gb_core::cli::image_side)]
    width: usize,
    /// Image height in pixels (8 to 8192).
    #[arg(long, default_value_t = 150, value_parser = gb_core::cli::image_side)]
    height: usize,
    /// Number of views (train + test).
    #[arg(long, default_value_t = 24)]
    views: usize,
    /// Number of test views (without the object); default: a third of the views.
    #[arg(long)]
    test_views: Option<usize>,
    /// Grow the masks by this many pixels.
    #[arg(long, default_value_t = 0)]
    dilate: usize,
    /// Also write RGB / normal-map pairs with captions to this folder.
    #[arg(long)]
    pairs: Option<PathBuf>,
}

/// Generates the scene, writes it, and prints a one-line summary.
pub fn run(args: Args) -> anyhow::Result<()> {
    let opts = ProceduralOptions {
        name: args.name,
        seed: args.seed,
        width: args.width,
        height: args.height,
        views: args.views,
        test_views: args.test_views.unwrap_or(args.views / 3),
        dilate: args.dilate,
    };
    let start = std::time::Instant::now();
    let scene = procedural::write(&opts, &args.out)?;
    if let Some(dir) = &args.pairs {
        procedural::write_scene_pairs(dir, &scene)
            .with_context(|| format!("writing pairs to {}", dir.display()))?;
    }
    let test = scene
        .views
        .iter()
        .filter(|v| v.split == Split::Test)
        .count();
    println!(
        "wrote {} to {}: {} views ({} train, {} test), {}x{}, seed {}, {:.2} s",
        opts.name,
        args.out.display(),
        scene.views.len(),
        scene.views.len() - test,
        test,
        opts.width,
        opts.height,
        opts.seed,
        start.elapsed().as_secs_f64()
    );
    Ok(())
}
