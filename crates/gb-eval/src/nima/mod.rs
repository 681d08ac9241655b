//! NIMA (Neural Image Assessment, Talebi & Milanfar, IEEE TIP 2018) as pyiqa's `nima`
//! metric computes it: an InceptionResNetV2 backbone (timm `inception_resnet_v2`), a global
//! average pool, `Linear(1536, 10)` and a softmax over the ten AVA rating bins; the score is
//! the distribution's mean, `sum_{i=1..10} i p_i` (pyiqa's `dist_to_mos`), in [1, 10],
//! higher is better. No-reference: it scores each image alone.
//!
//! # Input pipeline
//! As pyiqa in eval mode ([`preprocess()`]): RGB in [0, 1] -> shorter side resized to 299
//! (torchvision bilinear, antialiased) -> 299x299 center crop -> `(x - 0.5) / 0.5`.
//!
//! # Weights
//! No weights ship with the project. Bring pyiqa's checkpoint (`NIMA_InceptionV2_ava-b0c77c00.pth`,
//! a dict whose `params` entry is the state dict) as safetensors:
//! ```text
//! python -c "import torch, safetensors.torch as st; \
//!   st.save_file(torch.load('NIMA_InceptionV2_ava-b0c77c00.pth', map_location='cpu')['params'], \
//!   'nima_inception_resnet_v2_ava.safetensors')"
//! ```
//! Keys are timm's under `base_model.` (`base_model.conv2d_1a.conv.weight`,
//! `base_model.repeat.0.branch1.1.bn.running_var`, ...) plus `classifier.2.weight` `[10, 1536]`
//! and `classifier.2.bias`; another prefix in front of them (`net.`) is accepted, and
//! `num_batches_tracked` is ignored. A missing tensor or a wrong shape is an error that names
//! the tensor and the file.
//!
//! # Parity
//! tests/nima_parity.rs checks the network, head and input pipeline against timm 1.0.31 +
//! torchvision with deterministic pseudo-random weights that both sides generate (fixtures
//! from tools/eval_parity_nima/make_fixtures.py).

pub(crate) mod block17;
pub(crate) mod block35;
pub(crate) mod block8;
pub mod error;
pub mod head;
pub(crate) mod layers;
pub(crate) mod mixed_5b;
pub(crate) mod mixed_6a;
pub(crate) mod mixed_7a;
pub(crate) mod model;
pub mod preprocess;
pub(crate) mod stem;

use std::path::Path;

use burn::tensor::{Device, Tensor, TensorData};
use gb_core::RgbImage;

pub use error::NimaError;
pub use head::{mean_score, NUM_BINS};
pub use model::FEATURE_DIM;
pub use preprocess::preprocess;

use crate::fid::safetensors_f32::F32Tensors;
use head::NimaHead;
use layers::{FnSource, Loader, SafetensorsSource, TensorSource};
use model::InceptionResNetV2;

/// The input side pyiqa uses (`default_cfg['input_size']` of `inception_resnet_v2`).
pub const INPUT_SIZE: usize = 299;
/// The smallest input side the backbone accepts (its last reduction needs 3x3 left).
pub const MIN_INPUT_SIZE: usize = 75;
/// Conventional file name of the NIMA weights in a weights folder.
pub const WEIGHTS_FILE: &str = "nima_inception_resnet_v2_ava.safetensors";

/// The outputs of one batch through the network.
#[derive(Debug, Clone)]
pub struct NimaOutput {
    /// Pooled backbone features `[N, 1536]`.
    pub features: Tensor<2>,
    /// Head logits `[N, 10]`.
    pub logits: Tensor<2>,
    /// Score distributions `[N, 10]` (softmax of the logits).
    pub distribution: Tensor<2>,
}

/// The NIMA assessment of one image.
#[derive(Debug, Clone, PartialEq)]
pub struct NimaPrediction {
    /// Probability of each rating 1..=10.
    pub distribution: [f32; NUM_BINS],
    /// The mean rating, `sum_i i p_i` (the NIMA score).
    pub mean: f64,
}

/// The NIMA network (inference only) and its input size.
#[derive(Debug, Clone)]
pub struct Nima {
    backbone: InceptionResNetV2,
    head: NimaHead,
    input_size: usize,
    device: Device,
}

