//! Standard LPIPS (Zhang et al. 2018), AlexNet or VGG16 backbone, with user-supplied weights.
//!
//! A port of `lpips.LPIPS(net="alex" | "vgg", version="0.1")` from the PyPI package `lpips`
//! 0.1.4, called as `model(pred, gt, normalize=True)` on [0, 1] images. No weights ship with
//! gb-nerf-rs: the user passes one safetensors file holding the package's whole state dict
//! (`net.sliceK.I.weight/bias` from torchvision's backbone, `linK.model.1.weight`,
//! optionally `scaling_layer.shift/scale`), e.g. written by
//! `safetensors.torch.save_file(lpips.LPIPS(net="alex").state_dict(), "lpips_alex.safetensors")`
//! (drop the duplicate `lins.*` keys first).
//!
//! The distance: inputs `2x - 1`, then `(x - shift) / scale` with the package's constants;
//! five ReLU feature maps (AlexNet relu1..relu5; VGG16 relu1_2, relu2_2, relu3_3, relu4_3,
//! relu5_3); each unit-normalised over channels, squared difference weighted by the linear
//! head, averaged over space, summed over the five layers. Identical to ST-LPIPS apart from the
//! backbone (see [`crate::stlpips`]), so both share `distance_from_features`.

use std::path::Path;

use burn::module::{Module, Param};
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{Initializer, PaddingConfig2d};
use burn::store::{ModuleSnapshot, SafetensorsStore};
use burn::tensor::activation::relu;
use burn::tensor::module::max_pool2d;
use burn::tensor::ops::MaxPoolOptions;
use burn::tensor::{Device, Tensor, TensorData};
use gb_core::RgbImage;

use crate::error::MetricError;
use crate::image_metrics::{check_bbox, check_pair};

/// The LPIPS input scaling constants (`ScalingLayer` of both packages).
const SHIFT: [f32; 3] = [-0.030, -0.088, -0.188];
const SCALE: [f32; 3] = [0.458, 0.448, 0.450];

/// The backbone network of standard LPIPS.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backbone {
    /// torchvision AlexNet features (stride-4 first convolution).
    Alex,
    /// torchvision VGG16 features.
    Vgg,
}

impl Backbone {
    /// `(package key prefix, in, out, kernel, stride, padding)` of every convolution, in order.
    fn convs(self) -> Vec<(&'static str, usize, usize, usize, usize, usize)> {
        match self {
            Backbone::Alex => vec![
                ("net.slice1.0.", 3, 64, 11, 4, 2),
                ("net.slice2.3.", 64, 192, 5, 1, 2),
                ("net.slice3.6.", 192, 384, 3, 1, 1),
                ("net.slice4.8.", 384, 256, 3, 1, 1),
                ("net.slice5.10.", 256, 256, 3, 1, 1),
            ],
            Backbone::Vgg => vec![
                ("net.slice1.0.", 3, 64, 3, 1, 1),
                ("net.slice1.2.", 64, 64, 3, 1, 1),
                ("net.slice2.5.", 64, 128, 3, 1, 1),
                ("net.slice2.7.", 128, 128, 3, 1, 1),
                ("net.slice3.10.", 128, 256, 3, 1, 1),
                ("net.slice3.12.", 256, 256, 3, 1, 1),
                ("net.slice3.14.", 256, 256, 3, 1, 1),
                ("net.slice4.17.", 256, 512, 3, 1, 1),
                ("net.slice4.19.", 512, 512, 3, 1, 1),
                ("net.slice4.21.", 512, 512, 3, 1, 1),
                ("net.slice5.24.", 512, 512, 3, 1, 1),
                ("net.slice5.26.", 512, 512, 3, 1, 1),
                ("net.slice5.28.", 512, 512, 3, 1, 1),
            ],
        }
    }

    /// Channels of the five compared feature maps.
    fn channels(self) -> [usize; 5] {
        match self {
            Backbone::Alex => [64, 192, 384, 256, 256],
            Backbone::Vgg => [64, 128, 256, 512, 512],
        }
    }

    /// The smallest image side the backbone accepts.
    pub fn min_side(self) -> usize {
        match self {
            // conv1 (11, s4, p2) then two 3x3/2 max pools: 31 px give 7 -> 3 -> 1.
            Backbone::Alex => 31,
            // four 2x2/2 max pools.
            Backbone::Vgg => 16,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Backbone::Alex => "LPIPS AlexNet",
            Backbone::Vgg => "LPIPS VGG16",
        }
    }
}

/// Standard LPIPS: backbone convolutions and linear heads.
#[derive(Module, Debug)]
pub struct LpipsNet {
    /// Input shift, `[1, 3, 1, 1]`.
    shift: Param<Tensor<4>>,
    /// Input scale, `[1, 3, 1, 1]`.
    scale: Param<Tensor<4>>,
    /// The backbone's convolutions in order.
    convs: Vec<Conv2d>,
    /// Linear heads, `[1, C_k, 1, 1]` each.
    lins: Vec<Param<Tensor<4>>>,
    /// Which backbone.
    #[module(skip)]
    backbone: Backbone,
}

