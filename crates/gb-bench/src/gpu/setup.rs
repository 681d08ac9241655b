//! The online setup of a GPU machine that reaches a package registry: the Vulkan loader and a
//! venv through `tools/bench/gpu_setup.sh`, then a release re-run (an offline machine takes
//! the bundle of [`super::bundle`] instead).

use std::process::Command;

use anyhow::{bail, Context};

use super::Args;

/// The venv `tools/bench/gpu_setup.sh` makes.
pub(super) const VENV_PYTHON: &str = ".venv-gpu/bin/python";

/// Installs what the GPU run needs, then runs this benchmark again in release with
/// `--no-setup` and the same arguments.
pub(super) fn setup_then_rerun(args: &Args) -> anyhow::Result<()> {
    let python_given = args.python.is_some();
    if !python_given {
        let status = Command::new("bash")
            .arg("tools/bench/gpu_setup.sh")
            .status()
            .context("tools/bench/gpu_setup.sh: cannot start bash")?;
        if !status.success() {
            bail!("tools/bench/gpu_setup.sh failed ({status})");
        }
    }
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    // Burn's `vulkan` feature (SPIR-V, tensor-core matmul and convolutions for f16) when it
    // builds and its first kernels run on this adapter (Mesa 22.3's lavapipe crashes creating
    // a SPIR-V pipeline); otherwise the default WGSL build, with a warning
    let vulkan = Command::new(&cargo)
        .args(["run", "--quiet", "--release", "--package", "xtask"])
        .args([
            "--features",
            "vulkan",
            "--",
            "devices",
            "--device",
            args.device.name(),
        ])
        .status()
        .is_ok_and(|s| s.success());
    if !vulkan {
        tracing::warn!(
            "the `vulkan` feature did not build or run on this adapter: measuring the WGSL build"
        );
    }
    let mut cmd = Command::new(&cargo);
    cmd.args(["run", "--quiet", "--release", "--package", "xtask"]);
    if vulkan {
        cmd.args(["--features", "vulkan"]);
    }
    cmd.arg("--")
        .args(["bench", "gpu", "--no-setup", "--device", args.device.name()])
        .args(["--budget-s", &args.budget_s.to_string()]);
    if let Some(out) = &args.out {
        cmd.arg("--out").arg(out);
    }
    if let Some(py) = &args.python {
        cmd.arg("--python").arg(py);
    }
    let status = cmd.status().context("cannot start cargo")?;
    if !status.success() {
        bail!("the release run of bench gpu failed ({status})");
    }
    Ok(())
}
