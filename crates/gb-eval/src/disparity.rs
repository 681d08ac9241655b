//! Disparity maps for D-PSNR (and D-FID): reading, and the 8-bit convention of the reference.
//!
//! Convention (the reference evaluation, SPIn-NeRF / nerf-pytorch, which saves
//! `to8b(disp / np.max(disp))`):
//! 1. non-finite or negative disparities are set to 0;
//! 2. the map is divided by its own maximum (per image; a maximum of 0 is an error);
//! 3. it is quantised with nerf-pytorch's `to8b`: `uint8(255 * clip(d, 0, 1))`, i.e.
//!    **truncation**, computed in `f64`;
//! 4. the 8-bit value is replicated to three channels and read back as `v / 255` in `f32`,
//!    like any 8-bit RGB image, so PSNR/FID then run on it unchanged.
//!
//! D-PSNR is [`crate::image_metrics::psnr`] on two such images (data range 1, equal to
//! scikit-image's `peak_signal_noise_ratio(gt8, pred8, data_range=255)`).
//! [`d_psnr_true_scale`] (not in the paper) changes step 2 only: both maps are divided by the
//! ground truth's maximum, so the prediction's own nearest point does not rescale it.
//!
//! Files: `.npy` (float32 or float64, shape `[h, w]` or `[h, w, 1]`, C or Fortran order) hold
//! raw values; `.png` / `.jpg` are read as grey and scaled to [0, 1] first (only the ratio to
//! the maximum matters). With [`DepthKind::Depth`] the values are depths and the disparity is
//! `1 / depth` where the depth is positive and finite, 0 elsewhere.

use std::path::{Path, PathBuf};

use gb_core::RgbImage;

use crate::error::MetricError;
use crate::image_metrics::{psnr, Region};

/// A single-channel map, row-major `[height, width]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ScalarMap {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width * height` values.
    pub data: Vec<f32>,
}

/// What a depth file holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DepthKind {
    /// Disparity (inverse depth), used as is.
    #[default]
    Disparity,
    /// Metric or relative depth; converted with `1 / depth`.
    Depth,
}

/// A depth or disparity file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum DisparityReadError {
    /// The file could not be read or parsed.
    #[error("{path}: cannot read depth/disparity map: {reason}")]
    Read {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
}

/// Reads a depth or disparity map (`.npy` or an image file) and returns disparity.
pub fn read_disparity(path: &Path, kind: DepthKind) -> Result<ScalarMap, DisparityReadError> {
    let err = |reason: String| DisparityReadError::Read {
        path: path.to_path_buf(),
        reason,
    };
    let is_npy = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("npy"));
    let mut map = if is_npy {
        let bytes = std::fs::read(path).map_err(|e| err(e.to_string()))?;
        read_npy(&bytes).map_err(err)?
    } else {
        let (width, height, data) = gb_core::read_gray(path).map_err(|e| err(e.to_string()))?;
        ScalarMap {
            width,
            height,
            data,
        }
    };
    if kind == DepthKind::Depth {
        for v in &mut map.data {
            *v = if v.is_finite() && *v > 0.0 {
                1.0 / *v
            } else {
                0.0
            };
        }
    }
    Ok(map)
}

fn read_npy(bytes: &[u8]) -> Result<ScalarMap, String> {
    let npy = gb_core::npy::read_npy(bytes).map_err(|e| e.to_string())?;
    let (height, width) = match npy.shape.as_slice() {
        [h, w] | [h, w, 1] => (*h as usize, *w as usize),
        other => {
            return Err(format!(
                "expected shape [h, w] or [h, w, 1], found {other:?}"
            ))
        }
    };
    if npy.kind != gb_core::npy::NpyKind::Float {
        return Err(format!(
            "expected float32 or float64 values, found dtype {}",
            npy.dtype
        ));
    }
    let data: Vec<f32> = npy.data.into_iter().map(|v| v as f32).collect();
    Ok(ScalarMap {
        width,
        height,
        data,
    })
}

/// Disparity (`1 / depth`, 0 where the depth is not a positive number) as a map.
pub fn disparity_map(depth: &[f32], width: usize, height: usize) -> ScalarMap {
    let data = depth
        .iter()
        .map(|d| {
            if d.is_finite() && *d > 0.0 {
                1.0 / d
            } else {
                0.0
            }
        })
        .collect();
    ScalarMap {
        width,
        height,
        data,
    }
}

