//! Looping GIF animations (the orbit of a trained field), written atomically.

use std::path::Path;

use gb_core::RgbImage;
use image::codecs::gif::{GifEncoder, Repeat};
use image::{Delay, Frame, RgbaImage};

use crate::ReportError;

fn to_rgba(img: &RgbImage) -> RgbaImage {
    let mut out = RgbaImage::new(img.width as u32, img.height as u32);
    for (i, px) in out.pixels_mut().enumerate() {
        let q = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        let d = &img.data[i * 3..i * 3 + 3];
        px.0 = [q(d[0]), q(d[1]), q(d[2]), 255];
    }
    out
}

/// Writes `frames` as a looping GIF at `fps` frames per second (atomically).
pub fn write_gif(path: &Path, frames: &[RgbImage], fps: u32) -> Result<(), ReportError> {
    let io = |e: String| ReportError::Io {
        path: path.to_path_buf(),
        source: std::io::Error::other(e),
    };
    let mut bytes = Vec::new();
    {
        let mut enc = GifEncoder::new_with_speed(&mut bytes, 10);
        enc.set_repeat(Repeat::Infinite)
            .map_err(|e| io(e.to_string()))?;
        let delay = Delay::from_numer_denom_ms(1000, fps.max(1));
        for f in frames {
            enc.encode_frame(Frame::from_parts(to_rgba(f), 0, 0, delay))
                .map_err(|e| io(e.to_string()))?;
        }
    }
    gb_core::write_atomic(path, &bytes).map_err(|e| io(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gif_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("o.gif");
        let frames: Vec<RgbImage> = (0..3)
            .map(|i| RgbImage::filled(8, 6, [i as f32 / 2.0, 0.2, 0.9]))
            .collect();
        write_gif(&p, &frames, 12).unwrap();
        let back = gb_core::read_rgb(&p, None).unwrap();
        assert_eq!((back.width, back.height), (8, 6));
        let bytes = std::fs::read(&p).unwrap();
        assert_eq!(&bytes[..6], b"GIF89a");
    }
}
