//! Reporting of gb-nerf-rs runs and benchmarks, apart from the pipeline: SVG line charts
//! ([`svg`]), the static HTML page of a run ([`page`]), the images of its rows ([`images`]),
//! training curves from a run's log ([`curves`]) and GIF animations ([`gif`]). The pipeline
//! (gb-inpaint) fills these with a run's renders and metrics; the benchmarks (gb-bench) draw
//! their figures with the same charts.

pub mod curves;
pub mod gif;
pub mod images;
pub mod page;
pub mod svg;

use std::path::PathBuf;

/// Why a report file could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A file could not be read or written, or two images do not match.
    #[error("{path}: {source}")]
    Io {
        /// The file (or what was being made).
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}
