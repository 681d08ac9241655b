//! `Mixed_6a` (Reduction-A): 35x35x320 -> 17x17x1088 (3x3/2 | 1x1-3x3-3x3/2 | maxpool/2).

use burn::tensor::Tensor;

use super::error::NimaError;
use super::layers::{max_pool_3x3_s2, Chain, ConvBn, Loader, K1, K3P1, K3S2};

/// Output channels: 384 + 384 + 320.
pub(crate) const MIXED_6A_CHANNELS: usize = 1088;

/// timm's `Mixed_6a` (`base_model.mixed_6a.*`).
#[derive(Debug, Clone)]
pub(crate) struct Mixed6a {
    branch0: ConvBn,
    branch1: Chain,
}

impl Mixed6a {
    /// Loads `mixed_6a` from its loader.
    pub(crate) fn load(l: &Loader) -> Result<Self, NimaError> {
        Ok(Self {
            branch0: l.conv_bn("branch0", 320, 384, K3S2)?,
            branch1: Chain::load(
                l,
                "branch1",
                &[(320, 256, K1), (256, 256, K3P1), (256, 384, K3S2)],
            )?,
        })
    }

    /// `[N, 320, h, w]` -> `[N, 1088, (h-3)/2+1, (w-3)/2+1]`.
    pub(crate) fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        Tensor::cat(
            vec![
                self.branch0.forward(x.clone()),
                self.branch1.forward(x.clone()),
                max_pool_3x3_s2(x),
            ],
            1,
        )
    }
}
