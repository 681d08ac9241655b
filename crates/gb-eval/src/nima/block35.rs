//! `Block35` (Inception-ResNet-A): the ten residual 35x35 blocks of `repeat`, scale 0.17.

use burn::tensor::activation::relu;
use burn::tensor::Tensor;

use super::error::NimaError;
use super::layers::{Chain, Conv, ConvBn, Loader, K1, K3P1};

/// Channels of the residual stream.
pub(crate) const CHANNELS: usize = 320;
/// Number of blocks in `repeat`.
pub(crate) const COUNT: usize = 10;
/// Residual branch scale.
const SCALE: f32 = 0.17;

/// timm's `Block35` (`base_model.repeat.{i}.*`):
/// `relu(x + 0.17 * conv2d(cat(1x1 | 1x1-3x3 | 1x1-3x3-3x3)))`.
#[derive(Debug, Clone)]
pub(crate) struct Block35 {
    branch0: ConvBn,
    branch1: Chain,
    branch2: Chain,
    /// 128 -> 320, with the scale folded in.
    conv2d: Conv,
}

impl Block35 {
    /// Loads one block from its loader.
    pub(crate) fn load(l: &Loader) -> Result<Self, NimaError> {
        Ok(Self {
            branch0: l.conv_bn("branch0", CHANNELS, 32, K1)?,
            branch1: Chain::load(l, "branch1", &[(CHANNELS, 32, K1), (32, 32, K3P1)])?,
            branch2: Chain::load(
                l,
                "branch2",
                &[(CHANNELS, 32, K1), (32, 48, K3P1), (48, 64, K3P1)],
            )?,
            conv2d: l.conv("conv2d", 128, CHANNELS, K1, SCALE)?,
        })
    }

    /// `[N, 320, h, w]` -> `[N, 320, h, w]`.
    pub(crate) fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let branches = Tensor::cat(
            vec![
                self.branch0.forward(x.clone()),
                self.branch1.forward(x.clone()),
                self.branch2.forward(x.clone()),
            ],
            1,
        );
        relu(self.conv2d.forward(branches) + x)
    }
}
