//! Test doubles with closed forms: a mock inpainting eps-predictor, a linear pooling
//! encoder (transpose known in closed form) and a small nonlinear conv encoder.

use std::cell::RefCell;

use burn::tensor::module::conv2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{Device, Tensor, TensorData};
use gb_diffusion::distill::noise::standard_normal;
use gb_diffusion::distill::{DistillError, EpsBatch, InpaintEpsPredictor, LatentEncoder};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Latent channels of the test encoders.
pub const LATENT_C: usize = 4;

/// Coefficients of the mock predictor.
pub const A: f32 = 0.7;
pub const M: f32 = 0.3;
pub const K: f32 = -0.2;

/// `eps[r,c,y,x] = A*x_t + (c+1)*mean(text_r) + M*mask + K*masked_latents`, recording
/// every call's batch size and timestep.
#[derive(Default)]
pub struct MockUnet {
    pub calls: RefCell<Vec<(usize, usize)>>,
    /// When set, eps is NaN at every position where x_t > this threshold.
    pub nan_above: Option<f32>,
}

impl InpaintEpsPredictor for MockUnet {
    fn predict_eps(&self, batch: EpsBatch) -> Result<Tensor<4>, DistillError> {
        let [n, c, h, w] = batch.noisy_latents.dims();
        self.calls.borrow_mut().push((n, batch.timestep));
        let device = batch.noisy_latents.device();
        let text_mean = batch
            .text_embeddings
            .mean_dims(&[1, 2])
            .reshape([n, 1, 1, 1]);
        let ramp = Tensor::<1>::from_data(
            TensorData::new((1..=c).map(|v| v as f32).collect::<Vec<_>>(), [c]),
            &device,
        )
        .reshape([1, c, 1, 1]);
        let eps = batch.noisy_latents.clone().mul_scalar(A)
            + (text_mean.repeat_dim(1, c) * ramp.repeat_dim(0, n)).repeat(&[1, 1, h, w])
            + batch.mask.repeat_dim(1, c).mul_scalar(M)
            + batch.masked_image_latents.mul_scalar(K);
        Ok(match self.nan_above {
            Some(th) => {
                let bad = batch.noisy_latents.greater_elem(th);
                eps.mask_fill(bad, f32::NAN)
            }
            None => eps,
        })
    }
}

/// Host version of the mock for one row: `x_t`, text mean, mask (`h*w`), masked latents.
pub fn mock_eps_host(
    x_t: &[f32],
    text_mean: f32,
    mask: &[f32],
    masked: &[f32],
    hw: usize,
) -> Vec<f32> {
    (0..x_t.len())
        .map(|i| {
            let c = i / hw;
            A * x_t[i] + (c as f32 + 1.0) * text_mean + M * mask[i % hw] + K * masked[i]
        })
        .collect()
}

/// Seeded standard-normal host values.
pub fn randn(seed: u64, count: usize) -> Vec<f32> {
    standard_normal(&mut ChaCha8Rng::seed_from_u64(seed), count)
}

/// Seeded uniform values in [0, 1).
pub fn rand01(seed: u64, count: usize) -> Vec<f32> {
    use rand::Rng;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count).map(|_| rng.random::<f32>()).collect()
}

/// A tensor from host values.
pub fn tensor<const D: usize>(values: Vec<f32>, shape: [usize; D], device: &Device) -> Tensor<D> {
    Tensor::from_data(TensorData::new(values, shape), device)
}

/// Host values of a tensor.
pub fn host<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().try_into_vec_as::<f32>().expect("f32 tensor")
}

/// `latent[k] = sum_c MIX[k][c] * avgpool2x2(img[c])`: linear, factor 2.
pub struct LinearPoolEncoder {
    weight: Tensor<4>,
}

/// The channel mix of [`LinearPoolEncoder`].
pub const MIX: [[f32; 3]; LATENT_C] = [
    [0.5, -0.25, 0.125],
    [0.0, 1.0, -0.5],
    [0.75, 0.25, 0.0],
    [-1.0, 0.5, 0.25],
];

