//! A plain 2D discrete Fourier transform on the small support areas of [`crate::fsr`]
//! (separable, `O(MN(M + N))`; a 48x48 area takes a few hundred thousand products).

use std::f64::consts::PI;

/// A complex number.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct C {
    pub re: f64,
    pub im: f64,
}

impl C {
    pub fn new(re: f64, im: f64) -> Self {
        Self { re, im }
    }
    pub fn conj(self) -> Self {
        Self::new(self.re, -self.im)
    }
    pub fn norm_sqr(self) -> f64 {
        self.re * self.re + self.im * self.im
    }
    pub fn scale(self, s: f64) -> Self {
        Self::new(self.re * s, self.im * s)
    }
    pub fn times(self, o: Self) -> Self {
        Self::new(
            self.re * o.re - self.im * o.im,
            self.re * o.im + self.im * o.re,
        )
    }
}

impl std::ops::AddAssign for C {
    fn add_assign(&mut self, o: Self) {
        self.re += o.re;
        self.im += o.im;
    }
}

impl std::ops::SubAssign for C {
    fn sub_assign(&mut self, o: Self) {
        self.re -= o.re;
        self.im -= o.im;
    }
}

/// `e^{sign * 2 pi i k / n}` for `k` in `0..n`.
fn twiddles(n: usize, sign: f64) -> Vec<C> {
    (0..n)
        .map(|k| {
            let a = sign * 2.0 * PI * k as f64 / n as f64;
            C::new(a.cos(), a.sin())
        })
        .collect()
}

/// The unnormalised 2D DFT of the `w x h` row-major `data` with exponent sign `sign`
/// (`-1`: forward, `+1`: inverse without the `1 / (w h)`).
pub fn dft2(data: &[C], w: usize, h: usize, sign: f64) -> Vec<C> {
    let (tw, th) = (twiddles(w, sign), twiddles(h, sign));
    // rows
    let mut rows = vec![C::default(); w * h];
    for y in 0..h {
        let row = &data[y * w..(y + 1) * w];
        for k in 0..w {
            let mut s = C::default();
            for (x, v) in row.iter().enumerate() {
                s += v.times(tw[(k * x) % w]);
            }
            rows[y * w + k] = s;
        }
    }
    // columns
    let mut out = vec![C::default(); w * h];
    for k in 0..w {
        for l in 0..h {
            let mut s = C::default();
            for y in 0..h {
                s += rows[y * w + k].times(th[(l * y) % h]);
            }
            out[l * w + k] = s;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn forward_then_inverse_is_the_identity_times_the_size() {
        let (w, h) = (6, 5);
        let data: Vec<C> = (0..w * h)
            .map(|i| C::new((i as f64 * 0.37).sin(), 0.0))
            .collect();
        let back = dft2(&dft2(&data, w, h, -1.0), w, h, 1.0);
        for (a, b) in data.iter().zip(&back) {
            assert!((a.re * (w * h) as f64 - b.re).abs() < 1e-9);
            assert!(b.im.abs() < 1e-9);
        }
    }

    #[test]
    fn a_basis_function_has_one_coefficient() {
        let (w, h) = (8, 4);
        let data: Vec<C> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                let a = 2.0 * PI * (3.0 * x / w as f64 + 1.0 * y / h as f64);
                C::new(a.cos(), a.sin())
            })
            .collect();
        let f = dft2(&data, w, h, -1.0);
        for (i, v) in f.iter().enumerate() {
            let want = if i == w + 3 { (w * h) as f64 } else { 0.0 };
            assert!(
                (v.re - want).abs() < 1e-9 && v.im.abs() < 1e-9,
                "{i}: {v:?}"
            );
        }
    }
}
