//! `cargo xtask`: the gb-nerf-rs command line.
//!
//! Every subcommand lives in its own file under `cmd/`. Errors are printed as one clear
//! line (with their causes) and exit with code 2; nothing a user types ends in a panic.

mod cmd;

use clap::{Parser, Subcommand};

/// NeRF object removal with a geometric diffusion prior and Balanced Score Distillation.
#[derive(Parser)]
#[command(name = "cargo xtask", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// List the compute backends and check that each one runs.
    Devices(cmd::devices::Args),
    /// The paper's metrics (PSNR, SSIM, LPIPS, FID, NIMA, BRISQUE, D-FID, D-PSNR) on two folders.
    Eval(cmd::eval::Args),
    /// Fine-tune the geometric prior (LoRA on RGB / normal pairs), or train the tiny prior.
    Finetune(cmd::finetune::Args),
    /// Object removal: train a NeRF on the unmasked pixels and fill the mask (default job).
    Inpaint(cmd::inpaint::Args),
    /// The paper's method grid on one scene: baseline and ablation tables, CSD w3 sweep.
    Ablate(cmd::ablate::Args),
    /// 2D inpainting with a Stable Diffusion inpainting prior (checks that a prior loads).
    InpaintImage(cmd::inpaint_image::Args),
    /// The 2D score-distillation playground: SDS, CSD or BSD on the pixels inside a mask.
    DistillImage(cmd::distill_image::Args),
    /// Run one network component on fixed inputs and write its outputs (parity checks).
    Parity(cmd::parity::Args),
    /// Benchmarks writing bench/results/*.json (`bench eval`, ...).
    Bench(cmd::bench::Args),
    /// Property tests of every file reader (10 000 cases each), report in bench/results.
    Fuzz(cmd::fuzz::Args),
    /// Generate a procedural object-removal scene (stairs, fence) in the SPIn-NeRF layout.
    Scene(cmd::scene::Args),
    /// Summarise a scene folder: views per split, resolution, masks, near/far, warnings.
    SceneInfo(cmd::scene_info::Args),
}

fn main() {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Devices(a) => cmd::devices::run(a),
        Command::Eval(a) => cmd::eval::run(a),
        Command::Finetune(a) => cmd::finetune::run(a),
        Command::Inpaint(a) => cmd::inpaint::run(a),
        Command::Ablate(a) => cmd::ablate::run(a),
        Command::InpaintImage(a) => cmd::inpaint_image::run(a),
        Command::DistillImage(a) => cmd::distill_image::run(a),
        Command::Parity(a) => cmd::parity::run(a),
        Command::Bench(a) => cmd::bench::run(a),
        Command::Fuzz(a) => cmd::fuzz::run(a),
        Command::Scene(a) => cmd::scene::run(a),
        Command::SceneInfo(a) => cmd::scene_info::run(a),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(2);
    }
}
