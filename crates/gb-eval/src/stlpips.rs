//! ST-LPIPS (shift-tolerant LPIPS, Ghildyal & Liu 2022), AlexNet variant, in Burn.
//!
//! A port of `stlpips_pytorch.stlpips.LPIPS(net="alex", variant="shift_tolerant")` from the PyPI
//! package `stlpips-pytorch` 0.0.2, called as `model(pred, gt, normalize=True)` on [0, 1] images.
//! It runs on any gb_core backend, inference only (no autodiff).
//!
//! The network: inputs `2x - 1`, then `(x - shift) / scale`; AlexNet features with a stride-1
//! 11x11 first convolution and anti-aliased down-sampling ("BlurPool": reflect padding of 2 on
//! every side, then a depthwise 3x3 binomial filter with stride 2):
//! - relu1 = ReLU(blur(conv1(x)))
//! - relu2 = ReLU(conv2(blur(maxpool3s1(relu1))))
//! - relu3 = ReLU(conv3(blur(maxpool3s1(relu2))))
//! - relu4 = ReLU(conv4(relu3)), relu5 = ReLU(conv5(relu4))
//!
//! Each feature map is unit-normalised over channels (`x / (||x|| + 1e-10)`), the squared
//! difference is weighted per channel by the linear head (`linN`, a bias-free 1x1 convolution),
//! averaged over space, and the five layers are summed.
//!
//! Weights: `$GB_TEST_DATA/weights/stlpips_alex_shift_tolerant.safetensors`, with the package's
//! own key names (`net.slice1.0.weight`, `lin0.model.1.weight`, `scaling_layer.shift`, ...).

use std::path::Path;

use burn::module::{Module, Param};
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{Initializer, PaddingConfig2d};
use burn::store::{ModuleSnapshot, SafetensorsStore};
use burn::tensor::activation::relu;
use burn::tensor::module::{conv2d, max_pool2d};
use burn::tensor::ops::{ConvOptions, MaxPoolOptions, PadMode};
use burn::tensor::{Device, Tensor};
use gb_core::RgbImage;

use crate::error::MetricError;
use crate::lpips::{distance_from_features, pair_distance, size_check, PerceptualDistance};

/// Channels of the five AlexNet feature maps LPIPS compares.
const CHANNELS: [usize; 5] = [64, 192, 384, 256, 256];

/// How the package's tensor names map onto [`StLpipsAlexNet`]'s fields.
const KEY_MAP: [(&str, &str); 14] = [
    (r"^scaling_layer\.shift$", "shift"),
    (r"^scaling_layer\.scale$", "scale"),
    (r"^net\.slice1\.0\.", "conv1."),
    (r"^net\.slice1\.1\.filt$", "blur1"),
    (r"^net\.slice2\.4\.filt$", "blur2"),
    (r"^net\.slice2\.5\.", "conv2."),
    (r"^net\.slice3\.8\.filt$", "blur3"),
    (r"^net\.slice3\.9\.", "conv3."),
    (r"^net\.slice4\.11\.", "conv4."),
    (r"^net\.slice5\.13\.", "conv5."),
    (r"^lin0\.model\.1\.weight$", "lin0"),
    (r"^lin1\.model\.1\.weight$", "lin1"),
    (r"^lin2\.model\.1\.weight$", "lin2"),
    (r"^lin([34])\.model\.1\.weight$", "lin$1"),
];

