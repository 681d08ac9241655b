//! `gb-nerf` (in the repository: `cargo xtask`): the gb-nerf-rs command line.
//! `cargo install --path xtask` installs it as `gb-nerf`; it carries the built-in prior and
//! the CLIP tokenizer inside (see [`assets`]), so it runs without the source tree.
//!
//! Every subcommand lives in its own file under `cmd/`. Errors (argument errors included)
//! are printed as one clear line, `error: ...` (with their causes), the last line on stderr,
//! and exit with code 2; nothing a user types ends in a panic. Logs go to stderr without
//! colour codes unless stderr is a terminal, and hide the progress bars while they print.

mod assets;
mod cmd;
mod default_device;
mod memory;

use std::io::IsTerminal;

use clap::error::ErrorKind;
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

/// NeRF object removal with a geometric diffusion prior and Balanced Score Distillation.
#[derive(Parser)]
#[command(name = "cargo xtask", bin_name = "cargo xtask", version, about)]
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
    /// A reference view from the prior: one training view with its mask filled, for
    /// `inpaint --reference VIEW=IMAGE`.
    Fill(cmd::fill::Args),
    /// The 2D score-distillation playground: SDS, CSD or BSD on the pixels inside a mask.
    DistillImage(cmd::distill_image::Args),
    /// Run one network component on fixed inputs and write its outputs (parity checks).
    Parity(cmd::parity::Args),
    /// Benchmarks writing bench/results/*.json (`bench eval`, ...).
    Bench(gb_bench::Args),
    /// Property tests of every file reader (10 000 cases each), report in bench/results.
    Fuzz(cmd::fuzz::Args),
    /// Generate a procedural object-removal scene (stairs, fence, alcove, wall), SPIn-NeRF layout.
    Scene(cmd::scene::Args),
    /// Summarise a scene folder: views per split, resolution, masks, near/far, warnings.
    SceneInfo(cmd::scene_info::Args),
    /// Your own photos to a scene: COLMAP poses (the object masked out) in the LLFF layout.
    Capture(cmd::capture::Args),
    /// The nerfstudio export of a finished run, from its checkpoint (no training).
    Export(cmd::export::Args),
}

/// Logs at `RUST_LOG` (default `info`) on stderr, through the writer that suspends the
/// progress bars of `gb_core::progress` while a line is written.
fn init_logging() {
    let bars = indicatif::MultiProgress::new();
    gb_core::progress::install(bars.clone());
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(tracing_indicatif::IndicatifWriter::<
            tracing_indicatif::writer::Stderr,
        >::new(bars))
        .init();
}

/// How the user runs this command: `cargo xtask` when Cargo started it (in a clone, and in
/// the tests), `gb-nerf` once installed. Usage lines and reproducing commands name it.
pub fn program_name() -> &'static str {
    if std::env::var_os("CARGO").is_some() {
        "cargo xtask"
    } else {
        "gb-nerf"
    }
}

/// Parses the command line; a usage error is printed as one `error: ...` line (exit 2),
/// `--help` and `--version` as clap prints them.
fn parse_cli() -> Cli {
    let name = program_name();
    let parsed = Cli::command()
        .name(name)
        .bin_name(name)
        .try_get_matches()
        .and_then(|m| Cli::from_arg_matches(&m));
    match parsed {
        Ok(cli) => cli,
        Err(e) if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) => {
            e.exit()
        }
        Err(e) if e.kind() == ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => e.exit(),
        Err(e) => {
            eprintln!("error: {}", usage_error_line(&e.render().to_string()));
            std::process::exit(2);
        }
    }
}

/// clap's multi-line usage error as one line: the message, its details, then the usage,
/// without the "For more information" hint.
fn usage_error_line(rendered: &str) -> String {
    let body = rendered.trim_start();
    let body = body.strip_prefix("error:").unwrap_or(body);
    let parts: Vec<&str> = body
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with("For more information"))
        .collect();
    format!("{} (see --help)", parts.join("; "))
}

fn main() {
    let kept = memory::keep_large_blocks();
    default_device::pin_to_command_line();
    init_logging();
    tracing::debug!(
        kept,
        "malloc keeps large freed blocks (xtask/src/memory.rs)"
    );
    let cli = parse_cli();
    if let Err(e) = assets::install() {
        eprintln!("error: {}", gb_core::messages::one_line(&format!("{e:#}")));
        std::process::exit(2);
    }
    let result = match cli.command {
        Command::Devices(a) => cmd::devices::run(a),
        Command::Eval(a) => cmd::eval::run(a),
        Command::Finetune(a) => cmd::finetune::run(a),
        Command::Inpaint(a) => cmd::inpaint::run(a),
        Command::Ablate(a) => cmd::ablate::run(a),
        Command::InpaintImage(a) => cmd::inpaint_image::run(a),
        Command::DistillImage(a) => cmd::distill_image::run(a),
        Command::Fill(a) => cmd::fill::run(a),
        Command::Parity(a) => cmd::parity::run(a),
        Command::Bench(a) => gb_bench::run(a),
        Command::Fuzz(a) => cmd::fuzz::run(a),
        Command::Scene(a) => cmd::scene::run(a),
        Command::SceneInfo(a) => cmd::scene_info::run(a),
        Command::Capture(a) => cmd::capture::run(a),
        Command::Export(a) => cmd::export::run(a),
    };
    if let Err(e) = result {
        eprintln!("error: {}", gb_core::messages::one_line(&format!("{e:#}")));
        std::process::exit(2);
    }
}
