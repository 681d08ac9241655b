//! D-FID: FID between the 8-bit renderings of predicted and ground-truth disparity maps.
//!
//! Each disparity map is normalised by its own maximum and written as an 8-bit, 3-channel
//! image by [`crate::disparity::disparity_to_rgb8`] (the reference evaluation's
//! `to8b(disp / max(disp))`, documented there); FID then runs on those images unchanged.

use crate::disparity::{disparity_to_rgb8, ScalarMap};
use crate::error::MetricError;
use crate::fid::{check_counts, FidError, FidExtractor};

/// D-FID could not be computed.
#[derive(Debug, thiserror::Error)]
pub enum DFidError {
    /// A disparity map could not be rendered to 8 bits (for example its maximum is 0).
    #[error("disparity map {index} of the {set} set: {source}")]
    Disparity {
        /// Which set.
        set: &'static str,
        /// Position in the set.
        index: usize,
        /// The rendering error.
        source: MetricError,
    },
    /// FID itself failed.
    #[error(transparent)]
    Fid(#[from] FidError),
}

/// D-FID between two sets of disparity maps (each needs at least 2 maps).
pub fn d_fid(
    extractor: &FidExtractor,
    pred: &[ScalarMap],
    gt: &[ScalarMap],
) -> Result<f64, DFidError> {
    check_counts(pred.len(), gt.len())?;
    let render = |set: &'static str, maps: &[ScalarMap]| {
        maps.iter()
            .enumerate()
            .map(|(index, m)| {
                disparity_to_rgb8(m).map_err(|source| DFidError::Disparity { set, index, source })
            })
            .collect::<Result<Vec<_>, _>>()
    };
    let p = render("prediction", pred)?;
    let g = render("ground truth", gt)?;
    Ok(extractor.fid(&p, &g)?)
}
