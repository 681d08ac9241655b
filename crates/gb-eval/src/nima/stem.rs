//! The stem of InceptionResNetV2: five `ConvNormAct` layers and two max pools, 3 -> 192
//! channels at 1/8 of the input side (299 -> 35).

use burn::tensor::Tensor;

use super::error::NimaError;
use super::layers::{max_pool_3x3_s2, ConvBn, Loader, K1, K3, K3P1, K3S2};

/// `conv2d_1a` ... `conv2d_4a` with `maxpool_3a` and `maxpool_5a`.
#[derive(Debug, Clone)]
pub(crate) struct Stem {
    conv2d_1a: ConvBn,
    conv2d_2a: ConvBn,
    conv2d_2b: ConvBn,
    conv2d_3b: ConvBn,
    conv2d_4a: ConvBn,
}

/// Output channels of the stem.
pub(crate) const STEM_CHANNELS: usize = 192;

impl Stem {
    /// Loads the stem from the backbone loader (`base_model.`).
    pub(crate) fn load(l: &Loader) -> Result<Self, NimaError> {
        Ok(Self {
            conv2d_1a: l.conv_bn("conv2d_1a", 3, 32, K3S2)?,
            conv2d_2a: l.conv_bn("conv2d_2a", 32, 32, K3)?,
            conv2d_2b: l.conv_bn("conv2d_2b", 32, 64, K3P1)?,
            conv2d_3b: l.conv_bn("conv2d_3b", 64, 80, K1)?,
            conv2d_4a: l.conv_bn("conv2d_4a", 80, STEM_CHANNELS, K3)?,
        })
    }

    /// `[N, 3, H, W]` -> `[N, 192, H', W']`.
    pub(crate) fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let x = self.conv2d_1a.forward(x);
        let x = self.conv2d_2a.forward(x);
        let x = self.conv2d_2b.forward(x);
        let x = max_pool_3x3_s2(x);
        let x = self.conv2d_3b.forward(x);
        let x = self.conv2d_4a.forward(x);
        max_pool_3x3_s2(x)
    }
}
