//! Progress bars that share one [`MultiProgress`] with the log writer, so that a warning
//! printed during training does not break a bar.
//!
//! The CLI creates the `MultiProgress`, hands it to [`install`], and writes its logs through
//! `tracing_indicatif::IndicatifWriter::new(multi)`, which hides the bars while a line is
//! written. Libraries create their bars with [`bar`]; without an installed `MultiProgress`
//! (tests, other programs) a bar draws on stderr by itself, as `ProgressBar::new` does.

use std::sync::OnceLock;

use indicatif::{MultiProgress, ProgressBar, ProgressStyle};

static MULTI: OnceLock<MultiProgress> = OnceLock::new();

/// Registers the program's `MultiProgress`; every later [`bar`] is drawn through it.
/// Returns `false` (and changes nothing) when one is already installed.
pub fn install(multi: MultiProgress) -> bool {
    MULTI.set(multi).is_ok()
}

/// A progress bar of `len` steps, drawn through the installed `MultiProgress` if any.
pub fn bar(len: u64) -> ProgressBar {
    let bar = ProgressBar::new(len);
    match MULTI.get() {
        Some(multi) => multi.add(bar),
        None => bar,
    }
}

/// The bar of a training loop: `total` steps with elapsed and remaining time, at
/// `position` (a resumed run's step), drawn when `show`, hidden otherwise.
pub fn training_bar(total: u64, position: u64, show: bool) -> ProgressBar {
    let bar = if show {
        self::bar(total)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template(
            "{bar:30} {pos}/{len} [{elapsed_precise}<{eta_precise}] {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_position(position);
    bar
}
