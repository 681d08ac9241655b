//! Full-reference pixel metrics: PSNR and SSIM, over the whole image, a bounding box or a mask.
//!
//! Both follow scikit-image 0.26 exactly and compute in `f64` from the `f32` pixels:
//! - [`psnr`] = `peak_signal_noise_ratio(gt, pred, data_range=1)`, i.e. `10 log10(1 / MSE)` with
//!   the MSE averaged over pixels and the three channels. Identical images give
//!   `f64::INFINITY`; reports write it as the JSON string `"inf"` (see `crate::report`).
//! - [`ssim`] = `structural_similarity(gt, pred, gaussian_weights=True, sigma=1.5,
//!   use_sample_covariance=False, data_range=1, channel_axis=-1)`: an 11-tap Gaussian window
//!   (sigma 1.5, truncate 3.5), K1 = 0.01, K2 = 0.03, population covariances, SciPy's
//!   `reflect` border, the SSIM map averaged per channel after cropping a 5-pixel strip on each
//!   side, then averaged over channels. [`ssim_luminance`] does the same on one channel, the
//!   luminance `0.2125 R + 0.7154 G + 0.0721 B` (scikit-image's `rgb2gray`).
//!
//! Regions ([`Region`]):
//! - `Full`: the whole image.
//! - `BBox`: both images are cropped to the box (columns `x0..x1`, rows `y0..y1`, ends
//!   exclusive) and the metric runs on the crops (SSIM thus crops its border again inside the box,
//!   and the box must be at least 11x11).
//! - `Mask`: PSNR averages the squared error over the mask's pixels (all three channels). SSIM
//!   computes the full SSIM map (scikit-image's `full=True` map, `reflect` border) and averages
//!   it over the mask's pixels and the channels, with NO border cropping, since masks may touch
//!   the border. An empty mask is [`MetricError::EmptyMask`].

pub use gb_core::psnr_from_mse;
use gb_core::RgbImage;

use crate::error::MetricError;

/// Which pixels a metric looks at.
#[derive(Debug, Clone, PartialEq)]
pub enum Region {
    /// The whole image.
    Full,
    /// The crop with columns `x0..x1` and rows `y0..y1` (ends exclusive).
    BBox {
        /// Left column, inclusive.
        x0: usize,
        /// Top row, inclusive.
        y0: usize,
        /// Right column, exclusive.
        x1: usize,
        /// Bottom row, exclusive.
        y1: usize,
    },
    /// One flag per pixel, row-major (`y * width + x`); `true` pixels count.
    Mask(Vec<bool>),
}

impl Region {
    /// The tight bounding box of a row-major mask of `width` columns, or `None` if the mask
    /// selects no pixel.
    pub fn bbox_of_mask(mask: &[bool], width: usize) -> Option<Region> {
        if width == 0 {
            return None;
        }
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for (i, _) in mask.iter().enumerate().filter(|(_, &m)| m) {
            let (x, y) = (i % width, i / width);
            x0 = x0.min(x);
            y0 = y0.min(y);
            x1 = x1.max(x + 1);
            y1 = y1.max(y + 1);
        }
        (x0 != usize::MAX).then_some(Region::BBox { x0, y0, x1, y1 })
    }
}

/// The channels SSIM is computed on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SsimChannels {
    /// R, G and B separately, then averaged (scikit-image `channel_axis=-1`).
    Rgb,
    /// One luminance channel, `0.2125 R + 0.7154 G + 0.0721 B` (scikit-image `rgb2gray`).
    Luminance,
}

/// SSIM constants (Wang et al. 2004, as scikit-image with `gaussian_weights=True`).
const SSIM_SIGMA: f64 = 1.5;
const SSIM_RADIUS: usize = 5; // int(3.5 * 1.5 + 0.5)
const SSIM_WIN: usize = 2 * SSIM_RADIUS + 1;
const SSIM_C1: f64 = 0.01 * 0.01;
const SSIM_C2: f64 = 0.03 * 0.03;

/// PSNR in dB of `pred` against `gt` (data range 1) over `region`; `f64::INFINITY` when the
/// region's pixels are identical.
pub fn psnr(pred: &RgbImage, gt: &RgbImage, region: &Region) -> Result<f64, MetricError> {
    let mse = mse(pred, gt, region)?;
    Ok(psnr_from_mse(mse))
}

