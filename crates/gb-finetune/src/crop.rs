//! Square crops of a [`PairSample`] resized to the training resolution.
//!
//! Resampling is bilinear with half-pixel centres (PyTorch's `align_corners=False`, no
//! antialiasing; the weights are `gb_core::resample::bilinear_matrix`), restricted to the
//! crop (border pixels are clamped to the crop, never read from outside it).
//!
//! - RGB is resampled per channel.
//! - Normal maps are resampled as VECTORS: each pixel is decoded to its unit normal (invalid
//!   pixels to the zero vector), the vectors are interpolated and renormalised, then encoded
//!   again. Interpolating the image instead would shorten the vectors and bias them.
//! - The validity is resampled like an image and thresholded at [`VALID_THRESHOLD`], so only
//!   pixels whose every contributing source pixel is valid stay valid; invalid output pixels
//!   get the neutral value of [`crate::normal_map::INVALID_PIXEL`].

use crate::normal_map::{decode_pixel, encode_normal, INVALID_PIXEL};
use crate::sample::PairSample;
use rand::Rng;

/// A resampled validity at or above this is valid (only fully valid neighbourhoods).
pub const VALID_THRESHOLD: f32 = 0.999;

/// Range of the crop side as a fraction of the image's short side.
pub const CROP_FRACTION: (f32, f32) = (0.6, 1.0);

/// Separable bilinear resampling of a `[side, side, c]` window at `(x0, y0)` of a
/// `[h, w, c]` image to `[size, size, c]`.
fn resample(
    src: &[f32],
    w: usize,
    c: usize,
    (x0, y0, side): (usize, usize, usize),
    size: usize,
) -> Vec<f32> {
    let m = gb_core::resample::bilinear_matrix(side, size); // [size, side]
                                                            // taps: for each output index, the (source offset, weight) pairs that are non-zero
    let taps: Vec<Vec<(usize, f32)>> = (0..size)
        .map(|o| {
            (0..side)
                .filter_map(|i| {
                    let wt = m[o * side + i];
                    (wt != 0.0).then_some((i, wt))
                })
                .collect()
        })
        .collect();
    // rows first: [side, size, c]
    let mut tmp = vec![0.0f32; side * size * c];
    for y in 0..side {
        let row = (y0 + y) * w;
        for (ox, tap) in taps.iter().enumerate() {
            for ch in 0..c {
                let mut acc = 0.0f32;
                for &(i, wt) in tap {
                    acc += wt * src.get((row + x0 + i) * c + ch).copied().unwrap_or(0.0);
                }
                tmp[(y * size + ox) * c + ch] = acc;
            }
        }
    }
    let mut out = vec![0.0f32; size * size * c];
    for (oy, tap) in taps.iter().enumerate() {
        for ox in 0..size {
            for ch in 0..c {
                let mut acc = 0.0f32;
                for &(i, wt) in tap {
                    acc += wt * tmp[(i * size + ox) * c + ch];
                }
                out[(oy * size + ox) * c + ch] = acc;
            }
        }
    }
    out
}

/// The square window `[x0, x0 + side) x [y0, y0 + side)` of `sample` resized to
/// `size x size` (see the module docs). The window is clamped to the image; `size` 0 is
/// treated as 1, and an empty sample gives black RGB and invalid normals.
pub fn crop_and_resize(
    sample: &PairSample,
    x0: usize,
    y0: usize,
    side: usize,
    size: usize,
) -> PairSample {
    let size = size.max(1);
    let (w, h) = (sample.width, sample.height);
    if w == 0 || h == 0 {
        return PairSample {
            name: sample.name.clone(),
            width: size,
            height: size,
            rgb: vec![0.0; size * size * 3],
            normal: sample
                .normal
                .as_ref()
                .map(|_| INVALID_PIXEL.repeat(size * size)),
            normal_valid: vec![0.0; size * size],
            caption: sample.caption.clone(),
        };
    }
    let side = side.clamp(1, w.min(h));
    let x0 = x0.min(w - side);
    let y0 = y0.min(h - side);
    let win = (x0, y0, side);
    let rgb = resample(&sample.rgb, w, 3, win, size);
    let valid_src: Vec<f32> = (0..w * h)
        .map(|i| sample.normal_valid.get(i).copied().unwrap_or(0.0))
        .collect();
    let valid_r = resample(&valid_src, w, 1, win, size);
    let valid: Vec<f32> = valid_r
        .iter()
        .map(|&v| if v >= VALID_THRESHOLD { 1.0 } else { 0.0 })
        .collect();
    let (normal, valid) = match &sample.normal {
        None => (None, valid),
        Some(img) => {
            let vecs: Vec<f32> = (0..w * h)
                .flat_map(|i| {
                    let px = [
                        img.get(3 * i).copied().unwrap_or(0.5),
                        img.get(3 * i + 1).copied().unwrap_or(0.5),
                        img.get(3 * i + 2).copied().unwrap_or(0.5),
                    ];
                    match decode_pixel(px) {
                        Some(n) if valid_src[i] > 0.5 => n,
                        _ => [0.0; 3],
                    }
                })
                .collect();
            let vr = resample(&vecs, w, 3, win, size);
            let mut out = Vec::with_capacity(size * size * 3);
            let mut ok = Vec::with_capacity(size * size);
            for (i, v) in vr.chunks_exact(3).enumerate() {
                let (px, good) = if valid[i] > 0.5 {
                    encode_normal([v[0], v[1], v[2]])
                } else {
                    (INVALID_PIXEL, false)
                };
                out.extend_from_slice(&px);
                ok.push(if good { 1.0 } else { 0.0 });
            }
            (Some(out), ok)
        }
    };
    PairSample {
        name: sample.name.clone(),
        width: size,
        height: size,
        rgb,
        normal,
        normal_valid: valid,
        caption: sample.caption.clone(),
    }
}

/// A random square crop, side `min(h, w) * U(0.6, 1.0)` at a uniformly random position,
/// resized to `size x size` (see [`crop_and_resize`]).
pub fn random_square_crop<R: Rng + ?Sized>(
    sample: &PairSample,
    size: usize,
    rng: &mut R,
) -> PairSample {
    let short = sample.width.min(sample.height);
    let frac = rng.random_range(CROP_FRACTION.0..=CROP_FRACTION.1);
    let side = ((short as f32 * frac).round() as usize).clamp(1, short.max(1));
    let x0 = rng.random_range(0..=sample.width.saturating_sub(side));
    let y0 = rng.random_range(0..=sample.height.saturating_sub(side));
    crop_and_resize(sample, x0, y0, side, size)
}

/// The centred square of side `min(h, w)` resized to `size x size`: deterministic, for
/// validation.
pub fn center_square_resize(sample: &PairSample, size: usize) -> PairSample {
    let side = sample.width.min(sample.height);
    let x0 = (sample.width - side) / 2;
    let y0 = (sample.height - side) / 2;
    crop_and_resize(sample, x0, y0, side, size)
}
