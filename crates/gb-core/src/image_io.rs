//! Image files as plain `f32` buffers in [0, 1], row-major, channels last.

use std::path::{Path, PathBuf};

/// An RGB image with `f32` values in [0, 1], stored row-major as `[h, w, 3]`.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `height * width * 3` values in [0, 1].
    pub data: Vec<f32>,
}

impl RgbImage {
    /// A new image filled with one colour.
    pub fn filled(width: usize, height: usize, rgb: [f32; 3]) -> Self {
        let mut data = Vec::with_capacity(width * height * 3);
        for _ in 0..width * height {
            data.extend_from_slice(&rgb);
        }
        Self {
            width,
            height,
            data,
        }
    }

    /// The colour at pixel (x, y).
    pub fn get(&self, x: usize, y: usize) -> [f32; 3] {
        let i = (y * self.width + x) * 3;
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }

    /// Sets the colour at pixel (x, y).
    pub fn set(&mut self, x: usize, y: usize, rgb: [f32; 3]) {
        let i = (y * self.width + x) * 3;
        self.data[i..i + 3].copy_from_slice(&rgb);
    }

    /// The bilinear sample at continuous pixel coordinates (pixel centres at `+0.5`),
    /// clamped at the border.
    pub fn bilinear(&self, x: f32, y: f32) -> [f32; 3] {
        let x = (x - 0.5).clamp(0.0, (self.width - 1) as f32);
        let y = (y - 0.5).clamp(0.0, (self.height - 1) as f32);
        let (xa, ya) = (x.floor() as usize, y.floor() as usize);
        let (xb, yb) = ((xa + 1).min(self.width - 1), (ya + 1).min(self.height - 1));
        let (fx, fy) = (x - xa as f32, y - ya as f32);
        let (a, b, c, d) = (
            self.get(xa, ya),
            self.get(xb, ya),
            self.get(xa, yb),
            self.get(xb, yb),
        );
        [0, 1, 2].map(|ch| {
            let top = a[ch] * (1.0 - fx) + b[ch] * fx;
            let bottom = c[ch] * (1.0 - fx) + d[ch] * fx;
            top * (1.0 - fy) + bottom * fy
        })
    }
}

/// An image file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum ImageIoError {
    /// The file could not be opened or decoded. The decoder's error is part of the message
    /// and is deliberately not a `source`, so that error chains (anyhow) print it once.
    #[error("{path}: cannot read image: {error}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The decoder's error.
        error: image::ImageError,
    },
    /// The file could not be encoded or written.
    #[error("{path}: cannot write image: {reason}")]
    Write {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
}

/// Reads a PNG/JPEG as RGB in [0, 1]. Alpha, if present, is composited on `background`
/// (pass `None` to drop alpha).
pub fn read_rgb(path: &Path, background: Option<[f32; 3]>) -> Result<RgbImage, ImageIoError> {
    let img = image::open(path).map_err(|error| ImageIoError::Read {
        path: path.to_path_buf(),
        error,
    })?;
    let rgba = img.to_rgba32f();
    let (w, h) = (rgba.width() as usize, rgba.height() as usize);
    let mut data = Vec::with_capacity(w * h * 3);
    for p in rgba.pixels() {
        let [r, g, b, a] = p.0;
        match background {
            Some(bg) => {
                data.push(r * a + bg[0] * (1.0 - a));
                data.push(g * a + bg[1] * (1.0 - a));
                data.push(b * a + bg[2] * (1.0 - a));
            }
            None => data.extend_from_slice(&[r, g, b]),
        }
    }
    Ok(RgbImage {
        width: w,
        height: h,
        data,
    })
}

/// The `(width, height)` of an image file, from its header alone (no decoding).
pub fn image_size(path: &Path) -> Result<(usize, usize), ImageIoError> {
    let (w, h) = image::image_dimensions(path).map_err(|error| ImageIoError::Read {
        path: path.to_path_buf(),
        error,
    })?;
    Ok((w as usize, h as usize))
}

/// Reads a single-channel image (e.g. a mask); returns `(width, height, values)` with
/// 8-bit values divided by 255 and 16-bit values by 65535.
pub fn read_gray(path: &Path) -> Result<(usize, usize, Vec<f32>), ImageIoError> {
    let img = image::open(path).map_err(|error| ImageIoError::Read {
        path: path.to_path_buf(),
        error,
    })?;
    let g = img.to_luma32f();
    Ok((g.width() as usize, g.height() as usize, g.into_raw()))
}

fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Writes an RGB image in [0, 1] as an 8-bit PNG, atomically.
pub fn write_rgb_png(path: &Path, img: &RgbImage) -> Result<(), ImageIoError> {
    let bytes: Vec<u8> = img.data.iter().map(|&v| to_u8(v)).collect();
    encode_png(
        path,
        &bytes,
        img.width,
        img.height,
        image::ExtendedColorType::Rgb8,
    )
}

/// Writes a single-channel image in [0, 1] as an 8-bit grayscale PNG, atomically.
pub fn write_gray_png(
    path: &Path,
    width: usize,
    height: usize,
    values: &[f32],
) -> Result<(), ImageIoError> {
    let bytes: Vec<u8> = values.iter().map(|&v| to_u8(v)).collect();
    encode_png(path, &bytes, width, height, image::ExtendedColorType::L8)
}

fn encode_png(
    path: &Path,
    bytes: &[u8],
    width: usize,
    height: usize,
    color: image::ExtendedColorType,
) -> Result<(), ImageIoError> {
    use image::ImageEncoder;
    let mut buf = Vec::new();
    image::codecs::png::PngEncoder::new(&mut buf)
        .write_image(bytes, width as u32, height as u32, color)
        .map_err(|e| ImageIoError::Write {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
    crate::atomic::write_atomic(path, &buf).map_err(|e| ImageIoError::Write {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn bilinear_interpolates_between_pixel_centres_and_clamps_at_the_border() {
        let mut img = RgbImage::filled(2, 1, [0.0; 3]);
        img.set(1, 0, [1.0, 0.5, 0.0]);
        assert_eq!(img.bilinear(0.5, 0.5), [0.0; 3]);
        assert_eq!(img.bilinear(1.5, 0.5), [1.0, 0.5, 0.0]);
        assert_eq!(img.bilinear(1.0, 0.5), [0.5, 0.25, 0.0]);
        assert_eq!(img.bilinear(-3.0, 9.0), [0.0; 3]);
        assert_eq!(img.bilinear(7.0, 0.5), [1.0, 0.5, 0.0]);
    }

    use super::*;

    #[test]
    fn png_round_trip_is_within_quantisation() {
        let dir = tempfile::tempdir().unwrap();
        let mut img = RgbImage::filled(4, 3, [0.2, 0.5, 0.9]);
        img.set(1, 2, [1.0, 0.0, 0.25]);
        let p = dir.path().join("a.png");
        write_rgb_png(&p, &img).unwrap();
        let back = read_rgb(&p, None).unwrap();
        assert_eq!((back.width, back.height), (4, 3));
        for (a, b) in img.data.iter().zip(&back.data) {
            assert!((a - b).abs() <= 0.5 / 255.0 + 1e-6);
        }
    }

    #[test]
    fn unreadable_file_names_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("broken.png");
        std::fs::write(&p, b"not a png").unwrap();
        let err = read_rgb(&p, None).unwrap_err().to_string();
        assert!(err.contains("broken.png"), "{err}");
    }
}
