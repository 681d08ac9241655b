//! Burn's default device, pointed at the backend the command runs on.
//!
//! Burn creates some tensors on its default device rather than the caller's: an optimiser
//! state read from a checkpoint (`ModuleOptimizer::load_record`) lands on `Device::default()`
//! and moves to the parameters' device at the first step. That default is the first GPU
//! runtime compiled in (wgpu here), so a `--device flex` run that resumes a checkpoint opened
//! wgpu: a GPU context it never used, and on a machine without a GL driver an `ERROR
//! wgpu_hal::gles::egl` line in its log. Burn reads `BURN_DEVICE` for that default; the
//! command line's `--device` (flex when absent) sets it, unless the user has.

use gb_core::BackendKind;

/// The backend named by `--device X` or `--device=X` in `args`; flex (the commands' default)
/// when there is none or it is not a backend (the command's own parse reports that).
pub fn device_choice(args: &[String]) -> BackendKind {
    let value = args
        .windows(2)
        .find(|w| w[0] == "--device")
        .map(|w| w[1].as_str())
        .or_else(|| args.iter().find_map(|a| a.strip_prefix("--device=")));
    value.and_then(|v| v.parse().ok()).unwrap_or_default()
}

/// Sets `BURN_DEVICE` to [`device_choice`] of this process's arguments, unless it is set.
/// Call it first in `main`, before any thread exists (the environment is process-wide).
pub fn pin_to_command_line() {
    if std::env::var_os("BURN_DEVICE").is_some() {
        return;
    }
    let args: Vec<String> = std::env::args().collect();
    std::env::set_var("BURN_DEVICE", device_choice(&args).name());
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(line: &str) -> Vec<String> {
        line.split_whitespace().map(str::to_string).collect()
    }

    #[test]
    fn the_device_flag_in_either_form_chooses_and_flex_is_the_fallback() {
        let choice = |line: &str| device_choice(&args(line));
        assert_eq!(
            choice("gb-nerf inpaint --device wgpu --out o"),
            BackendKind::Wgpu
        );
        assert_eq!(
            choice("gb-nerf export --run o --device=ndarray"),
            BackendKind::Ndarray
        );
        assert_eq!(choice("gb-nerf eval --device gpu"), BackendKind::Wgpu);
        assert_eq!(choice("gb-nerf inpaint --out o"), BackendKind::Flex);
        assert_eq!(choice("gb-nerf inpaint --device tpu"), BackendKind::Flex);
        assert_eq!(choice("gb-nerf inpaint --device"), BackendKind::Flex);
    }
}