/// The ST-LPIPS AlexNet network and its linear heads (weights only; see the module docs).
#[derive(Module, Debug)]
pub struct StLpipsAlexNet {
    /// Input shift of the scaling layer, `[1, 3, 1, 1]`.
    shift: Param<Tensor<4>>,
    /// Input scale of the scaling layer, `[1, 3, 1, 1]`.
    scale: Param<Tensor<4>>,
    /// 11x11, 3 -> 64, stride 1, padding 2.
    conv1: Conv2d,
    /// Blur filter after conv1, `[64, 1, 3, 3]`.
    blur1: Param<Tensor<4>>,
    /// Blur filter after the first max pool, `[64, 1, 3, 3]`.
    blur2: Param<Tensor<4>>,
    /// 5x5, 64 -> 192, padding 2.
    conv2: Conv2d,
    /// Blur filter after the second max pool, `[192, 1, 3, 3]`.
    blur3: Param<Tensor<4>>,
    /// 3x3, 192 -> 384, padding 1.
    conv3: Conv2d,
    /// 3x3, 384 -> 256, padding 1.
    conv4: Conv2d,
    /// 3x3, 256 -> 256, padding 1.
    conv5: Conv2d,
    /// Linear head of layer 1, `[1, 64, 1, 1]`.
    lin0: Param<Tensor<4>>,
    /// Linear head of layer 2, `[1, 192, 1, 1]`.
    lin1: Param<Tensor<4>>,
    /// Linear head of layer 3, `[1, 384, 1, 1]`.
    lin2: Param<Tensor<4>>,
    /// Linear head of layer 4, `[1, 256, 1, 1]`.
    lin3: Param<Tensor<4>>,
    /// Linear head of layer 5, `[1, 256, 1, 1]`.
    lin4: Param<Tensor<4>>,
}

fn conv(cin: usize, cout: usize, k: usize, pad: usize, device: &Device) -> Conv2d {
    Conv2dConfig::new([cin, cout], [k, k])
        .with_padding(PaddingConfig2d::Explicit(pad, pad, pad, pad))
        .with_initializer(Initializer::Zeros)
        .init(device)
}

fn zeros(shape: [usize; 4], device: &Device) -> Param<Tensor<4>> {
    Param::from_tensor(Tensor::zeros(shape, device))
}

impl StLpipsAlexNet {
    /// An all-zero network of the right shapes, to be filled by [`StLpipsAlexNet::load`].
    fn empty(device: &Device) -> Self {
        Self {
            shift: zeros([1, 3, 1, 1], device),
            scale: zeros([1, 3, 1, 1], device),
            conv1: conv(3, 64, 11, 2, device),
            blur1: zeros([64, 1, 3, 3], device),
            blur2: zeros([64, 1, 3, 3], device),
            conv2: conv(64, 192, 5, 2, device),
            blur3: zeros([192, 1, 3, 3], device),
            conv3: conv(192, 384, 3, 1, device),
            conv4: conv(384, 256, 3, 1, device),
            conv5: conv(256, 256, 3, 1, device),
            lin0: zeros([1, CHANNELS[0], 1, 1], device),
            lin1: zeros([1, CHANNELS[1], 1, 1], device),
            lin2: zeros([1, CHANNELS[2], 1, 1], device),
            lin3: zeros([1, CHANNELS[3], 1, 1], device),
            lin4: zeros([1, CHANNELS[4], 1, 1], device),
        }
    }

    /// Loads the network from the package's safetensors file; every tensor must be present
    /// with the expected shape, and no tensor may be left over.
    pub fn load(path: &Path, device: &Device) -> Result<Self, MetricError> {
        let err = |reason: String| MetricError::Weights {
            path: path.to_path_buf(),
            what: "ST-LPIPS AlexNet",
            reason,
        };
        if !path.is_file() {
            return Err(err("file not found".into()));
        }
        let mut store = SafetensorsStore::from_file(path);
        for (from, to) in KEY_MAP {
            store = store.with_key_remapping(from, to);
        }
        let mut model = Self::empty(device);
        let result = model
            .load_from(&mut store)
            .map_err(|e| err(e.to_string()))?;
        if !result.unused.is_empty() {
            return Err(err(format!("unexpected tensors {:?}", result.unused)));
        }
        Ok(model)
    }