/// The reference's 8-bit, 3-channel rendering of a disparity map (see the module docs).
pub fn disparity_to_rgb8(disp: &ScalarMap) -> Result<RgbImage, MetricError> {
    Ok(disparity_to_rgb8_over(disp, max_disparity(disp)?))
}

/// An error when `disp`'s buffer does not hold `width * height` values.
fn check_size(disp: &ScalarMap) -> Result<(), MetricError> {
    let expected = disp.width * disp.height;
    if disp.data.len() != expected {
        return Err(MetricError::BadBuffer {
            which: "disparity",
            got: disp.data.len(),
            expected,
            width: disp.width,
            height: disp.height,
            channels: 1,
        });
    }
    Ok(())
}

/// Disparity as D-PSNR reads it: non-finite and negative values are 0.
fn clean(v: f32) -> f64 {
    if v.is_finite() && v > 0.0 {
        f64::from(v)
    } else {
        0.0
    }
}

/// The largest disparity of `disp` ([`clean`]), checked against its buffer's size; an error
/// when it is not positive.
fn max_disparity(disp: &ScalarMap) -> Result<f64, MetricError> {
    check_size(disp)?;
    let max = disp.data.iter().map(|&v| clean(v)).fold(0.0, f64::max);
    if max <= 0.0 {
        return Err(MetricError::InvalidInput {
            what: "disparity map",
            reason: "its maximum is not positive, so it cannot be normalised by it".into(),
        });
    }
    Ok(max)
}

/// The 8-bit rendering of `disp` divided by `max` instead of its own maximum (steps 1, 3 and
/// 4 of the module docs); values above `max` clip to 255.
fn disparity_to_rgb8_over(disp: &ScalarMap, max: f64) -> RgbImage {
    let mut data = Vec::with_capacity(disp.data.len() * 3);
    for &v in &disp.data {
        let q = (255.0 * (clean(v) / max).clamp(0.0, 1.0)).floor() as u8;
        let f = f32::from(q) / 255.0;
        data.extend_from_slice(&[f, f, f]);
    }
    RgbImage {
        width: disp.width,
        height: disp.height,
        data,
    }
}

/// D-PSNR: PSNR between the 8-bit renderings of two disparity maps over `region`.
pub fn d_psnr(pred: &ScalarMap, gt: &ScalarMap, region: &Region) -> Result<f64, MetricError> {
    psnr(&disparity_to_rgb8(pred)?, &disparity_to_rgb8(gt)?, region)
}