impl LpipsNet {
    fn empty(backbone: Backbone, device: &Device) -> Self {
        let convs = backbone
            .convs()
            .into_iter()
            .map(|(_, cin, cout, k, s, p)| {
                Conv2dConfig::new([cin, cout], [k, k])
                    .with_stride([s, s])
                    .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
                    .with_initializer(Initializer::Zeros)
                    .init(device)
            })
            .collect();
        let lins = backbone
            .channels()
            .iter()
            .map(|&c| Param::from_tensor(Tensor::zeros([1, c, 1, 1], device)))
            .collect();
        let constant = |v: [f32; 3]| {
            Param::from_tensor(Tensor::<4>::from_data(
                TensorData::new(v.to_vec(), [1, 3, 1, 1]),
                device,
            ))
        };
        Self {
            shift: constant(SHIFT),
            scale: constant(SCALE),
            convs,
            lins,
            backbone,
        }
    }

    /// Loads the package's state dict from a safetensors file (see the module docs). Every
    /// backbone and head tensor must be present; the scaling constants may be absent.
    pub fn load(path: &Path, backbone: Backbone, device: &Device) -> Result<Self, MetricError> {
        let err = |reason: String| MetricError::Weights {
            path: path.to_path_buf(),
            what: backbone.name(),
            reason,
        };
        if !path.is_file() {
            return Err(err("file not found".into()));
        }
        let mut store = SafetensorsStore::from_file(path)
            .allow_partial(true)
            .with_key_remapping(r"^scaling_layer\.shift$", "shift")
            .with_key_remapping(r"^scaling_layer\.scale$", "scale");
        for (i, (prefix, ..)) in backbone.convs().iter().enumerate() {
            store = store
                .with_key_remapping(format!("^{}", regex_escape(prefix)), format!("convs.{i}."));
        }
        store = store.with_key_remapping(r"^lin([0-4])\.model\.1\.weight$", "lins.$1");
        let mut model = Self::empty(backbone, device);
        let result = model
            .load_from(&mut store)
            .map_err(|e| err(e.to_string()))?;
        let missing: Vec<&String> = result
            .missing
            .iter()
            .map(|(p, _)| p)
            .filter(|p| *p != "shift" && *p != "scale")
            .collect();
        if !missing.is_empty() {
            return Err(err(format!("missing tensors {missing:?}")));
        }
        // `lins.K.*` duplicates `linK.*` in the package's state dict: tolerated.
        let unused: Vec<&String> = result
            .unused
            .iter()
            .filter(|k| !k.starts_with("lins."))
            .collect();
        if !unused.is_empty() {
            return Err(err(format!("unexpected tensors {unused:?}")));
        }
        if !result.errors.is_empty() {
            return Err(err(format!("{:?}", result.errors)));
        }
        Ok(model)
    }

    fn features(&self, x: Tensor<4>) -> Vec<Tensor<4>> {
        let x = (x - self.shift.val()) / self.scale.val();
        let c = |i: usize, h: Tensor<4>| relu(self.convs[i].forward(h));
        match self.backbone {
            Backbone::Alex => {
                let pool =
                    |h: Tensor<4>| max_pool2d(h, MaxPoolOptions::new([3, 3]).with_stride([2, 2]));
                let r1 = c(0, x);
                let r2 = c(1, pool(r1.clone()));
                let r3 = c(2, pool(r2.clone()));
                let r4 = c(3, r3.clone());
                let r5 = c(4, r4.clone());
                vec![r1, r2, r3, r4, r5]
            }
            Backbone::Vgg => {
                let pool = |h: Tensor<4>| max_pool2d(h, MaxPoolOptions::new([2, 2]));
                let r1 = c(1, c(0, x));
                let r2 = c(3, c(2, pool(r1.clone())));
                let r3 = c(6, c(5, c(4, pool(r2.clone()))));
                let r4 = c(9, c(8, c(7, pool(r3.clone()))));
                let r5 = c(12, c(11, c(10, pool(r4.clone()))));
                vec![r1, r2, r3, r4, r5]
            }
        }
    }

    /// Per-item distances `[n]` between two batches `[n, 3, h, w]` of [0, 1] images.
    pub fn forward(&self, pred: Tensor<4>, gt: Tensor<4>) -> Tensor<1> {
        let n = pred.dims()[0];
        let feats = self.features(Tensor::cat(vec![pred, gt], 0) * 2.0 - 1.0);
        let lins: Vec<Tensor<4>> = self.lins.iter().map(|l| l.val()).collect();
        distance_from_features(feats, &lins, n)
    }
}

