//! Depth maps as 16-bit PNGs, nerfstudio's convention: a pixel value `v > 0` is the z-depth
//! `v * depth_unit_scale_factor` in scene units, and `0` means "no depth here".

use std::io::Cursor;
use std::path::Path;

use image::{DynamicImage, ImageBuffer, ImageFormat, Luma};

use crate::error::InpaintError;

/// nerfstudio's default `depth_unit_scale_factor`: one PNG step is a millimetre when the
/// scene unit is a metre. Used whenever the deepest value fits in 16 bits with it.
pub const MILLIMETRE: f64 = 1e-3;

/// The largest value a 16-bit PNG holds.
const MAX_CODE: f64 = u16::MAX as f64;

/// The depth unit (scene units per PNG step) for depths up to `max_depth`: [`MILLIMETRE`]
/// when `max_depth` fits in 16 bits with it, else `max_depth / 65535`, so that the deepest
/// value is the largest code. The quantisation error is at most half of it.
pub fn depth_unit_for(max_depth: f32) -> f64 {
    let max = f64::from(max_depth);
    if max.is_finite() && max > MILLIMETRE * MAX_CODE {
        max / MAX_CODE
    } else {
        MILLIMETRE
    }
}

/// The 16-bit codes of `depth` in steps of `unit`: `round(d / unit)`, at least 1 so that a
/// valid depth never reads as missing; non-finite or non-positive depths become 0.
pub fn quantise_depth(depth: &[f32], unit: f64) -> Vec<u16> {
    depth
        .iter()
        .map(|&d| {
            let d = f64::from(d);
            if d.is_finite() && d > 0.0 {
                (d / unit).round().clamp(1.0, MAX_CODE) as u16
            } else {
                0
            }
        })
        .collect()
}

/// Writes `depth` (`width * height` z-depths, row-major) as a 16-bit grayscale PNG in steps of
/// `unit` (see [`quantise_depth`]), atomically.
pub fn write_depth_png(
    path: &Path,
    width: usize,
    height: usize,
    depth: &[f32],
    unit: f64,
) -> Result<(), InpaintError> {
    let bad = |reason: String| InpaintError::io(path, std::io::Error::other(reason));
    let buffer: ImageBuffer<Luma<u16>, Vec<u16>> =
        ImageBuffer::from_raw(width as u32, height as u32, quantise_depth(depth, unit))
            .ok_or_else(|| {
                bad(format!(
                    "depth map has {} values, expected {width} x {height}",
                    depth.len()
                ))
            })?;
    let mut bytes = Vec::new();
    DynamicImage::ImageLuma16(buffer)
        .write_to(&mut Cursor::new(&mut bytes), ImageFormat::Png)
        .map_err(|e| bad(format!("cannot encode the depth PNG: {e}")))?;
    gb_core::write_atomic(path, &bytes).map_err(|e| InpaintError::io(path, e))
}

/// Reads a 16-bit depth PNG written by [`write_depth_png`] (or any single-channel 16-bit
/// PNG in nerfstudio's convention): `(width, height, depths)`, each code times `unit`, with 0
/// for "no depth". Errors name the file, also when it is not 16-bit grayscale.
pub fn read_depth_png(path: &Path, unit: f64) -> Result<(usize, usize, Vec<f32>), InpaintError> {
    let bad = |reason: String| InpaintError::io(path, std::io::Error::other(reason));
    let img = image::open(path).map_err(|e| bad(format!("cannot read the depth PNG: {e}")))?;
    let DynamicImage::ImageLuma16(buffer) = img else {
        return Err(bad(format!(
            "depth PNG is {:?}, expected 16-bit grayscale",
            img.color()
        )));
    };
    let (w, h) = (buffer.width() as usize, buffer.height() as usize);
    let depth = buffer
        .into_raw()
        .into_iter()
        .map(|code| (f64::from(code) * unit) as f32)
        .collect();
    Ok((w, h, depth))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_is_millimetres_unless_the_depth_does_not_fit() {
        assert_eq!(depth_unit_for(6.0), MILLIMETRE);
        assert_eq!(depth_unit_for(65.0), MILLIMETRE);
        let u = depth_unit_for(131.07);
        assert_eq!(u, f64::from(131.07f32) / 65535.0);
        assert_eq!(quantise_depth(&[131.07], u), vec![65535]);
        assert_eq!(depth_unit_for(f32::NAN), MILLIMETRE);
    }

    #[test]
    fn invalid_depths_are_zero_and_tiny_ones_stay_valid() {
        let codes = quantise_depth(&[0.0, -1.0, f32::NAN, f32::INFINITY, 1e-5, 2.0004], 1e-3);
        assert_eq!(codes, vec![0, 0, 0, 0, 1, 2000]);
    }

    #[test]
    fn png_round_trips_within_half_a_step() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("d.png");
        let depth: Vec<f32> = (0..12).map(|i| 0.5 + 0.37 * i as f32).collect();
        write_depth_png(&p, 4, 3, &depth, MILLIMETRE).unwrap();
        let (w, h, back) = read_depth_png(&p, MILLIMETRE).unwrap();
        assert_eq!((w, h), (4, 3));
        for (a, b) in depth.iter().zip(&back) {
            assert!((a - b).abs() <= 0.5e-3 + 1e-6, "{a} vs {b}");
        }
        // wrong size and a non-16-bit file are errors naming the file
        let e = write_depth_png(&p, 5, 3, &depth, MILLIMETRE).unwrap_err();
        assert!(e.to_string().contains("d.png") && e.to_string().contains("5 x 3"));
        let rgb = dir.path().join("rgb.png");
        gb_core::write_rgb_png(&rgb, &gb_core::RgbImage::filled(2, 2, [0.5; 3])).unwrap();
        let e = read_depth_png(&rgb, MILLIMETRE).unwrap_err();
        assert!(e.to_string().contains("16-bit grayscale"), "{e}");
    }
}