/// D-PSNR on the true scale (gb-nerf-rs's addition; [`d_psnr`] is the paper's): both maps
/// divided by the ground truth's maximum, then rendered and compared as D-PSNR. D-PSNR divides
/// the prediction by its own maximum, so where a run renders the view's nearest point, even
/// far outside `region`, rescales every pixel of it; this one measures the error in `region`
/// alone.
pub fn d_psnr_true_scale(
    pred: &ScalarMap,
    gt: &ScalarMap,
    region: &Region,
) -> Result<f64, MetricError> {
    let max = max_disparity(gt)?;
    check_size(pred)?;
    psnr(
        &disparity_to_rgb8_over(pred, max),
        &disparity_to_rgb8_over(gt, max),
        region,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalises_by_the_maximum_and_truncates() {
        let m = ScalarMap {
            width: 4,
            height: 1,
            data: vec![2.0, 1.0, 0.999, f32::NAN],
        };
        let img = disparity_to_rgb8(&m).unwrap();
        let u8s: Vec<u8> = img
            .data
            .iter()
            .step_by(3)
            .map(|v| (v * 255.0).round() as u8)
            .collect();
        // 255 * 0.5 = 127.5 -> 127 (truncated), 255 * 0.4995 = 127.37 -> 127.
        assert_eq!(u8s, vec![255, 127, 127, 0]);
        assert_eq!(img.data[0..3], [1.0, 1.0, 1.0]);
    }

    #[test]
    fn the_true_scale_ignores_a_nearer_point_outside_the_region() {
        // the truth and a prediction equal to it inside the first three pixels, whose only
        // difference is a nearer point in the fourth: D-PSNR rescales the whole map by it
        let gt = ScalarMap {
            width: 4,
            height: 1,
            data: vec![0.2, 0.4, 0.6, 0.8],
        };
        let pred = ScalarMap {
            data: vec![0.2, 0.4, 0.6, 1.6],
            ..gt.clone()
        };
        let inside = Region::BBox {
            x0: 0,
            y0: 0,
            x1: 3,
            y1: 1,
        };
        assert_eq!(
            d_psnr_true_scale(&pred, &gt, &inside).unwrap(),
            f64::INFINITY
        );
        // own scale: 0.2 / 1.6 = 0.125 -> 31/255 against 0.25 -> 63/255, and so on
        let own = d_psnr(&pred, &gt, &inside).unwrap();
        let mse = [(31.0 - 63.0_f64), (63.0 - 127.0), (95.0 - 191.0)]
            .iter()
            .map(|d| (d / 255.0).powi(2))
            .sum::<f64>()
            / 3.0;
        assert!((own - -10.0 * mse.log10()).abs() < 1e-3, "{own}");
        // the nearer point itself is clipped to the truth's maximum: 255 against 255
        let at = Region::BBox {
            x0: 3,
            y0: 0,
            x1: 4,
            y1: 1,
        };
        assert_eq!(d_psnr_true_scale(&pred, &gt, &at).unwrap(), f64::INFINITY);
        // a depth error inside the region still counts: 0.4 -> 0.3 (127 -> 95)
        let off = ScalarMap {
            data: vec![0.2, 0.3, 0.6, 0.8],
            ..gt.clone()
        };
        let want = -10.0 * ((32.0_f64 / 255.0).powi(2) / 3.0).log10();
        let got = d_psnr_true_scale(&off, &gt, &inside).unwrap();
        assert!((got - want).abs() < 1e-3, "{got} against {want}");
        // an all-zero prediction is a number on this scale, a short buffer an error
        let zero = ScalarMap {
            data: vec![0.0; 4],
            ..gt.clone()
        };
        assert!(d_psnr_true_scale(&zero, &gt, &inside).unwrap() < 10.0);
        let short = ScalarMap {
            data: vec![0.2; 3],
            ..gt.clone()
        };
        assert!(matches!(
            d_psnr_true_scale(&short, &gt, &inside),
            Err(MetricError::BadBuffer { .. })
        ));
    }

    #[test]
    fn all_zero_disparity_is_an_error() {
        let m = ScalarMap {
            width: 2,
            height: 1,
            data: vec![0.0, -1.0],
        };
        assert!(matches!(
            disparity_to_rgb8(&m),
            Err(MetricError::InvalidInput { .. })
        ));
    }

    #[test]
    fn scaled_disparity_gives_infinite_d_psnr() {
        let a = ScalarMap {
            width: 3,
            height: 2,
            data: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
        };
        let b = ScalarMap {
            data: a.data.iter().map(|v| v * 4.0).collect(),
            ..a.clone()
        };
        assert_eq!(d_psnr(&a, &b, &Region::Full).unwrap(), f64::INFINITY);
    }

    use gb_core::npy::encode_raw as npy;

    /// Found by `cargo xtask-fuzz`: a Fortran-order map with a zero side and a huge other
    /// side used to loop over the huge side (a hang); it now reads as the empty map it is.
    #[test]
    fn an_empty_fortran_map_with_a_huge_side_reads_at_once() {
        let bytes = npy(
            "{'descr': '<f4', 'fortran_order': True, 'shape': (1000000000000, 0), }",
            &[],
        );
        let m = read_npy(&bytes).unwrap();
        assert_eq!((m.height, m.width, m.data.len()), (1_000_000_000_000, 0, 0));
    }

    #[test]
    fn fortran_maps_are_reordered_to_rows() {
        let values: Vec<u8> = [1.0f32, 4.0, 2.0, 5.0, 3.0, 6.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let bytes = npy(
            "{'descr': '<f4', 'fortran_order': True, 'shape': (2, 3), }",
            &values,
        );
        let m = read_npy(&bytes).unwrap();
        assert_eq!((m.height, m.width), (2, 3));
        assert_eq!(m.data, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    }
}
