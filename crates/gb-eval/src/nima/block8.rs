//! `Block8` (Inception-ResNet-C): the nine residual 8x8 blocks of `repeat_2` (scale 0.2, ReLU)
//! and the final `block8` (scale 1, no ReLU), with a factorised 1x3 / 3x1 branch.

use burn::tensor::activation::relu;
use burn::tensor::Tensor;

use super::error::NimaError;
use super::layers::{Chain, Conv, ConvBn, ConvSpec, Loader, K1};

/// Channels of the residual stream.
pub(crate) const CHANNELS: usize = 2080;
/// Number of blocks in `repeat_2` (the tenth, `block8`, stands alone).
pub(crate) const COUNT: usize = 9;
/// Residual branch scale of `repeat_2`.
pub(crate) const REPEAT_SCALE: f32 = 0.20;

/// 1x3, padding (0, 1).
const K1X3: ConvSpec = ConvSpec {
    kernel: [1, 3],
    stride: 1,
    padding: [0, 1],
};
/// 3x1, padding (1, 0).
const K3X1: ConvSpec = ConvSpec {
    kernel: [3, 1],
    stride: 1,
    padding: [1, 0],
};

/// timm's `Block8` (`base_model.repeat_2.{i}.*`, `base_model.block8.*`):
/// `x + scale * conv2d(cat(1x1 | 1x1-1x3-3x1))`, then ReLU unless `no_relu`.
#[derive(Debug, Clone)]
pub(crate) struct Block8 {
    branch0: ConvBn,
    branch1: Chain,
    /// 448 -> 2080, with the scale folded in.
    conv2d: Conv,
    relu: bool,
}

impl Block8 {
    /// Loads one block from its loader with its residual `scale`, and ReLU or not.
    pub(crate) fn load(l: &Loader, scale: f32, relu: bool) -> Result<Self, NimaError> {
        Ok(Self {
            branch0: l.conv_bn("branch0", CHANNELS, 192, K1)?,
            branch1: Chain::load(
                l,
                "branch1",
                &[(CHANNELS, 192, K1), (192, 224, K1X3), (224, 256, K3X1)],
            )?,
            conv2d: l.conv("conv2d", 448, CHANNELS, K1, scale)?,
            relu,
        })
    }

    /// `[N, 2080, h, w]` -> `[N, 2080, h, w]`.
    pub(crate) fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let branches = Tensor::cat(
            vec![
                self.branch0.forward(x.clone()),
                self.branch1.forward(x.clone()),
            ],
            1,
        );
        let out = self.conv2d.forward(branches) + x;
        if self.relu {
            relu(out)
        } else {
            out
        }
    }
}