impl Nima {
    /// Loads pyiqa NIMA weights saved as safetensors (see the module docs) onto `device`.
    pub fn load(path: &Path, device: &Device) -> Result<Self, NimaError> {
        let tensors = F32Tensors::read(path).map_err(NimaError::from_reader)?;
        Self::from_source(&SafetensorsSource::new(tensors, path), device)
    }

    /// Loads weights from safetensors bytes; `path` only names them in errors.
    pub fn from_safetensors_bytes(
        bytes: &[u8],
        path: &Path,
        device: &Device,
    ) -> Result<Self, NimaError> {
        let tensors = F32Tensors::parse(bytes, path).map_err(NimaError::from_reader)?;
        Self::from_source(&SafetensorsSource::new(tensors, path), device)
    }

    /// Builds the network from a closure that returns the row-major values of each tensor,
    /// asked for by its pyiqa name (`base_model.conv2d_1a.conv.weight`, ...,
    /// `classifier.2.bias`) and shape, or `None` when it has none; `label` names the source
    /// in errors. Every tensor is asked for exactly once, in timm's state-dict order.
    pub fn from_fn(
        f: impl FnMut(&str, &[usize]) -> Option<Vec<f32>>,
        label: &str,
        device: &Device,
    ) -> Result<Self, NimaError> {
        Self::from_source(&FnSource::new(f, label), device)
    }

    fn from_source(source: &dyn TensorSource, device: &Device) -> Result<Self, NimaError> {
        let root = Loader::new(source, device);
        Ok(Self {
            backbone: InceptionResNetV2::load(&root.sub("base_model"))?,
            head: NimaHead::load(&root)?,
            input_size: INPUT_SIZE,
            device: device.clone(),
        })
    }

    /// Uses `size x size` network inputs instead of pyiqa's 299 (for tests and quick runs;
    /// scores then differ from pyiqa's). At least [`MIN_INPUT_SIZE`].
    pub fn with_input_size(mut self, size: usize) -> Result<Self, NimaError> {
        if size < MIN_INPUT_SIZE {
            return Err(NimaError::InputTooSmall(size));
        }
        self.input_size = size;
        Ok(self)
    }

    /// The network input side.
    pub fn input_size(&self) -> usize {
        self.input_size
    }

    /// The device the weights live on.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// Runs a normalised batch `[N, 3, H, W]` (`H, W >= 75`; see [`preprocess()`]).
    pub fn forward(&self, x: Tensor<4>) -> NimaOutput {
        let features = self.backbone.forward_pooled(x);
        let logits = self.head.logits(features.clone());
        let distribution = NimaHead::distribution(logits.clone());
        NimaOutput {
            features,
            logits,
            distribution,
        }
    }

    /// The score distribution and mean of each image (resized and cropped as pyiqa does).
    pub fn predict_batch(&self, images: &[RgbImage]) -> Result<Vec<NimaPrediction>, NimaError> {
        if images.is_empty() {
            return Ok(Vec::new());
        }
        let s = self.input_size;
        let mut input = Vec::with_capacity(images.len() * 3 * s * s);
        for im in images {
            input.extend(preprocess(im, s)?);
        }
        let x = Tensor::<4>::from_data(
            TensorData::new(input, [images.len(), 3, s, s]),
            &self.device,
        );
        let dist = self
            .forward(x)
            .distribution
            .into_data()
            .try_to_vec::<f32>()
            .map_err(|_| NimaError::NonFinite("distribution (not f32)"))?;
        dist.chunks_exact(NUM_BINS)
            .map(|p| {
                if p.iter().any(|v| !v.is_finite()) {
                    return Err(NimaError::NonFinite("distribution"));
                }
                let mut distribution = [0.0f32; NUM_BINS];
                distribution.copy_from_slice(p);
                Ok(NimaPrediction {
                    distribution,
                    mean: mean_score(p),
                })
            })
            .collect()
    }

    /// The score distribution and mean of one image.
    pub fn predict(&self, image: &RgbImage) -> Result<NimaPrediction, NimaError> {
        self.predict_batch(std::slice::from_ref(image))?
            .pop()
            .ok_or(NimaError::NonFinite("distribution (empty output)"))
    }
}

/// The NIMA score (mean rating in [1, 10], higher is better) of one image.
pub fn nima_score(model: &Nima, image: &RgbImage) -> Result<f64, NimaError> {
    Ok(model.predict(image)?.mean)
}