/// Mean squared error over `region` (pixels and the three channels), in `f64`.
pub fn mse(pred: &RgbImage, gt: &RgbImage, region: &Region) -> Result<f64, MetricError> {
    check_pair(pred, gt)?;
    let w = pred.width;
    let sq = |i: usize| -> f64 {
        (0..3)
            .map(|c| {
                let d = f64::from(pred.data[i * 3 + c]) - f64::from(gt.data[i * 3 + c]);
                d * d
            })
            .sum()
    };
    let (sum, count) = match region {
        Region::Full => ((0..w * pred.height).map(sq).sum::<f64>(), w * pred.height),
        Region::BBox { x0, y0, x1, y1 } => {
            check_bbox(*x0, *y0, *x1, *y1, w, pred.height)?;
            let sum = (*y0..*y1)
                .flat_map(|y| (*x0..*x1).map(move |x| y * w + x))
                .map(sq)
                .sum();
            (sum, (x1 - x0) * (y1 - y0))
        }
        Region::Mask(mask) => {
            let n = check_mask(mask, w, pred.height)?;
            let sum = mask
                .iter()
                .enumerate()
                .filter(|(_, &m)| m)
                .map(|(i, _)| sq(i))
                .sum();
            (sum, n)
        }
    };
    Ok(sum / (count * 3) as f64)
}

/// Mean SSIM of `pred` against `gt` on RGB over `region` (see the module documentation).
pub fn ssim(pred: &RgbImage, gt: &RgbImage, region: &Region) -> Result<f64, MetricError> {
    ssim_with(pred, gt, region, SsimChannels::Rgb)
}

/// Mean SSIM on the luminance channel only (scikit-image `rgb2gray` weights).
pub fn ssim_luminance(pred: &RgbImage, gt: &RgbImage, region: &Region) -> Result<f64, MetricError> {
    ssim_with(pred, gt, region, SsimChannels::Luminance)
}

/// Mean SSIM on the chosen channels over `region`.
pub fn ssim_with(
    pred: &RgbImage,
    gt: &RgbImage,
    region: &Region,
    channels: SsimChannels,
) -> Result<f64, MetricError> {
    check_pair(pred, gt)?;
    let (w, h) = (pred.width, pred.height);
    match region {
        Region::Full => ssim_cropped_mean(pred, gt, (0, 0, w, h), channels),
        Region::BBox { x0, y0, x1, y1 } => {
            check_bbox(*x0, *y0, *x1, *y1, w, h)?;
            ssim_cropped_mean(pred, gt, (*x0, *y0, *x1, *y1), channels)
        }
        Region::Mask(mask) => {
            let n = check_mask(mask, w, h)?;
            check_ssim_size(w, h)?;
            let planes = planes(pred, gt, (0, 0, w, h), channels);
            let mut total = 0.0;
            for (x, y) in &planes {
                let map = ssim_map(x, y, w, h);
                let s: f64 = map
                    .iter()
                    .zip(mask)
                    .filter(|(_, &m)| m)
                    .map(|(v, _)| v)
                    .sum();
                total += s / n as f64;
            }
            Ok(total / planes.len() as f64)
        }
    }
}

/// SSIM on the crop `(x0, y0, x1, y1)`, map border cropped by the window radius.
fn ssim_cropped_mean(
    pred: &RgbImage,
    gt: &RgbImage,
    crop: (usize, usize, usize, usize),
    channels: SsimChannels,
) -> Result<f64, MetricError> {
    let (w, h) = (crop.2 - crop.0, crop.3 - crop.1);
    check_ssim_size(w, h)?;
    let planes = planes(pred, gt, crop, channels);
    let r = SSIM_RADIUS;
    let mut total = 0.0;
    for (x, y) in &planes {
        let map = ssim_map(x, y, w, h);
        let mut s = 0.0;
        for row in r..h - r {
            s += map[row * w + r..row * w + w - r].iter().sum::<f64>();
        }
        total += s / ((w - 2 * r) * (h - 2 * r)) as f64;
    }
    Ok(total / planes.len() as f64)
}

/// The channel planes `(pred, gt)` of the crop, in `f64`.
fn planes(
    pred: &RgbImage,
    gt: &RgbImage,
    (x0, y0, x1, y1): (usize, usize, usize, usize),
    channels: SsimChannels,
) -> Vec<(Vec<f64>, Vec<f64>)> {
    let extract = |img: &RgbImage, weights: [f64; 3]| -> Vec<f64> {
        let mut out = Vec::with_capacity((x1 - x0) * (y1 - y0));
        for y in y0..y1 {
            for x in x0..x1 {
                let i = (y * img.width + x) * 3;
                out.push(
                    (0..3)
                        .map(|c| weights[c] * f64::from(img.data[i + c]))
                        .sum(),
                );
            }
        }
        out
    };
    match channels {
        SsimChannels::Rgb => (0..3)
            .map(|c| {
                let mut wts = [0.0; 3];
                wts[c] = 1.0;
                (extract(pred, wts), extract(gt, wts))
            })
            .collect(),
        SsimChannels::Luminance => {
            let wts = [0.2125, 0.7154, 0.0721];
            vec![(extract(pred, wts), extract(gt, wts))]
        }
    }
}