impl LinearPoolEncoder {
    pub fn new(device: &Device) -> Self {
        let mut w = Vec::new();
        for row in MIX {
            for m in row {
                w.extend([m / 4.0; 4]);
            }
        }
        Self {
            weight: tensor(w, [LATENT_C, 3, 2, 2], device),
        }
    }

    /// Host transpose: image gradient `[3, H, W]` of `sum(latents * g)` for `g` `[4, H/2, W/2]`.
    pub fn transpose_host(g: &[f32], height: usize, width: usize) -> Vec<f32> {
        let (lh, lw) = (height / 2, width / 2);
        let mut out = vec![0.0f32; 3 * height * width];
        for c in 0..3 {
            for y in 0..height {
                for x in 0..width {
                    let mut s = 0.0;
                    for (k, row) in MIX.iter().enumerate() {
                        s += row[c] / 4.0 * g[k * lh * lw + (y / 2) * lw + x / 2];
                    }
                    out[c * height * width + y * width + x] = s;
                }
            }
        }
        out
    }
}

impl LatentEncoder for LinearPoolEncoder {
    fn encode(&self, image: Tensor<4>) -> Result<Tensor<4>, DistillError> {
        let mut weight = self.weight.clone();
        if image.is_autodiff() {
            weight = weight.autodiff();
        }
        Ok(conv2d(
            image,
            weight,
            None,
            ConvOptions::new([2, 2], [0, 0], [1, 1], 1),
        ))
    }

    fn downsample_factor(&self) -> usize {
        2
    }
}

/// A nonlinear encoder: conv 3x3 stride 2 (3 -> 8), tanh, conv 1x1 (8 -> 4); seeded weights.
pub struct ConvEncoder {
    w1: Tensor<4>,
    b1: Tensor<1>,
    w2: Tensor<4>,
}

impl ConvEncoder {
    pub fn new(device: &Device, seed: u64) -> Self {
        let scale = |v: Vec<f32>, s: f32| v.into_iter().map(|x| x * s).collect::<Vec<_>>();
        Self {
            w1: tensor(scale(randn(seed, 8 * 3 * 9), 0.3), [8, 3, 3, 3], device),
            b1: tensor(scale(randn(seed + 1, 8), 0.1), [8], device),
            w2: tensor(
                scale(randn(seed + 2, LATENT_C * 8), 0.4),
                [LATENT_C, 8, 1, 1],
                device,
            ),
        }
    }
}

impl LatentEncoder for ConvEncoder {
    fn encode(&self, image: Tensor<4>) -> Result<Tensor<4>, DistillError> {
        let ad = image.is_autodiff();
        let lift4 = |t: &Tensor<4>| if ad { t.clone().autodiff() } else { t.clone() };
        let b1 = if ad {
            self.b1.clone().autodiff()
        } else {
            self.b1.clone()
        };
        let h = conv2d(
            image,
            lift4(&self.w1),
            Some(b1),
            ConvOptions::new([2, 2], [1, 1], [1, 1], 1),
        );
        Ok(conv2d(
            h.tanh(),
            lift4(&self.w2),
            None,
            ConvOptions::new([1, 1], [0, 0], [1, 1], 1),
        ))
    }

    fn downsample_factor(&self) -> usize {
        2
    }
}

/// Makes sure wgpu (lavapipe) finds a runtime dir.
pub fn wgpu_env() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
            let _ = std::fs::create_dir_all("/tmp/xdg");
            std::env::set_var("XDG_RUNTIME_DIR", "/tmp/xdg");
        }
    });
}

/// Max absolute difference.
pub fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

/// Max absolute value.
pub fn max_abs(a: &[f32]) -> f32 {
    a.iter().map(|x| x.abs()).fold(0.0, f32::max)
}
