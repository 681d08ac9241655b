//! pyiqa's NIMA input pipeline in eval mode (`NIMA.preprocess`), on an RGB image in [0, 1]:
//!
//! 1. `torchvision.transforms.functional.resize(x, S)`: the shorter side becomes `S`, the
//!    longer `int(S * long / short)` (both unchanged when already there); bilinear with
//!    `antialias=True` (torchvision's default since 0.17), i.e. ATen's separable
//!    `_upsample_bilinear2d_aa`: a triangle filter widened by the downscale factor, its taps
//!    clipped to the image and renormalised, width pass first, then height, in f32;
//! 2. `center_crop(x, S)`: offsets `int(round((size - S) / 2))`, Python's round half to even;
//! 3. `(x - mean) / std` with timm's `pretrained_cfg` for `inception_resnet_v2`:
//!    mean = std = (0.5, 0.5, 0.5), so `2 x - 1`.
//!
//! `S` is `default_cfg['input_size'][-1]` = 299 in pyiqa. Images reach pyiqa through
//! `imread2tensor` (PIL RGB, `to_tensor`: u8 / 255), as `gb_core::read_rgb` reads them.

use gb_core::RgbImage;

use super::error::NimaError;

/// timm's `IMAGENET_INCEPTION_MEAN`.
pub const MEAN: [f32; 3] = [0.5, 0.5, 0.5];
/// timm's `IMAGENET_INCEPTION_STD`.
pub const STD: [f32; 3] = [0.5, 0.5, 0.5];

/// The size torchvision's `resize(img, size)` gives an `height x width` image:
/// `(new_height, new_width)`.
pub fn resized_size(height: usize, width: usize, size: usize) -> (usize, usize) {
    let (short, long) = if width <= height {
        (width, height)
    } else {
        (height, width)
    };
    let new_long = ((size * long) as f64 / short as f64) as usize;
    if width <= height {
        (new_long, size)
    } else {
        (size, new_long)
    }
}

/// The taps of one axis of ATen's antialiased bilinear resize
/// (`_compute_indices_min_size_weights_aa`): per output index, the first input index and the
/// normalised weights.
fn aa_taps(input: usize, output: usize) -> Vec<(usize, Vec<f32>)> {
    let scale = input as f32 / output as f32;
    // interp_size 2 (bilinear): support = (2 / 2) * scale when downscaling, else 1.
    let support = if scale >= 1.0 { scale } else { 1.0 };
    let invscale = if scale >= 1.0 { 1.0 / scale } else { 1.0 };
    let max_interp = (support.ceil() as i64) * 2 + 1;
    (0..output)
        .map(|i| {
            let center = (f64::from(scale) * (i as f64 + 0.5)) as f32;
            let xmin = ((f64::from(center - support) + 0.5) as i64).max(0);
            let xsize = (((f64::from(center + support) + 0.5) as i64).min(input as i64) - xmin)
                .clamp(0, max_interp);
            let mut w: Vec<f32> = (0..xsize)
                .map(|j| {
                    let x = ((f64::from((j + xmin) as f32 - center) + 0.5) * f64::from(invscale))
                        as f32;
                    let x = x.abs();
                    if x < 1.0 {
                        1.0 - x
                    } else {
                        0.0
                    }
                })
                .collect();
            let total: f32 = w.iter().sum();
            if total != 0.0 {
                w.iter_mut().for_each(|v| *v /= total);
            }
            (xmin as usize, w)
        })
        .collect()
}

/// Resizes a planar `[channels, height, width]` image to `out_h x out_w` with torchvision's
/// antialiased bilinear filter (see the module docs). An axis whose size does not change is
/// left alone, as ATen does.
pub fn resize_bilinear_aa(
    chw: &[f32],
    channels: usize,
    (height, width): (usize, usize),
    (out_h, out_w): (usize, usize),
) -> Vec<f32> {
    let mut cur = chw.to_vec();
    let mut w = width;
    if out_w != width {
        let taps = aa_taps(width, out_w);
        let mut next = vec![0.0f32; channels * height * out_w];
        for (src, dst) in cur.chunks_exact(width).zip(next.chunks_exact_mut(out_w)) {
            for (o, (start, weights)) in dst.iter_mut().zip(&taps) {
                *o = weights
                    .iter()
                    .zip(&src[*start..])
                    .fold(0.0f32, |acc, (wt, v)| acc + wt * v);
            }
        }
        cur = next;
        w = out_w;
    }
    if out_h != height {
        let taps = aa_taps(height, out_h);
        let mut next = vec![0.0f32; channels * out_h * w];
        for c in 0..channels {
            let plane = &cur[c * height * w..(c + 1) * height * w];
            let out = &mut next[c * out_h * w..(c + 1) * out_h * w];
            for (y, (start, weights)) in taps.iter().enumerate() {
                let row = &mut out[y * w..(y + 1) * w];
                for (k, wt) in weights.iter().enumerate() {
                    let src = &plane[(start + k) * w..(start + k + 1) * w];
                    if k == 0 {
                        row.iter_mut().zip(src).for_each(|(o, v)| *o = wt * v);
                    } else {
                        row.iter_mut().zip(src).for_each(|(o, v)| *o += wt * v);
                    }
                }
            }
        }
        cur = next;
    }
    cur
}

