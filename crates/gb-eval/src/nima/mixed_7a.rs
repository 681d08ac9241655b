//! `Mixed_7a` (Reduction-B): 17x17x1088 -> 8x8x2080
//! (1x1-3x3/2 | 1x1-3x3/2 | 1x1-3x3-3x3/2 | maxpool/2).

use burn::tensor::Tensor;

use super::error::NimaError;
use super::layers::{max_pool_3x3_s2, Chain, Loader, K1, K3P1, K3S2};

/// Output channels: 384 + 288 + 320 + 1088.
pub(crate) const MIXED_7A_CHANNELS: usize = 2080;

/// timm's `Mixed_7a` (`base_model.mixed_7a.*`).
#[derive(Debug, Clone)]
pub(crate) struct Mixed7a {
    branch0: Chain,
    branch1: Chain,
    branch2: Chain,
}

impl Mixed7a {
    /// Loads `mixed_7a` from its loader.
    pub(crate) fn load(l: &Loader) -> Result<Self, NimaError> {
        Ok(Self {
            branch0: Chain::load(l, "branch0", &[(1088, 256, K1), (256, 384, K3S2)])?,
            branch1: Chain::load(l, "branch1", &[(1088, 256, K1), (256, 288, K3S2)])?,
            branch2: Chain::load(
                l,
                "branch2",
                &[(1088, 256, K1), (256, 288, K3P1), (288, 320, K3S2)],
            )?,
        })
    }

    /// `[N, 1088, h, w]` -> `[N, 2080, (h-3)/2+1, (w-3)/2+1]`.
    pub(crate) fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        Tensor::cat(
            vec![
                self.branch0.forward(x.clone()),
                self.branch1.forward(x.clone()),
                self.branch2.forward(x.clone()),
                max_pool_3x3_s2(x),
            ],
            1,
        )
    }
}