/// LPIPS from the features of a batch `[pred; gt]` (first `n` items predictions): unit-normalise
/// each map over channels (`x / (||x|| + 1e-10)`), weight the squared difference by the head,
/// average over space and sum over layers.
pub(crate) fn distance_from_features(
    feats: Vec<Tensor<4>>,
    lins: &[Tensor<4>],
    n: usize,
) -> Tensor<1> {
    let mut total: Option<Tensor<1>> = None;
    for (f, lin) in feats.into_iter().zip(lins) {
        let norm = f.clone().powi_scalar(2).sum_dim(1).sqrt() + 1e-10;
        let f = f / norm;
        let [_, c, h, w] = f.dims();
        let f0 = f.clone().slice([0..n, 0..c, 0..h, 0..w]);
        let f1 = f.slice([n..2 * n, 0..c, 0..h, 0..w]);
        let d = (f0 - f1).powi_scalar(2) * lin.clone();
        let layer = d.sum_dim(1).mean_dim(2).mean_dim(3).reshape([n]);
        total = Some(match total {
            Some(t) => t + layer,
            None => layer,
        });
    }
    total.expect("LPIPS compares five feature maps")
}

fn regex_escape(s: &str) -> String {
    s.replace('.', r"\.")
}

/// `[1, 3, h, w]` from an `[h, w, 3]` image.
pub(crate) fn image_tensor(img: &RgbImage, device: &Device) -> Tensor<4> {
    let data = TensorData::new(img.data.clone(), [1, img.height, img.width, 3]);
    Tensor::<4>::from_data(data, device).permute([0, 3, 1, 2])
}

/// Standard LPIPS with its weights, ready to score image pairs on one device.
#[derive(Debug)]
pub struct Lpips {
    net: LpipsNet,
    device: Device,
}

impl Lpips {
    /// Loads the `backbone` network from `path` onto `device`.
    pub fn load(path: &Path, backbone: Backbone, device: &Device) -> Result<Self, MetricError> {
        Ok(Self {
            net: LpipsNet::load(path, backbone, device)?,
            device: device.clone(),
        })
    }
}

impl PerceptualDistance for Lpips {
    fn distance(&self, pred: &RgbImage, gt: &RgbImage) -> Result<f64, MetricError> {
        let (name, min) = (self.net.backbone.name(), self.net.backbone.min_side());
        let check =
            |img: &RgbImage| size_check(img, name, min, img.width >= min && img.height >= min);
        pair_distance(pred, gt, &self.device, check, |p, g| self.net.forward(p, g))
    }
}

/// A perceptual network's distance between two images of one size: LPIPS ([`Lpips`]) and
/// ST-LPIPS ([`crate::stlpips::StLpips`]). Lower is better; 0 for identical images.
pub trait PerceptualDistance {
    /// The distance between `pred` and `gt` over the whole images.
    fn distance(&self, pred: &RgbImage, gt: &RgbImage) -> Result<f64, MetricError>;

    /// The distance over the crop with columns `x0..x1` and rows `y0..y1` (ends exclusive).
    fn distance_bbox(
        &self,
        pred: &RgbImage,
        gt: &RgbImage,
        (x0, y0, x1, y1): (usize, usize, usize, usize),
    ) -> Result<f64, MetricError> {
        check_pair(pred, gt)?;
        check_bbox(x0, y0, x1, y1, pred.width, pred.height)?;
        self.distance(&crop(pred, x0, y0, x1, y1), &crop(gt, x0, y0, x1, y1))
    }
}

/// The distance of a perceptual network (LPIPS, ST-LPIPS) between two images of one size,
/// after `check` (the network's size limit), by `forward` on their tensors on `device`.
pub(crate) fn pair_distance(
    pred: &RgbImage,
    gt: &RgbImage,
    device: &Device,
    check: impl Fn(&RgbImage) -> Result<(), MetricError>,
    forward: impl Fn(Tensor<4>, Tensor<4>) -> Tensor<1>,
) -> Result<f64, MetricError> {
    check_pair(pred, gt)?;
    check(pred)?;
    let d = forward(image_tensor(pred, device), image_tensor(gt, device));
    let v: f32 = d.into_scalar();
    Ok(f64::from(v))
}

/// [`MetricError::TooSmall`] for `metric` (smallest side `min`) unless `fits` holds for `img`.
pub(crate) fn size_check(
    img: &RgbImage,
    metric: &'static str,
    min: usize,
    fits: bool,
) -> Result<(), MetricError> {
    if fits {
        return Ok(());
    }
    Err(MetricError::TooSmall {
        metric,
        min,
        width: img.width,
        height: img.height,
    })
}

/// The crop `x0..x1`, `y0..y1` of an image (bounds already checked).
fn crop(img: &RgbImage, x0: usize, y0: usize, x1: usize, y1: usize) -> RgbImage {
    let mut data = Vec::with_capacity((x1 - x0) * (y1 - y0) * 3);
    for y in y0..y1 {
        data.extend_from_slice(&img.data[(y * img.width + x0) * 3..(y * img.width + x1) * 3]);
    }
    RgbImage {
        width: x1 - x0,
        height: y1 - y0,
        data,
    }
}
