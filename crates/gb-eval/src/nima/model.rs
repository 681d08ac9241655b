//! The InceptionResNetV2 backbone as timm 1.0.31 builds it (`inception_resnet_v2`, the
//! `features_only` network that pyiqa's NIMA uses): stem, `mixed_5b`, 10 x `Block35`,
//! `mixed_6a`, 20 x `Block17`, `mixed_7a`, 9 x `Block8`, `block8` (no ReLU), `conv2d_7b`
//! (1x1 `ConvNormAct` to 1536 channels), then a global average pool.
//!
//! Every tensor name is timm's state-dict key under `base_model.`; batch norm is in eval mode
//! with eps 1e-3 (timm's `norm_eps` default for this model) and folded into the convolutions.

use burn::tensor::Tensor;

use super::block17::{self, Block17};
use super::block35::{self, Block35};
use super::block8::{self, Block8};
use super::error::NimaError;
use super::layers::{ConvBn, Loader, K1};
use super::mixed_5b::{Mixed5b, MIXED_5B_CHANNELS};
use super::mixed_6a::{Mixed6a, MIXED_6A_CHANNELS};
use super::mixed_7a::{Mixed7a, MIXED_7A_CHANNELS};
use super::stem::Stem;

/// Channels of the last feature map (`conv2d_7b`), the length of the pooled feature.
pub const FEATURE_DIM: usize = 1536;

/// InceptionResNetV2 without its ImageNet classifier (inference only).
#[derive(Debug, Clone)]
pub(crate) struct InceptionResNetV2 {
    stem: Stem,
    mixed_5b: Mixed5b,
    repeat: Vec<Block35>,
    mixed_6a: Mixed6a,
    repeat_1: Vec<Block17>,
    mixed_7a: Mixed7a,
    repeat_2: Vec<Block8>,
    block8: Block8,
    conv2d_7b: ConvBn,
}

impl InceptionResNetV2 {
    /// Loads the backbone from the backbone loader (`base_model.`).
    pub(crate) fn load(l: &Loader) -> Result<Self, NimaError> {
        const _: () = assert!(MIXED_5B_CHANNELS == block35::CHANNELS);
        const _: () = assert!(MIXED_6A_CHANNELS == block17::CHANNELS);
        const _: () = assert!(MIXED_7A_CHANNELS == block8::CHANNELS);
        let repeat = |name: &str, i: usize| l.sub(name).sub(&i.to_string());
        Ok(Self {
            stem: Stem::load(l)?,
            mixed_5b: Mixed5b::load(&l.sub("mixed_5b"))?,
            repeat: (0..block35::COUNT)
                .map(|i| Block35::load(&repeat("repeat", i)))
                .collect::<Result<_, _>>()?,
            mixed_6a: Mixed6a::load(&l.sub("mixed_6a"))?,
            repeat_1: (0..block17::COUNT)
                .map(|i| Block17::load(&repeat("repeat_1", i)))
                .collect::<Result<_, _>>()?,
            mixed_7a: Mixed7a::load(&l.sub("mixed_7a"))?,
            repeat_2: (0..block8::COUNT)
                .map(|i| Block8::load(&repeat("repeat_2", i), block8::REPEAT_SCALE, true))
                .collect::<Result<_, _>>()?,
            block8: Block8::load(&l.sub("block8"), 1.0, false)?,
            conv2d_7b: l.conv_bn("conv2d_7b", block8::CHANNELS, FEATURE_DIM, K1)?,
        })
    }

    /// The `conv2d_7b` feature map `[N, 1536, h, w]` of a normalised batch `[N, 3, H, W]`
    /// (`H, W >= 75`).
    pub(crate) fn forward_features(&self, x: Tensor<4>) -> Tensor<4> {
        let mut x = self.mixed_5b.forward(self.stem.forward(x));
        for block in &self.repeat {
            x = block.forward(x);
        }
        x = self.mixed_6a.forward(x);
        for block in &self.repeat_1 {
            x = block.forward(x);
        }
        x = self.mixed_7a.forward(x);
        for block in &self.repeat_2 {
            x = block.forward(x);
        }
        self.conv2d_7b.forward(self.block8.forward(x))
    }

    /// Globally average-pooled features `[N, 1536]` (`AdaptiveAvgPool2d(1)` + flatten).
    pub(crate) fn forward_pooled(&self, x: Tensor<4>) -> Tensor<2> {
        let x = self.forward_features(x);
        let [n, c, _, _] = x.dims();
        x.mean_dim(3).mean_dim(2).reshape([n, c])
    }
}
