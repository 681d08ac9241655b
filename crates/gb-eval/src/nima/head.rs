//! The NIMA head (pyiqa `classifier`): `Flatten -> Dropout -> Linear(1536, 10) -> Softmax`
//! on the globally average-pooled backbone features. Dropout is the identity at inference
//! (pyiqa's rate is 0 anyway), so the head is `softmax(W f + b)`, with `W` =
//! `classifier.2.weight` `[10, 1536]` and `b` = `classifier.2.bias` `[10]`.

use burn::tensor::activation::softmax;
use burn::tensor::{Tensor, TensorData};

use super::error::NimaError;
use super::layers::Loader;
use super::model::FEATURE_DIM;

/// Number of score bins (AVA ratings 1..10).
pub const NUM_BINS: usize = 10;

/// `classifier.2` of pyiqa's NIMA.
#[derive(Debug, Clone)]
pub(crate) struct NimaHead {
    /// `W^T`, `[1536, 10]`.
    weight_t: Tensor<2>,
    /// `[1, 10]`.
    bias: Tensor<2>,
}

impl NimaHead {
    /// Loads `classifier.2.{weight,bias}` from the root loader.
    pub(crate) fn load(l: &Loader) -> Result<Self, NimaError> {
        let l = l.sub("classifier").sub("2");
        let w = l.values("weight", &[NUM_BINS, FEATURE_DIM])?;
        let b = l.values("bias", &[NUM_BINS])?;
        let device = l.device();
        Ok(Self {
            weight_t: Tensor::<2>::from_data(TensorData::new(w, [NUM_BINS, FEATURE_DIM]), device)
                .transpose(),
            bias: Tensor::from_data(TensorData::new(b, [1, NUM_BINS]), device),
        })
    }

    /// Logits `[N, 10]` of pooled features `[N, 1536]`.
    pub(crate) fn logits(&self, features: Tensor<2>) -> Tensor<2> {
        features.matmul(self.weight_t.clone()) + self.bias.clone()
    }

    /// The score distribution (softmax over the bins) of logits `[N, 10]`.
    pub(crate) fn distribution(logits: Tensor<2>) -> Tensor<2> {
        softmax(logits, 1)
    }
}

/// pyiqa's `dist_to_mos`: the mean score `sum_i i * p_i`, `i = 1..=len`.
pub fn mean_score(distribution: &[f32]) -> f64 {
    distribution
        .iter()
        .enumerate()
        .map(|(i, p)| (i + 1) as f64 * f64::from(*p))
        .sum()
}
