//! `Mixed_5b`: the 35x35 inception block that widens the stem's 192 channels to 320
//! (1x1 | 1x1-5x5 | 1x1-3x3-3x3 | avgpool-1x1).

use burn::tensor::Tensor;

use super::error::NimaError;
use super::layers::{avg_pool_3x3_s1, Chain, ConvBn, ConvSpec, Loader, K1, K3P1};

/// 5x5, padding 2.
const K5P2: ConvSpec = ConvSpec {
    kernel: [5, 5],
    stride: 1,
    padding: [2, 2],
};

/// Output channels: 96 + 64 + 96 + 64.
pub(crate) const MIXED_5B_CHANNELS: usize = 320;

/// timm's `Mixed_5b` (`base_model.mixed_5b.*`).
#[derive(Debug, Clone)]
pub(crate) struct Mixed5b {
    branch0: ConvBn,
    branch1: Chain,
    branch2: Chain,
    /// `branch3` is `AvgPool2d` then this `ConvNormAct` (`branch3.1`).
    branch3_conv: ConvBn,
}

impl Mixed5b {
    /// Loads `mixed_5b` from its loader.
    pub(crate) fn load(l: &Loader) -> Result<Self, NimaError> {
        Ok(Self {
            branch0: l.conv_bn("branch0", 192, 96, K1)?,
            branch1: Chain::load(l, "branch1", &[(192, 48, K1), (48, 64, K5P2)])?,
            branch2: Chain::load(
                l,
                "branch2",
                &[(192, 64, K1), (64, 96, K3P1), (96, 96, K3P1)],
            )?,
            branch3_conv: l.sub("branch3").conv_bn("1", 192, 64, K1)?,
        })
    }

    /// `[N, 192, h, w]` -> `[N, 320, h, w]`.
    pub(crate) fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        Tensor::cat(
            vec![
                self.branch0.forward(x.clone()),
                self.branch1.forward(x.clone()),
                self.branch2.forward(x.clone()),
                self.branch3_conv.forward(avg_pool_3x3_s1(x)),
            ],
            1,
        )
    }
}