/// The SSIM map of two `w x h` planes (scikit-image's `full=True` output).
fn ssim_map(x: &[f64], y: &[f64], w: usize, h: usize) -> Vec<f64> {
    let kernel = gaussian_kernel();
    let blur = |v: &[f64]| gaussian_filter(v, w, h, &kernel);
    let prod = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(p, q)| p * q).collect::<Vec<f64>>();
    let ux = blur(x);
    let uy = blur(y);
    let uxx = blur(&prod(x, x));
    let uyy = blur(&prod(y, y));
    let uxy = blur(&prod(x, y));
    (0..w * h)
        .map(|i| {
            let vx = uxx[i] - ux[i] * ux[i];
            let vy = uyy[i] - uy[i] * uy[i];
            let vxy = uxy[i] - ux[i] * uy[i];
            let a1 = 2.0 * ux[i] * uy[i] + SSIM_C1;
            let a2 = 2.0 * vxy + SSIM_C2;
            let b1 = ux[i] * ux[i] + uy[i] * uy[i] + SSIM_C1;
            let b2 = vx + vy + SSIM_C2;
            (a1 * a2) / (b1 * b2)
        })
        .collect()
}

/// SciPy's normalised 1-D Gaussian weights for sigma 1.5, radius 5.
fn gaussian_kernel() -> [f64; SSIM_WIN] {
    let mut k = [0.0; SSIM_WIN];
    for (i, v) in k.iter_mut().enumerate() {
        let x = i as f64 - SSIM_RADIUS as f64;
        *v = (-0.5 / (SSIM_SIGMA * SSIM_SIGMA) * x * x).exp();
    }
    let sum: f64 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= sum);
    k
}

/// SciPy `gaussian_filter(mode="reflect")`: rows (axis 0) first, then columns (axis 1).
fn gaussian_filter(v: &[f64], w: usize, h: usize, k: &[f64; SSIM_WIN]) -> Vec<f64> {
    let r = SSIM_RADIUS as isize;
    let mut tmp = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let mut s = 0.0;
            for (j, kj) in k.iter().enumerate() {
                let yy = reflect(y as isize + j as isize - r, h);
                s += kj * v[yy * w + x];
            }
            tmp[y * w + x] = s;
        }
    }
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        let row = &tmp[y * w..(y + 1) * w];
        for x in 0..w {
            let mut s = 0.0;
            for (j, kj) in k.iter().enumerate() {
                s += kj * row[reflect(x as isize + j as isize - r, w)];
            }
            out[y * w + x] = s;
        }
    }
    out
}

/// SciPy's `reflect` (half-sample symmetric) index: `d c b a | a b c d | d c b a`.
fn reflect(i: isize, n: usize) -> usize {
    let n = n as isize;
    let period = 2 * n;
    let mut m = i.rem_euclid(period);
    if m >= n {
        m = period - 1 - m;
    }
    m as usize
}

/// Checks that both images are well-formed and the same size.
pub(crate) fn check_pair(pred: &RgbImage, gt: &RgbImage) -> Result<(), MetricError> {
    check_buffer("prediction", pred)?;
    check_buffer("ground truth", gt)?;
    if (pred.width, pred.height) != (gt.width, gt.height) {
        return Err(MetricError::SizeMismatch {
            pred_w: pred.width,
            pred_h: pred.height,
            gt_w: gt.width,
            gt_h: gt.height,
        });
    }
    Ok(())
}

fn check_buffer(which: &'static str, img: &RgbImage) -> Result<(), MetricError> {
    let expected = img.width * img.height * 3;
    if img.data.len() != expected {
        return Err(MetricError::BadBuffer {
            which,
            got: img.data.len(),
            expected,
            width: img.width,
            height: img.height,
            channels: 3,
        });
    }
    Ok(())
}

/// Checks a box against a `width x height` image.
pub(crate) fn check_bbox(
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
    width: usize,
    height: usize,
) -> Result<(), MetricError> {
    if x0 >= x1 || y0 >= y1 || x1 > width || y1 > height {
        return Err(MetricError::BadBBox {
            x0,
            y0,
            x1,
            y1,
            width,
            height,
        });
    }
    Ok(())
}

