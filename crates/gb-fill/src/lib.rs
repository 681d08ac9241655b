//! 2D fills of the masked pixels of one image that need no weights, for a reference view
//! (`cargo xtask fill --with fsr|smooth`, issue 46) that every user has offline.
//!
//! - [`fsr`]: frequency-selective reconstruction (Seiler and Kaup's frequency-selective
//!   extrapolation, processed block by block as in Genser et al. 2018): each block of the hole
//!   is modelled as a sparse sum of 2D Fourier basis functions fitted to the known pixels
//!   around it, weighted by their distance, so texture and edges run on into the hole.
//! - [`smooth`]: the membrane (harmonic) fill: every masked pixel the mean of its neighbours,
//!   the boundary held. No texture; the weak baseline.
//!
//! Both keep every pixel outside the mask as it is.

mod dft;
mod error;
pub mod fsr;
pub mod smooth;

pub use error::FillError;
pub use fsr::FsrSettings;

use gb_core::RgbImage;

/// Checks that `mask` (row-major, true: fill) matches `image` and leaves something to fill
/// and something known.
pub fn check(image: &RgbImage, mask: &[bool], mask_size: (usize, usize)) -> Result<(), FillError> {
    let (w, h) = (image.width, image.height);
    if mask_size != (w, h) {
        return Err(FillError::SizeMismatch {
            image: (w, h),
            mask: mask_size,
        });
    }
    if mask.len() != w * h {
        return Err(FillError::MaskLength {
            flags: mask.len(),
            pixels: w * h,
        });
    }
    let holes = mask.iter().filter(|m| **m).count();
    if holes == 0 {
        return Err(FillError::EmptyMask);
    }
    if holes == mask.len() {
        return Err(FillError::NothingKnown);
    }
    Ok(())
}

/// The image's three channels as planes of `f64`.
fn planes(image: &RgbImage) -> [Vec<f64>; 3] {
    let n = image.width * image.height;
    let mut p = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
    for i in 0..n {
        for (c, plane) in p.iter_mut().enumerate() {
            plane[i] = image.data[3 * i + c] as f64;
        }
    }
    p
}

/// `image` with its masked pixels taken from `planes`, clamped to [0, 1].
fn with_masked(image: &RgbImage, mask: &[bool], planes: &[Vec<f64>; 3]) -> RgbImage {
    let mut out = image.clone();
    for (i, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
        for (c, plane) in planes.iter().enumerate() {
            out.data[3 * i + c] = plane[i].clamp(0.0, 1.0) as f32;
        }
    }
    out
}

#[cfg(test)]
pub(crate) mod test_images {
    use gb_core::RgbImage;

    /// A `w x h` texture of oblique stripes and a second, finer pattern, in [0.1, 0.9].
    pub fn stripes(w: usize, h: usize) -> RgbImage {
        let mut img = RgbImage::filled(w, h, [0.0; 3]);
        for y in 0..h {
            for x in 0..w {
                let (xf, yf) = (x as f64, y as f64);
                let a = (2.0 * std::f64::consts::PI * (xf + 0.5 * yf) / 12.0).sin();
                let b = (2.0 * std::f64::consts::PI * (0.3 * xf - yf) / 7.0).cos();
                img.set(
                    x,
                    y,
                    [
                        (0.5 + 0.25 * a + 0.15 * b) as f32,
                        (0.5 + 0.3 * a) as f32,
                        (0.5 - 0.2 * b + 0.1 * a) as f32,
                    ],
                );
            }
        }
        img
    }

    /// A square hole `[x0, x0 + s) x [y0, y0 + s)` in a `w x h` mask.
    pub fn square(w: usize, h: usize, x0: usize, y0: usize, s: usize) -> Vec<bool> {
        (0..w * h)
            .map(|i| (x0..x0 + s).contains(&(i % w)) && (y0..y0 + s).contains(&(i / w)))
            .collect()
    }

    /// PSNR (dB) of `a` against `b` over the masked pixels.
    pub fn masked_psnr(a: &RgbImage, b: &RgbImage, mask: &[bool]) -> f64 {
        let (mut se, mut n) = (0.0, 0usize);
        for (i, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
            for c in 0..3 {
                let d = (a.data[3 * i + c] - b.data[3 * i + c]) as f64;
                se += d * d;
                n += 1;
            }
        }
        10.0 * (n as f64 / se).log10()
    }
}
