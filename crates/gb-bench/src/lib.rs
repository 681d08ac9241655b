//! gb-bench: the benchmark commands (`cargo xtask bench <what>`), each writing
//! `bench/results/<what>-*.json` with the machine named and a reference measured in the same
//! run. Like burn's `backend-comparison`, this is program code that the CLI runs: each
//! benchmark is its clap arguments and a `run` that reports errors with `anyhow`.
//!
//! One file per benchmark, with the helpers they share in [`report`] (the machine's
//! description, peak memory, the report writer, the date) and [`python`] (the reference
//! interpreter); [`GridArgs`] are the method-grid flags that `ablate` and `bench quality`
//! share, and [`trade`] runs that grid once per preset. Adding a benchmark: write
//! `<what>.rs` with `pub struct Args` (clap::Args) and `pub fn run(args: Args) ->
//! anyhow::Result<()>`, declare it below, then add one variant to `What` and one arm to
//! [`run`].

pub mod distill;
pub mod eval;
pub mod fill;
pub mod gpu;
mod grid_args;
pub mod nerf;
pub mod pipeline;
pub mod python;
pub mod quality;
pub mod report;
pub mod trade;
pub mod unet;

pub use grid_args::GridArgs;
pub use report::{hostname, machine_description, peak_rss_mb, today, write_report};

/// Arguments of `cargo xtask bench`.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

/// Which benchmark to run.
#[derive(clap::Subcommand)]
enum What {
    /// Time per image of each evaluation metric, against the Python references.
    Eval(eval::Args),
    /// NeRF training speed per preset and backend, against plain PyTorch on this CPU.
    Nerf(nerf::Args),
    /// U-Net / VAE forward time at SD-1.5 size, against diffusers on this CPU.
    Unet(unet::Args),
    /// One guidance step of SDS, CSD and BSD, and BSD's saving over CSD.
    Distill(distill::Args),
    /// Object-removal quality of every method on the procedural scenes, against `none`.
    Quality(quality::Args),
    /// One GB-NeRF training step per phase at a preset, with an SD-1.5-sized prior.
    Pipeline(pipeline::Args),
    /// The speed/accuracy trade: mask-box metrics against wall time per preset and method.
    Trade(trade::Args),
    /// The 2D fills of `cargo xtask fill` against the exact view, and their speed.
    Fill(fill::Args),
    /// Every GPU figure in one file (U-Net, VAE, a full step, NeRF vs flex); `--smoke` at
    /// tiny sizes on any device.
    Gpu(gpu::Args),
}

/// Runs the chosen benchmark.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args.what {
        What::Eval(a) => eval::run(a),
        What::Nerf(a) => nerf::run(a),
        What::Unet(a) => unet::run(a),
        What::Distill(a) => distill::run(a),
        What::Quality(a) => quality::run(a),
        What::Pipeline(a) => pipeline::run(a),
        What::Trade(a) => trade::run(a),
        What::Fill(a) => fill::run(a),
        What::Gpu(a) => gpu::run(a),
    }
}
