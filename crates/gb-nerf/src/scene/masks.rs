//! Reading object masks: 0/1 or 0/255 grayscale PNGs, fitted to their image's size.

use super::{Mask, SceneError};
use std::path::Path;

/// Reads a mask file and binarises it. Masks stored as 0/1 and as 0/255 both work: the
/// threshold is half the file's maximum value (an all-zero file is an empty mask). A PNG mask
/// must be binary (every pixel 0 or the file's maximum); a grey level in between is an error
/// naming the file, since a soft or anti-aliased mask has no meaning for object removal.
/// JPEG masks, which compression makes non-binary, are thresholded.
///
/// When the mask's size differs from `(width, height)`, a mask at least as large in both
/// directions is cropped to its top-left `width x height` region (the case seen in
/// SPIn-NeRF: 1008x576 masks for 1008x567 images), and any other is resized by nearest
/// neighbour; either way a warning naming the file is pushed onto `warnings`.
pub fn read_mask(
    path: &Path,
    width: usize,
    height: usize,
    warnings: &mut Vec<String>,
) -> Result<Mask, SceneError> {
    let (w, h, values) = gb_core::read_gray(path)?;
    let max = values.iter().copied().fold(0.0f32, f32::max);
    let lossy = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "jpg" | "jpeg"));
    let between = values.iter().filter(|&&v| v > 0.0 && v < max).count();
    if between > 0 && !lossy {
        return Err(SceneError::MaskNotBinary {
            path: path.to_path_buf(),
            pixels: between,
            total: values.len(),
        });
    }
    let threshold = max * 0.5;
    let bits: Vec<bool> = values.iter().map(|&v| max > 0.0 && v > threshold).collect();
    let raw = Mask {
        width: w,
        height: h,
        data: bits,
    };
    if (w, h) == (width, height) {
        return Ok(raw);
    }
    if w >= width && h >= height {
        warnings.push(format!(
            "{}: mask is {w}x{h} but its image is {width}x{height}; cropped to the top-left {width}x{height}",
            path.display()
        ));
        return Ok(crop(&raw, width, height));
    }
    warnings.push(format!(
        "{}: mask is {w}x{h} but its image is {width}x{height}; resized (nearest neighbour)",
        path.display()
    ));
    Ok(resize_nearest(&raw, width, height))
}

/// The top-left `width x height` part of a mask at least that large.
pub fn crop(m: &Mask, width: usize, height: usize) -> Mask {
    let mut data = Vec::with_capacity(width * height);
    for y in 0..height {
        data.extend_from_slice(&m.data[y * m.width..y * m.width + width]);
    }
    Mask {
        width,
        height,
        data,
    }
}

/// Nearest-neighbour resize of a mask (pixel centres map to pixel centres).
pub fn resize_nearest(m: &Mask, width: usize, height: usize) -> Mask {
    let mut data = Vec::with_capacity(width * height);
    for y in 0..height {
        let sy = (((y as f64 + 0.5) * m.height as f64 / height as f64) as usize)
            .min(m.height.saturating_sub(1));
        for x in 0..width {
            let sx = (((x as f64 + 0.5) * m.width as f64 / width as f64) as usize)
                .min(m.width.saturating_sub(1));
            data.push(m.data.get(sy * m.width + sx).copied().unwrap_or(false));
        }
    }
    Mask {
        width,
        height,
        data,
    }
}

/// Grows a mask by `radius` pixels (square structuring element, Chebyshev distance).
pub fn dilate(m: &Mask, radius: usize) -> Mask {
    if radius == 0 {
        return m.clone();
    }
    let (w, h) = (m.width, m.height);
    // separable: horizontal then vertical max filter
    let mut tmp = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let (x0, x1) = (x.saturating_sub(radius), (x + radius).min(w - 1));
            tmp[y * w + x] = (x0..=x1).any(|xx| m.data[y * w + xx]);
        }
    }
    let mut data = vec![false; w * h];
    for y in 0..h {
        let (y0, y1) = (y.saturating_sub(radius), (y + radius).min(h - 1));
        for x in 0..w {
            data[y * w + x] = (y0..=y1).any(|yy| tmp[yy * w + x]);
        }
    }
    Mask {
        width: w,
        height: h,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(path: &Path, w: usize, h: usize, vals: &[f32]) {
        gb_core::write_gray_png(path, w, h, vals).unwrap();
    }

    #[test]
    fn zero_one_and_zero_255_masks_agree() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.png"), dir.path().join("b.png"));
        let ones: Vec<f32> = (0..12)
            .map(|i| if i % 3 == 0 { 1.0 / 255.0 } else { 0.0 })
            .collect();
        let full: Vec<f32> = ones
            .iter()
            .map(|&v| if v > 0.0 { 1.0 } else { 0.0 })
            .collect();
        write(&a, 4, 3, &ones);
        write(&b, 4, 3, &full);
        let mut warn = Vec::new();
        let ma = read_mask(&a, 4, 3, &mut warn).unwrap();
        let mb = read_mask(&b, 4, 3, &mut warn).unwrap();
        assert_eq!(ma, mb);
        assert_eq!(ma.data.iter().filter(|&&v| v).count(), 4);
        assert!(warn.is_empty());
    }

    #[test]
    fn grey_levels_in_a_png_mask_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("soft.png");
        write(&p, 4, 1, &[0.0, 0.5, 1.0, 1.0]);
        let err = read_mask(&p, 4, 1, &mut Vec::new()).unwrap_err();
        assert!(
            matches!(
                err,
                SceneError::MaskNotBinary {
                    pixels: 1,
                    total: 4,
                    ..
                }
            ),
            "{err:?}"
        );
        assert!(err.to_string().contains("soft.png"), "{err}");
    }

    #[test]
    fn taller_mask_is_cropped_with_a_warning() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("tall.png");
        // 4x5 mask, last row set: cropping to 4x3 removes it; row 1 stays
        let mut v = vec![0.0; 20];
        v[4 + 2] = 1.0;
        v[16..20].fill(1.0);
        write(&p, 4, 5, &v);
        let mut warn = Vec::new();
        let m = read_mask(&p, 4, 3, &mut warn).unwrap();
        assert_eq!((m.width, m.height), (4, 3));
        assert_eq!(m.data.iter().filter(|&&v| v).count(), 1);
        assert!(m.data[4 + 2]);
        assert_eq!(warn.len(), 1);
        assert!(
            warn[0].contains("tall.png") && warn[0].contains("4x5"),
            "{}",
            warn[0]
        );
    }

    #[test]
    fn smaller_mask_is_resized() {
        let m = Mask {
            width: 2,
            height: 2,
            data: vec![true, false, false, false],
        };
        let r = resize_nearest(&m, 4, 4);
        let set: Vec<usize> = (0..16).filter(|&i| r.data[i]).collect();
        assert_eq!(set, vec![0, 1, 4, 5]);
    }

    #[test]
    fn dilation_grows_by_radius() {
        let mut m = Mask {
            width: 7,
            height: 7,
            data: vec![false; 49],
        };
        m.data[3 * 7 + 3] = true;
        let d = dilate(&m, 2);
        assert_eq!(d.data.iter().filter(|&&v| v).count(), 25);
        assert!(d.data[7 + 1] && !d.data[0]);
    }
}