/// Checks a mask's length and returns its number of selected pixels (never zero).
pub(crate) fn check_mask(mask: &[bool], width: usize, height: usize) -> Result<usize, MetricError> {
    if mask.len() != width * height {
        return Err(MetricError::MaskSize {
            got: mask.len(),
            expected: width * height,
            width,
            height,
        });
    }
    match mask.iter().filter(|&&m| m).count() {
        0 => Err(MetricError::EmptyMask),
        n => Ok(n),
    }
}

fn check_ssim_size(width: usize, height: usize) -> Result<(), MetricError> {
    if width < SSIM_WIN || height < SSIM_WIN {
        return Err(MetricError::TooSmall {
            metric: "SSIM",
            min: SSIM_WIN,
            width,
            height,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: usize, h: usize, phase: f32) -> RgbImage {
        let mut img = RgbImage::filled(w, h, [0.0; 3]);
        for y in 0..h {
            for x in 0..w {
                let v = ((x as f32 * 0.37 + y as f32 * 0.11 + phase).sin() + 1.0) * 0.5;
                img.set(x, y, [v, 1.0 - v, v * v]);
            }
        }
        img
    }

    #[test]
    fn reflect_matches_scipy_convention() {
        let got: Vec<usize> = (-3..7).map(|i| reflect(i, 4)).collect();
        assert_eq!(got, vec![2, 1, 0, 0, 1, 2, 3, 3, 2, 1]);
    }

    #[test]
    fn psnr_of_a_uniform_offset_is_closed_form() {
        let a = RgbImage::filled(8, 6, [0.5, 0.5, 0.5]);
        let b = RgbImage::filled(8, 6, [0.6, 0.4, 0.6]);
        let sq = |a: f32, b: f32| (f64::from(a) - f64::from(b)).powi(2);
        let mse = (2.0 * sq(0.6, 0.5) + sq(0.4, 0.5)) / 3.0;
        let expected = 10.0 * (1.0 / mse).log10();
        let got = psnr(&a, &b, &Region::Full).unwrap();
        assert!((got - expected).abs() < 1e-9, "{got} vs {expected}");
        assert_eq!(psnr(&a, &a, &Region::Full).unwrap(), f64::INFINITY);
    }

    #[test]
    fn mask_psnr_ignores_pixels_outside_the_mask() {
        let a = RgbImage::filled(4, 4, [0.5; 3]);
        let mut b = a.clone();
        b.set(0, 0, [1.0, 1.0, 1.0]);
        let mut mask = vec![true; 16];
        mask[0] = false;
        assert_eq!(psnr(&a, &b, &Region::Mask(mask)).unwrap(), f64::INFINITY);
        let err = psnr(&a, &b, &Region::Mask(vec![false; 16])).unwrap_err();
        assert!(matches!(err, MetricError::EmptyMask), "{err}");
    }

    #[test]
    fn ssim_of_identical_images_is_one_and_drops_with_noise() {
        let a = ramp(24, 20, 0.0);
        let b = ramp(24, 20, 0.4);
        assert!((ssim(&a, &a, &Region::Full).unwrap() - 1.0).abs() < 1e-12);
        let s = ssim(&a, &b, &Region::Full).unwrap();
        assert!(s < 0.99 && s > -1.0, "{s}");
    }

    #[test]
    fn bbox_of_mask_is_tight_and_end_exclusive() {
        let mut mask = vec![false; 5 * 4];
        mask[5 + 1] = true;
        mask[2 * 5 + 3] = true;
        assert_eq!(
            Region::bbox_of_mask(&mask, 5),
            Some(Region::BBox {
                x0: 1,
                y0: 1,
                x1: 4,
                y1: 3
            })
        );
        assert_eq!(Region::bbox_of_mask(&[false; 20], 5), None);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let a = ramp(12, 12, 0.0);
        let b = ramp(13, 12, 0.0);
        assert!(matches!(
            psnr(&a, &b, &Region::Full),
            Err(MetricError::SizeMismatch { .. })
        ));
        let small = ramp(10, 30, 0.0);
        assert!(matches!(
            ssim(&small, &small, &Region::Full),
            Err(MetricError::TooSmall { .. })
        ));
        let bbox = Region::BBox {
            x0: 2,
            y0: 0,
            x1: 20,
            y1: 5,
        };
        assert!(matches!(
            psnr(&a, &a, &bbox),
            Err(MetricError::BadBBox { .. })
        ));
        assert!(matches!(
            ssim(&a, &a, &Region::Mask(vec![true; 3])),
            Err(MetricError::MaskSize { .. })
        ));
    }
}