/// torchvision's `center_crop` offsets of a `size` crop from an axis of length `len`
/// (`len >= size`): `int(round((len - size) / 2))`, ties to even.
pub fn crop_offset(len: usize, size: usize) -> usize {
    ((len - size) as f64 / 2.0).round_ties_even() as usize
}

/// The network input of one image: resized, center-cropped to `size x size` and
/// normalised, planar `[3, size, size]` (see the module docs).
pub fn preprocess(image: &RgbImage, size: usize) -> Result<Vec<f32>, NimaError> {
    let (w, h) = (image.width, image.height);
    let expected = w * h * 3;
    if image.data.len() != expected || expected == 0 {
        return Err(NimaError::BadImage {
            width: w,
            height: h,
            got: image.data.len(),
            expected,
        });
    }
    let mut chw = vec![0.0f32; expected];
    for (i, px) in image.data.chunks_exact(3).enumerate() {
        for c in 0..3 {
            chw[c * w * h + i] = px[c];
        }
    }
    let (rh, rw) = resized_size(h, w, size);
    let resized = if (rh, rw) == (h, w) {
        chw
    } else {
        resize_bilinear_aa(&chw, 3, (h, w), (rh, rw))
    };
    let (top, left) = (crop_offset(rh, size), crop_offset(rw, size));
    let mut out = Vec::with_capacity(3 * size * size);
    for c in 0..3 {
        for y in top..top + size {
            let row = &resized[(c * rh + y) * rw + left..(c * rh + y) * rw + left + size];
            out.extend(row.iter().map(|v| (v - MEAN[c]) / STD[c]));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn output_size_follows_torchvision() {
        // Shorter side to S, the longer truncated: int(299 * 504 / 378) = 398.
        assert_eq!(resized_size(378, 504, 299), (299, 398));
        assert_eq!(resized_size(504, 378, 299), (398, 299));
        assert_eq!(resized_size(50, 61, 96), (96, 117));
        assert_eq!(resized_size(299, 299, 299), (299, 299));
        // Python's round: 10.5 -> 10, 11.5 -> 12.
        assert_eq!(crop_offset(117, 96), 10);
        assert_eq!(crop_offset(119, 96), 12);
        assert_eq!(crop_offset(96, 96), 0);
    }

    #[test]
    fn taps_sum_to_one_and_stay_inside() {
        for (i, o) in [(232, 128), (61, 117), (378, 299), (7, 3), (3, 7), (10, 10)] {
            for (start, w) in aa_taps(i, o) {
                assert!(start + w.len() <= i, "{i}->{o}");
                let s: f32 = w.iter().sum();
                assert!((s - 1.0).abs() < 1e-5, "{i}->{o}: {s}");
            }
        }
        // Same size: the identity.
        let img: Vec<f32> = (0..2 * 5 * 4).map(|v| v as f32).collect();
        assert_eq!(resize_bilinear_aa(&img, 2, (5, 4), (5, 4)), img);
        let taps = aa_taps(6, 6);
        assert!(taps
            .iter()
            .enumerate()
            .all(|(i, (s, w))| *s == i && w[0] == 1.0));
    }

    #[test]
    fn halving_averages_pixel_pairs() {
        // 2x downscale of a row: the triangle of support 2 covers pixels 2i-1..2i+2 with
        // weights 1/8, 3/8, 3/8, 1/8 (renormalised at the borders).
        let row: Vec<f32> = vec![0.0, 8.0, 16.0, 8.0, 0.0, 8.0];
        let out = resize_bilinear_aa(&row, 1, (1, 6), (1, 3));
        let want1 = (8.0 + 3.0 * 16.0 + 3.0 * 8.0) / 8.0;
        assert!((out[1] - want1).abs() < 1e-5, "{out:?}");
        let want0 = (3.0 * 0.0 + 3.0 * 8.0 + 16.0) / 7.0;
        assert!((out[0] - want0).abs() < 1e-5, "{out:?}");
    }

    #[test]
    fn bad_images_are_errors() {
        let img = RgbImage {
            width: 4,
            height: 4,
            data: vec![0.0; 10],
        };
        assert!(matches!(
            preprocess(&img, 96),
            Err(NimaError::BadImage { got: 10, .. })
        ));
        let constant = RgbImage::filled(80, 90, [1.0, 0.5, 0.0]);
        let x = preprocess(&constant, 75).unwrap();
        assert_eq!(x.len(), 3 * 75 * 75);
        assert!(x[..75 * 75].iter().all(|v| (v - 1.0).abs() < 1e-6));
        assert!(x[75 * 75..2 * 75 * 75].iter().all(|v| v.abs() < 1e-6));
        assert!(x[2 * 75 * 75..].iter().all(|v| (v + 1.0).abs() < 1e-6));
    }
}
