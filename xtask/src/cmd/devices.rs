//! `cargo xtask devices`: which backends work on this machine.

use burn::tensor::Tensor;
use gb_core::{BackendKind, Precision};

/// Arguments of `cargo xtask devices`.
#[derive(clap::Args)]
pub struct Args {
    /// Only check this backend.
    #[arg(long, value_enum)]
    device: Option<BackendKind>,
}

/// Runs a small matrix product on each backend and prints the result, the time, the prior's
/// default precision there, and wgpu's shader compiler. Fails (non-zero exit) when a checked
/// backend is unavailable or computes a wrong result, so that scripts (`bench gpu`'s SPIR-V
/// check) can rely on the status.
pub fn run(args: Args) -> anyhow::Result<()> {
    let kinds = match args.device {
        Some(k) => vec![k],
        None => BackendKind::ALL.to_vec(),
    };
    let mut failed = Vec::new();
    for kind in kinds {
        let start = std::time::Instant::now();
        let outcome = std::panic::catch_unwind(|| {
            let device = kind.device();
            let a = Tensor::<2>::ones([64, 64], &device);
            let s: f32 = a.clone().matmul(a).sum().into_scalar::<f32>();
            (s, Precision::default_for(&device))
        });
        match outcome {
            Ok((s, precision)) if s == 64.0 * 64.0 * 64.0 => {
                println!(
                    "{kind:8} ok   ({:.1} ms; prior precision {precision} by default)",
                    start.elapsed().as_secs_f64() * 1e3
                );
                if kind == BackendKind::Wgpu {
                    println!("         shaders: {}", gb_bench::gpu::WGPU_COMPILER);
                }
            }
            Ok((s, _)) => {
                println!("{kind:8} WRONG result {s}");
                failed.push(format!("{kind} (wrong result {s})"));
            }
            Err(_) => {
                println!("{kind:8} unavailable (see the log above)");
                failed.push(format!("{kind} (unavailable)"));
            }
        }
    }
    if !failed.is_empty() {
        anyhow::bail!("backends that do not work here: {}", failed.join(", "));
    }
    Ok(())
}
