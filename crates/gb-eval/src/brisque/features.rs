//! The 36 BRISQUE features exactly as OpenCV's `cv::quality::QualityBRISQUE` computes them:
//! grey conversion of the 8-bit image, scaling to [0, 1] in f32, then at two scales (the
//! image, and a bicubic half-size copy) the MSCN coefficients with a 7x7 Gaussian
//! (sigma 7/6, replicated border), an AGGD fit to them (2 features) and to the products of
//! horizontal, vertical and both diagonal neighbours (4 x 4 features).
//!
//! Arithmetic follows OpenCV's f32 pipeline: images in f32, sums in f64. A NaN MSCN value
//! (OpenCV's `sqrt` of a variance that rounding made negative, in flat regions) counts as
//! zero, as OpenCV's vectorised `max`/`min`/`patchNaNs` make it.

use super::error::BrisqueError;

/// Number of BRISQUE features.
pub const FEATURE_COUNT: usize = 36;

/// A single-channel f32 image, row-major.
#[derive(Debug, Clone)]
pub struct GrayF32 {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width * height` values.
    pub data: Vec<f32>,
}

/// OpenCV 4's 8-bit `COLOR_RGB2GRAY` (fixed point with 15-bit coefficients 9798, 19235,
/// 3735, rounded; bit-exact with `cv2.cvtColor`), then the
/// conversion to f32 with scale 1/255.
pub fn gray_from_rgb8(rgb: &[u8], width: usize, height: usize) -> Result<GrayF32, BrisqueError> {
    let expected = width * height * 3;
    if rgb.len() != expected {
        return Err(BrisqueError::BadBuffer {
            got: rgb.len(),
            expected,
            width,
            height,
            channels: 3,
        });
    }
    let scale = (1.0f64 / 255.0) as f32;
    let data = rgb
        .chunks_exact(3)
        .map(|p| {
            let y =
                (p[0] as u32 * 9798 + p[1] as u32 * 19235 + p[2] as u32 * 3735 + (1 << 14)) >> 15;
            y as f32 * scale
        })
        .collect();
    Ok(GrayF32 {
        width,
        height,
        data,
    })
}

/// An 8-bit grey image scaled to [0, 1] in f32.
pub fn gray_from_gray8(gray: &[u8], width: usize, height: usize) -> Result<GrayF32, BrisqueError> {
    if gray.len() != width * height {
        return Err(BrisqueError::BadBuffer {
            got: gray.len(),
            expected: width * height,
            width,
            height,
            channels: 1,
        });
    }
    let scale = (1.0f64 / 255.0) as f32;
    Ok(GrayF32 {
        width,
        height,
        data: gray.iter().map(|v| *v as f32 * scale).collect(),
    })
}

/// The 36 features of a grey image in [0, 1].
pub fn brisque_features(gray: &GrayF32) -> Result<[f32; FEATURE_COUNT], BrisqueError> {
    if gray.width < 8 || gray.height < 8 {
        return Err(BrisqueError::TooSmall {
            width: gray.width,
            height: gray.height,
        });
    }
    let mut out = [0.0f32; FEATURE_COUNT];
    let mut n = 0;
    for scale in 0..2 {
        let img = if scale == 0 {
            gray.clone()
        } else {
            resize_cubic(gray, gray.width / 2, gray.height / 2)
        };
        let mscn = mscn(&img);
        let fit = aggd_fit(&mscn.data)?;
        out[n] = fit.gamma as f32;
        out[n + 1] = ((fit.left * fit.left + fit.right * fit.right) as f32) / 2.0;
        n += 2;
        for (dy, dx) in [(0i64, 1i64), (1, 0), (1, 1), (-1, 1)] {
            let prod = pair_product(&mscn, dy, dx);
            let fit = aggd_fit(&prod)?;
            let g = fit.gamma;
            let constant = gamma_fn(1.0 / g).sqrt() / gamma_fn(3.0 / g).sqrt();
            let mean = (fit.right - fit.left) * (gamma_fn(2.0 / g) / gamma_fn(1.0 / g)) * constant;
            out[n] = g as f32;
            out[n + 1] = mean as f32;
            out[n + 2] = fit.left.powi(2) as f32;
            out[n + 3] = fit.right.powi(2) as f32;
            n += 4;
        }
    }
    Ok(out)
}

fn gamma_fn(x: f64) -> f64 {
    libm::tgamma(x)
}

/// Mean-subtracted contrast-normalised coefficients: (I - mu) / (sigma + 1/255).
pub fn mscn(img: &GrayF32) -> GrayF32 {
    let mu = gaussian_blur_7(img);
    let sq = GrayF32 {
        width: img.width,
        height: img.height,
        data: img.data.iter().map(|v| v * v).collect(),
    };
    let var = gaussian_blur_7(&sq);
    let c = (1.0f64 / 255.0) as f32;
    let data = img
        .data
        .iter()
        .zip(mu.data.iter().zip(&var.data))
        .map(|(x, (m, v))| {
            let sigma = (v - m * m).sqrt() + c;
            (x - m) / sigma
        })
        .collect();
    GrayF32 {
        width: img.width,
        height: img.height,
        data,
    }
}

/// Products of each coefficient with its neighbour at (row + dy, col + dx); zero outside.
fn pair_product(m: &GrayF32, dy: i64, dx: i64) -> Vec<f32> {
    let (w, h) = (m.width as i64, m.height as i64);
    let mut out = vec![0.0f32; m.data.len()];
    for i in 0..h {
        for j in 0..w {
            let (y, x) = (i + dy, j + dx);
            if y >= 0 && y < h && x >= 0 && x < w {
                out[(i * w + j) as usize] =
                    m.data[(i * w + j) as usize] * m.data[(y * w + x) as usize];
            }
        }
    }
    out
}

/// Parameters of an asymmetric generalised Gaussian fit.
struct AggdFit {
    gamma: f64,
    left: f64,
    right: f64,
}

/// OpenCV's `AGGDfit`: moment matching, then a grid search of the shape over
/// [0.2, 10) in steps of 0.001 that stops at the first local minimum.
fn aggd_fit(values: &[f32]) -> Result<AggdFit, BrisqueError> {
    let (mut pos_n, mut neg_n) = (0usize, 0usize);
    let (mut pos_sq, mut neg_sq, mut abs_sum) = (0.0f64, 0.0f64, 0.0f64);
    for &v in values {
        if v > 0.0 {
            pos_n += 1;
            pos_sq += (v * v) as f64;
            abs_sum += v as f64;
        } else if v < 0.0 {
            neg_n += 1;
            neg_sq += (v * v) as f64;
            abs_sum -= v as f64;
        }
    }
    if pos_n == 0 || neg_n == 0 {
        return Err(BrisqueError::Degenerate(format!(
            "{pos_n} positive and {neg_n} negative MSCN values (a flat or constant image)"
        )));
    }
    let left = (neg_sq / neg_n as f64).sqrt();
    let right = (pos_sq / pos_n as f64).sqrt();
    let gammahat = left / right;
    let total = values.len() as f64;
    let rhat = (abs_sum / total).powi(2) / ((neg_sq + pos_sq) / total);
    let rhatnorm =
        rhat * (gammahat.powi(3) + 1.0) * (gammahat + 1.0) / (gammahat.powi(2) + 1.0).powi(2);
    let mut prev_gamma = 0.0f64;
    let mut prev_diff = 1e10f64;
    let mut gam = 0.2f64;
    while gam < 10.0 {
        let r_gam =
            gamma_fn(2.0 / gam) * gamma_fn(2.0 / gam) / (gamma_fn(1.0 / gam) * gamma_fn(3.0 / gam));
        let diff = (r_gam - rhatnorm).abs();
        if diff > prev_diff {
            break;
        }
        prev_diff = diff;
        prev_gamma = gam;
        gam += 0.001;
    }
    Ok(AggdFit {
        gamma: prev_gamma,
        left,
        right,
    })
}

/// OpenCV's 7x7 Gaussian (sigma 7/6, f32 kernel) with a replicated border, separable, with
/// the operation order and rounding of its filters, bit for bit: the MSCN
/// variance `blur(I^2) - blur(I)^2` cancels in flat regions, so rounding matters.
pub fn gaussian_blur_7(img: &GrayF32) -> GrayF32 {
    let k = gaussian_kernel_7();
    let (w, h) = (img.width, img.height);
    let clamp = |v: i64, n: usize| v.clamp(0, n as i64 - 1) as usize;
    let mut rows = vec![0.0f32; w * h];
    for y in 0..h {
        let src = &img.data[y * w..(y + 1) * w];
        for x in 0..w {
            // OpenCV's row filter: k0 * x0, then multiply-adds in order, rounded once each.
            let mut s = k[0] * src[clamp(x as i64 - 3, w)];
            for (t, kv) in k.iter().enumerate().skip(1) {
                s = fma_f64(src[clamp(x as i64 + t as i64 - 3, w)], *kv, s);
            }
            rows[y * w + x] = s;
        }
    }
    let mut out = vec![0.0f32; w * h];
    for y in 0..h {
        let r = |d: i64| &rows[clamp(y as i64 + d, h) * w..][..w];
        let (c, a1, b1, a2, b2, a3, b3) = (r(0), r(-1), r(1), r(-2), r(2), r(-3), r(3));
        for x in 0..w {
            // OpenCV's symmetric column filter: k0 * S0, then single-rounding
            // multiply-adds of k_i * (S_i + S_-i) for i = 1, 2, 3.
            let s = k[3] * c[x];
            let s = fma_f64(b1[x] + a1[x], k[4], s);
            let s = fma_f64(b2[x] + a2[x], k[5], s);
            out[y * w + x] = fma_f64(b3[x] + a3[x], k[6], s);
        }
    }
    GrayF32 {
        width: w,
        height: h,
        data: out,
    }
}

/// `a * b + c` evaluated in f64 and rounded once to f32: bit-identical to OpenCV's filter
/// output on the fixtures (a true f32 FMA differs in about 2% of pixels).
fn fma_f64(a: f32, b: f32, c: f32) -> f32 {
    (a as f64 * b as f64 + c as f64) as f32
}

/// `cv::getGaussianKernel(7, 7/6, CV_32F)` as OpenCV 4 returns it. OpenCV evaluates the
/// Gaussian with its own bit-exact soft-float `exp`, whose outer taps differ by one ulp from
/// `exp(-x^2 / (2 sigma^2))` normalised in f64 (see the unit test), and that ulp is enough to
/// move MSCN values in flat regions; so the kernel is kept as OpenCV's exact bits.
pub fn gaussian_kernel_7() -> [f32; 7] {
    const BITS: [u32; 7] = [
        1011730765, 1033990286, 1047723454, 1051684198, 1047723454, 1033990286, 1011730765,
    ];
    BITS.map(f32::from_bits)
}

/// The same kernel computed directly (normalised in f64), for the tests.
#[cfg(test)]
fn gaussian_kernel_7_direct() -> [f32; 7] {
    let sigma = 7.0f64 / 6.0;
    let scale2x = -0.5 / (sigma * sigma);
    let mut k = [0.0f32; 7];
    let mut sum = 0.0f64;
    for (i, v) in k.iter_mut().enumerate() {
        let x = i as f64 - 3.0;
        *v = (scale2x * x * x).exp() as f32;
        sum += *v as f64;
    }
    for v in k.iter_mut() {
        *v = (*v as f64 / sum) as f32;
    }
    k
}

/// `cv::resize(..., INTER_CUBIC)` for f32 images (A = -0.75, replicated border, no
/// antialiasing), with OpenCV's order of operations (bit-identical on about 98% of the
/// pixels of the fixtures, within one ulp elsewhere); the same size is a copy.
pub fn resize_cubic(img: &GrayF32, new_w: usize, new_h: usize) -> GrayF32 {
    if new_w == img.width && new_h == img.height {
        return img.clone();
    }
    let taps = |src_n: usize, dst_n: usize| -> Vec<([usize; 4], [f32; 4])> {
        let scale = 1.0 / (dst_n as f64 / src_n as f64);
        (0..dst_n)
            .map(|d| {
                let f = ((d as f64 + 0.5) * scale - 0.5) as f32;
                let s = f.floor();
                let frac = f - s;
                let s = s as i64;
                let idx = [0i64, 1, 2, 3].map(|t| (s - 1 + t).clamp(0, src_n as i64 - 1) as usize);
                (idx, cubic_coeffs(frac))
            })
            .collect()
    };
    let xt = taps(img.width, new_w);
    let yt = taps(img.height, new_h);
    let w = img.width;
    let mut horiz = vec![0.0f32; new_w * img.height];
    for y in 0..img.height {
        let src = &img.data[y * w..(y + 1) * w];
        for (x, (idx, c)) in xt.iter().enumerate() {
            // Pairwise sums, as OpenCV's horizontal cubic pass rounds them.
            horiz[y * new_w + x] = (src[idx[0]] * c[0] + src[idx[1]] * c[1])
                + (src[idx[2]] * c[2] + src[idx[3]] * c[3]);
        }
    }
    let mut out = vec![0.0f32; new_w * new_h];
    for (y, (idx, c)) in yt.iter().enumerate() {
        let r = |t: usize| &horiz[idx[t] * new_w..][..new_w];
        let (r0, r1, r2, r3) = (r(0), r(1), r(2), r(3));
        for x in 0..new_w {
            // OpenCV's vertical cubic pass: two single-rounding multiply-adds, then their sum.
            let p1 = fma_f64(r0[x], c[0], r1[x] * c[1]);
            let p2 = fma_f64(r2[x], c[2], r3[x] * c[3]);
            out[y * new_w + x] = p1 + p2;
        }
    }
    GrayF32 {
        width: new_w,
        height: new_h,
        data: out,
    }
}

/// OpenCV's `interpolateCubic` with A = -0.75, in f32.
fn cubic_coeffs(x: f32) -> [f32; 4] {
    let a = -0.75f32;
    let c0 = ((a * (x + 1.0) - 5.0 * a) * (x + 1.0) + 8.0 * a) * (x + 1.0) - 4.0 * a;
    let c1 = ((a + 2.0) * x - (a + 3.0)) * x * x + 1.0;
    let c2 = ((a + 2.0) * (1.0 - x) - (a + 3.0)) * (1.0 - x) * (1.0 - x) + 1.0;
    [c0, c1, c2, 1.0 - c0 - c1 - c2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaussian_kernel_is_the_gaussian_to_one_ulp() {
        let k = gaussian_kernel_7();
        for (a, b) in k.iter().zip(gaussian_kernel_7_direct()) {
            assert!(
                (a.to_bits() as i64 - b.to_bits() as i64).abs() <= 1,
                "{a} vs {b}"
            );
        }
        let s: f32 = k.iter().sum();
        assert!((s - 1.0).abs() < 1e-6);
        assert!(k.iter().eq(k.iter().rev()), "kernel is not symmetric");
    }

    #[test]
    fn cubic_resize_keeps_a_constant_and_copies_same_size() {
        let img = GrayF32 {
            width: 9,
            height: 7,
            data: vec![0.25; 63],
        };
        let half = resize_cubic(&img, 4, 3);
        assert!(half.data.iter().all(|v| (v - 0.25).abs() < 1e-6));
        assert_eq!(resize_cubic(&img, 9, 7).data, img.data);
    }

    #[test]
    fn constant_image_is_a_clear_error() {
        let img = GrayF32 {
            width: 16,
            height: 16,
            data: vec![0.5; 256],
        };
        let err = brisque_features(&img).unwrap_err();
        assert!(matches!(err, BrisqueError::Degenerate(_)), "{err}");
    }
}
