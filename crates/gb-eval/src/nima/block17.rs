//! `Block17` (Inception-ResNet-B): the twenty residual 17x17 blocks of `repeat_1`, scale 0.1,
//! with a factorised 1x7 / 7x1 branch.

use burn::tensor::activation::relu;
use burn::tensor::Tensor;

use super::error::NimaError;
use super::layers::{Chain, Conv, ConvBn, ConvSpec, Loader, K1};

/// Channels of the residual stream.
pub(crate) const CHANNELS: usize = 1088;
/// Number of blocks in `repeat_1`.
pub(crate) const COUNT: usize = 20;
/// Residual branch scale.
const SCALE: f32 = 0.10;

/// 1x7, padding (0, 3).
const K1X7: ConvSpec = ConvSpec {
    kernel: [1, 7],
    stride: 1,
    padding: [0, 3],
};
/// 7x1, padding (3, 0).
const K7X1: ConvSpec = ConvSpec {
    kernel: [7, 1],
    stride: 1,
    padding: [3, 0],
};

/// timm's `Block17` (`base_model.repeat_1.{i}.*`):
/// `relu(x + 0.1 * conv2d(cat(1x1 | 1x1-1x7-7x1)))`.
#[derive(Debug, Clone)]
pub(crate) struct Block17 {
    branch0: ConvBn,
    branch1: Chain,
    /// 384 -> 1088, with the scale folded in.
    conv2d: Conv,
}

impl Block17 {
    /// Loads one block from its loader.
    pub(crate) fn load(l: &Loader) -> Result<Self, NimaError> {
        Ok(Self {
            branch0: l.conv_bn("branch0", CHANNELS, 192, K1)?,
            branch1: Chain::load(
                l,
                "branch1",
                &[(CHANNELS, 128, K1), (128, 160, K1X7), (160, 192, K7X1)],
            )?,
            conv2d: l.conv("conv2d", 384, CHANNELS, K1, SCALE)?,
        })
    }

    /// `[N, 1088, h, w]` -> `[N, 1088, h, w]`.
    pub(crate) fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let branches = Tensor::cat(
            vec![
                self.branch0.forward(x.clone()),
                self.branch1.forward(x.clone()),
            ],
            1,
        );
        relu(self.conv2d.forward(branches) + x)
    }
}
