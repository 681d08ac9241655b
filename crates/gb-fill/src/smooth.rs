//! The membrane (harmonic) fill: each masked pixel becomes the mean of its 4-neighbours
//! inside the image (Laplace's equation with the known pixels as the boundary), solved by
//! successive over-relaxation from the mean of the known pixels that touch the hole, its
//! factor the optimum for a square as wide as the hole's bounding box.

use gb_core::RgbImage;

use crate::{check, planes, with_masked, FillError};

/// At most this many sweeps.
const MAX_SWEEPS: usize = 5000;
/// Stop when no value moved more than this in a sweep.
const TOLERANCE: f64 = 1e-5;

/// Fills the masked pixels of `image` (`mask` row-major, its size `mask_size`).
pub fn fill(
    image: &RgbImage,
    mask: &[bool],
    mask_size: (usize, usize),
) -> Result<RgbImage, FillError> {
    check(image, mask, mask_size)?;
    let (w, h) = (image.width, image.height);
    let holes: Vec<usize> = (0..w * h).filter(|&i| mask[i]).collect();
    let neighbours = |i: usize| {
        let (x, y) = (i % w, i / w);
        [
            (x > 0).then(|| i - 1),
            (x + 1 < w).then(|| i + 1),
            (y > 0).then(|| i - w),
            (y + 1 < h).then(|| i + w),
        ]
        .into_iter()
        .flatten()
    };
    // SOR's optimal factor for a square of side `side`: 2 / (1 + sin(pi / (side + 1)))
    let (x0, x1, y0, y1) = holes.iter().fold((usize::MAX, 0, usize::MAX, 0), |b, &i| {
        (
            b.0.min(i % w),
            b.1.max(i % w),
            b.2.min(i / w),
            b.3.max(i / w),
        )
    });
    let side = (x1 - x0).max(y1 - y0) + 1;
    let omega = 2.0 / (1.0 + (std::f64::consts::PI / (side + 1) as f64).sin());
    let mut p = planes(image);
    for plane in p.iter_mut() {
        // start from the mean of the known pixels that touch the hole
        let (mut sum, mut n) = (0.0, 0usize);
        for &i in &holes {
            for j in neighbours(i).filter(|&j| !mask[j]) {
                sum += plane[j];
                n += 1;
            }
        }
        let start = if n > 0 { sum / n as f64 } else { 0.5 };
        for &i in &holes {
            plane[i] = start;
        }
        for _ in 0..MAX_SWEEPS {
            let mut moved: f64 = 0.0;
            for &i in &holes {
                let (mut s, mut k) = (0.0, 0usize);
                for j in neighbours(i) {
                    s += plane[j];
                    k += 1;
                }
                let next = plane[i] + omega * (s / k as f64 - plane[i]);
                moved = moved.max((next - plane[i]).abs());
                plane[i] = next;
            }
            if moved < TOLERANCE {
                break;
            }
        }
    }
    Ok(with_masked(image, mask, &p))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_images::{masked_psnr, square};

    #[test]
    fn a_linear_ramp_is_filled_exactly() {
        // a harmonic function is its own membrane fill
        let (w, h) = (40, 30);
        let mut img = RgbImage::filled(w, h, [0.0; 3]);
        for y in 0..h {
            for x in 0..w {
                let v = 0.1 + 0.02 * x as f32 + 0.01 * y as f32;
                img.set(x, y, [v, 1.0 - v, 0.5]);
            }
        }
        let mask = square(w, h, 10, 8, 12);
        let mut holed = img.clone();
        for (i, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
            holed.data[3 * i..3 * i + 3].copy_from_slice(&[0.0; 3]);
        }
        let out = fill(&holed, &mask, (w, h)).unwrap();
        assert!(masked_psnr(&out, &img, &mask) > 60.0);
        // outside the mask nothing changes
        for (i, m) in mask.iter().enumerate() {
            if !m {
                assert_eq!(out.data[3 * i..3 * i + 3], holed.data[3 * i..3 * i + 3]);
            }
        }
    }

    #[test]
    fn bad_masks_are_named() {
        let img = RgbImage::filled(4, 3, [0.5; 3]);
        assert_eq!(
            fill(&img, &[false; 12], (4, 3)).unwrap_err(),
            FillError::EmptyMask
        );
        assert_eq!(
            fill(&img, &[true; 12], (4, 3)).unwrap_err(),
            FillError::NothingKnown
        );
        let e = fill(&img, &[true; 6], (3, 2)).unwrap_err();
        assert_eq!(e.to_string(), "the mask is 3x2 but the image 4x3");
    }
}
