//! Images of a report row: the absolute difference of two images, and the masked input as a
//! method without a prior sees it.

use gb_core::RgbImage;

use crate::ReportError;

/// `|a - b|` per channel (sizes must match).
pub fn abs_diff(a: &RgbImage, b: &RgbImage) -> Result<RgbImage, ReportError> {
    if (a.width, a.height) != (b.width, b.height) {
        return Err(ReportError::Io {
            path: "difference image".into(),
            source: std::io::Error::other(format!(
                "sizes differ: {}x{} vs {}x{}",
                a.width, a.height, b.width, b.height
            )),
        });
    }
    Ok(RgbImage {
        width: a.width,
        height: a.height,
        data: a
            .data
            .iter()
            .zip(&b.data)
            .map(|(x, y)| (x - y).abs())
            .collect(),
    })
}

/// The image with the mask's pixels replaced by a grey / magenta checkerboard (what a method
/// without a prior sees of the view).
pub fn masked_input(img: &RgbImage, mask: &[bool]) -> RgbImage {
    let mut out = img.clone();
    if mask.len() != img.width * img.height {
        return out;
    }
    for y in 0..img.height {
        for x in 0..img.width {
            if mask[y * img.width + x] {
                let c = if (x / 4 + y / 4) % 2 == 0 {
                    [0.5, 0.5, 0.5]
                } else {
                    [0.8, 0.2, 0.8]
                };
                out.set(x, y, c);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diff_is_absolute_and_the_mask_is_a_checkerboard() {
        let a = RgbImage::filled(2, 1, [0.2, 0.5, 1.0]);
        let b = RgbImage::filled(2, 1, [0.5, 0.5, 0.0]);
        let d = abs_diff(&a, &b).unwrap();
        assert!((d.data[0] - 0.3).abs() < 1e-6 && d.data[1] == 0.0 && d.data[2] == 1.0);
        assert!(abs_diff(&a, &RgbImage::filled(1, 1, [0.0; 3])).is_err());
        let m = masked_input(&a, &[true, false]);
        assert_eq!(m.get(0, 0), [0.5, 0.5, 0.5]);
        assert_eq!(m.get(1, 0), a.get(1, 0));
    }
}