    /// The five feature maps of a batch `[n, 3, h, w]` already scaled to [-1, 1].
    fn features(&self, x: Tensor<4>) -> [Tensor<4>; 5] {
        let x = (x - self.shift.val()) / self.scale.val();
        let r1 = relu(blur_pool(self.conv1.forward(x), self.blur1.val()));
        let h = blur_pool(max_pool3(r1.clone()), self.blur2.val());
        let r2 = relu(self.conv2.forward(h));
        let h = blur_pool(max_pool3(r2.clone()), self.blur3.val());
        let r3 = relu(self.conv3.forward(h));
        let r4 = relu(self.conv4.forward(r3.clone()));
        let r5 = relu(self.conv5.forward(r4.clone()));
        [r1, r2, r3, r4, r5]
    }

    /// Per-item distances `[n]` between two batches `[n, 3, h, w]` of [0, 1] images.
    pub fn forward(&self, pred: Tensor<4>, gt: Tensor<4>) -> Tensor<1> {
        let n = pred.dims()[0];
        let feats = self.features(Tensor::cat(vec![pred, gt], 0) * 2.0 - 1.0);
        let lins = [&self.lin0, &self.lin1, &self.lin2, &self.lin3, &self.lin4].map(|l| l.val());
        distance_from_features(Vec::from(feats), &lins, n)
    }
}

/// 3x3 max pool, stride 1, no padding.
fn max_pool3(x: Tensor<4>) -> Tensor<4> {
    max_pool2d(x, MaxPoolOptions::new([3, 3]).with_stride([1, 1]))
}

/// The package's `Downsample(filt_size=3, stride=2, pad_more=True)`: reflect-pad 2 on each side,
/// then a depthwise 3x3 filter with stride 2.
fn blur_pool(x: Tensor<4>, filt: Tensor<4>) -> Tensor<4> {
    let channels = x.dims()[1];
    let padded = x.pad([(2, 2), (2, 2)], PadMode::Reflect);
    conv2d(
        padded,
        filt,
        None,
        ConvOptions::new([2, 2], [0, 0], [1, 1], channels),
    )
}

/// The smallest side (in pixels) whose feature maps stay valid through every layer.
pub const MIN_SIDE: usize = 21;

/// Whether an image side of `n` pixels survives the network (reflect padding of 2 needs at
/// least 3 pixels, pooling at least 3).
fn side_is_valid(n: usize) -> bool {
    let blur = |s: usize| (s + 4 - 3) / 2 + 1;
    let Some(s1) = n.checked_sub(6) else {
        return false;
    };
    if s1 < 3 {
        return false;
    }
    let m1 = blur(s1).saturating_sub(2);
    if m1 < 3 {
        return false;
    }
    let m2 = blur(m1).saturating_sub(2);
    m2 >= 3
}

/// ST-LPIPS with its weights, ready to score image pairs on one device.
#[derive(Debug)]
pub struct StLpips {
    net: StLpipsAlexNet,
    device: Device,
}

impl StLpips {
    /// File name of the weights inside a weights folder.
    pub const WEIGHTS_FILE: &'static str = "stlpips_alex_shift_tolerant.safetensors";

    /// Loads the network from `path` onto `device`.
    pub fn load(path: &Path, device: &Device) -> Result<Self, MetricError> {
        Ok(Self {
            net: StLpipsAlexNet::load(path, device)?,
            device: device.clone(),
        })
    }
}

impl PerceptualDistance for StLpips {
    fn distance(&self, pred: &RgbImage, gt: &RgbImage) -> Result<f64, MetricError> {
        let check = |img: &RgbImage| {
            let fits = side_is_valid(img.width) && side_is_valid(img.height);
            size_check(img, "ST-LPIPS", MIN_SIDE, fits)
        };
        pair_distance(pred, gt, &self.device, check, |p, g| self.net.forward(p, g))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn min_side_is_the_first_valid_size() {
        assert!(side_is_valid(MIN_SIDE));
        assert!(!side_is_valid(MIN_SIDE - 1));
        assert!((MIN_SIDE..200).all(side_is_valid));
    }
}
