//! Building blocks shared by every InceptionResNetV2 block: where tensors come from
//! ([`TensorSource`], [`Loader`]), timm's `ConvNormAct` ([`ConvBn`]) and the residual
//! blocks' plain convolution with bias ([`Conv`]).
//!
//! Tensor names follow the pyiqa NIMA state dict: the backbone's timm keys under
//! `base_model.` (`base_model.repeat.3.branch1.0.conv.weight`, ...) and the head under
//! `classifier.2.`; a [`Loader`] carries the module path so that each block's loading code is a
//! short table of `(timm name, in, out, kernel)` rows.

use std::cell::RefCell;
use std::path::{Path, PathBuf};

use burn::tensor::activation::relu;
use burn::tensor::module::{avg_pool2d, conv2d, max_pool2d};
use burn::tensor::ops::{AvgPoolOptions, ConvOptions, MaxPoolOptions};
use burn::tensor::{Device, Tensor, TensorData};

use super::error::NimaError;
use crate::fid::safetensors_f32::F32Tensors;

/// timm builds this model with `BatchNorm2d(eps=1e-3)` (TensorFlow's value).
pub const BN_EPS: f32 = 1e-3;

/// Supplies the f32 values of a tensor, by its pyiqa name and expected shape.
pub(crate) trait TensorSource {
    /// The row-major values of `name`, which must have `shape`.
    fn get(&self, name: &str, shape: &[usize]) -> Result<Vec<f32>, NimaError>;
}

/// Tensors of a safetensors file, whatever prefix the file puts before the timm keys.
pub(crate) struct SafetensorsSource {
    tensors: F32Tensors,
    /// The file's prefix for the backbone keys (`base_model.`, `net.base_model.`, or empty).
    backbone_prefix: String,
    /// The file's prefix for `classifier.2.*`.
    head_prefix: String,
    path: PathBuf,
}

/// The timm key whose position fixes the file's prefix.
const ANCHOR: &str = "conv2d_1a.conv.weight";

impl SafetensorsSource {
    /// Indexes `tensors`, found in `path`. The backbone prefix is whatever precedes
    /// `conv2d_1a.conv.weight` in the file (pyiqa: `base_model.`; a bare timm state dict:
    /// nothing); the head prefix is that prefix without its trailing `base_model.`.
    pub(crate) fn new(tensors: F32Tensors, path: &Path) -> Self {
        let mut candidates: Vec<&str> = tensors
            .names()
            .filter_map(|n| n.strip_suffix(ANCHOR))
            .filter(|p| p.is_empty() || p.ends_with('.'))
            .collect();
        candidates.sort_by_key(|p| p.len());
        let backbone_prefix = candidates
            .first()
            .map(|p| p.to_string())
            .unwrap_or_else(|| "base_model.".to_string());
        let head_prefix = backbone_prefix
            .strip_suffix("base_model.")
            .unwrap_or("")
            .to_string();
        Self {
            tensors,
            backbone_prefix,
            head_prefix,
            path: path.to_path_buf(),
        }
    }

    fn file_key(&self, name: &str) -> String {
        match name.strip_prefix("base_model.") {
            Some(rest) => format!("{}{rest}", self.backbone_prefix),
            None => format!("{}{name}", self.head_prefix),
        }
    }
}

impl TensorSource for SafetensorsSource {
    fn get(&self, name: &str, shape: &[usize]) -> Result<Vec<f32>, NimaError> {
        let key = self.file_key(name);
        self.tensors
            .get(&key, shape)
            .map_err(NimaError::from_reader)
            .map_err(|e| with_path(e, &self.path))
    }
}

/// Tensors from a closure `(name, shape) -> values` (in-memory or generated weights).
pub(crate) struct FnSource<F> {
    f: RefCell<F>,
    label: PathBuf,
}

impl<F: FnMut(&str, &[usize]) -> Option<Vec<f32>>> FnSource<F> {
    /// Wraps `f`; `label` stands for the file in error messages.
    pub(crate) fn new(f: F, label: &str) -> Self {
        Self {
            f: RefCell::new(f),
            label: PathBuf::from(label),
        }
    }
}

impl<F: FnMut(&str, &[usize]) -> Option<Vec<f32>>> TensorSource for FnSource<F> {
    fn get(&self, name: &str, shape: &[usize]) -> Result<Vec<f32>, NimaError> {
        let values =
            (self.f.borrow_mut())(name, shape).ok_or_else(|| NimaError::MissingTensor {
                path: self.label.clone(),
                tensor: name.to_string(),
            })?;
        let expected: usize = shape.iter().product();
        if values.len() != expected {
            return Err(NimaError::BadTensor {
                path: self.label.clone(),
                tensor: name.to_string(),
                got: vec![values.len()],
                dtype: "F32".into(),
                expected: shape.to_vec(),
            });
        }
        Ok(values)
    }
}

/// Fills in the file of an error raised by the tensor reader.
fn with_path(err: NimaError, path: &Path) -> NimaError {
    match err {
        NimaError::MissingTensor { tensor, .. } => NimaError::MissingTensor {
            path: path.to_path_buf(),
            tensor,
        },
        NimaError::BadTensor {
            tensor,
            got,
            dtype,
            expected,
            ..
        } => NimaError::BadTensor {
            path: path.to_path_buf(),
            tensor,
            got,
            dtype,
            expected,
        },
        other => other,
    }
}

/// Kernel, stride and padding of one convolution.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ConvSpec {
    /// `[kh, kw]`.
    pub kernel: [usize; 2],
    /// Stride (both axes).
    pub stride: usize,
    /// `[ph, pw]`.
    pub padding: [usize; 2],
}

/// 1x1.
pub(crate) const K1: ConvSpec = ConvSpec {
    kernel: [1, 1],
    stride: 1,
    padding: [0, 0],
};
/// 3x3, no padding.
pub(crate) const K3: ConvSpec = ConvSpec {
    kernel: [3, 3],
    stride: 1,
    padding: [0, 0],
};
/// 3x3, padding 1.
pub(crate) const K3P1: ConvSpec = ConvSpec {
    kernel: [3, 3],
    stride: 1,
    padding: [1, 1],
};
/// 3x3, stride 2, no padding.
pub(crate) const K3S2: ConvSpec = ConvSpec {
    kernel: [3, 3],
    stride: 2,
    padding: [0, 0],
};

/// A module path in the weights and the device to load onto.
pub(crate) struct Loader<'a> {
    source: &'a dyn TensorSource,
    prefix: String,
    device: &'a Device,
}

impl<'a> Loader<'a> {
    /// A loader at the root of the pyiqa state dict.
    pub(crate) fn new(source: &'a dyn TensorSource, device: &'a Device) -> Self {
        Self {
            source,
            prefix: String::new(),
            device,
        }
    }

    /// The loader of child module `name`.
    pub(crate) fn sub(&self, name: &str) -> Loader<'a> {
        Loader {
            source: self.source,
            prefix: format!("{}{name}.", self.prefix),
            device: self.device,
        }
    }

    /// The values of tensor `field` of this module.
    pub(crate) fn values(&self, field: &str, shape: &[usize]) -> Result<Vec<f32>, NimaError> {
        self.source.get(&format!("{}{field}", self.prefix), shape)
    }

    /// The device weights go to.
    pub(crate) fn device(&self) -> &'a Device {
        self.device
    }

    /// timm's `ConvNormAct` `name`: bias-free convolution `{name}.conv.weight`, batch norm
    /// `{name}.bn.{weight,bias,running_mean,running_var}` (eps [`BN_EPS`]) and ReLU.
    pub(crate) fn conv_bn(
        &self,
        name: &str,
        cin: usize,
        cout: usize,
        spec: ConvSpec,
    ) -> Result<ConvBn, NimaError> {
        let l = self.sub(name);
        let [kh, kw] = spec.kernel;
        let w = l.values("conv.weight", &[cout, cin, kh, kw])?;
        let gamma = l.values("bn.weight", &[cout])?;
        let beta = l.values("bn.bias", &[cout])?;
        let mean = l.values("bn.running_mean", &[cout])?;
        let var = l.values("bn.running_var", &[cout])?;
        // Eval-mode batch norm is a per-channel affine map, `alpha = gamma / sqrt(var + eps)`,
        // `beta - mean * alpha` (as PyTorch's CPU kernel computes it), folded into the
        // convolution's weights and bias.
        let alpha: Vec<f32> = gamma
            .iter()
            .zip(&var)
            .map(|(g, v)| g * (1.0 / (v + BN_EPS).sqrt()))
            .collect();
        let bias: Vec<f32> = beta
            .iter()
            .zip(mean.iter().zip(&alpha))
            .map(|(b, (m, a))| b - m * a)
            .collect();
        Ok(ConvBn(Conv::from_values(
            scale_rows(w, &alpha),
            bias,
            [cout, cin, kh, kw],
            spec,
            self.device,
        )))
    }

    /// A plain convolution `{name}.weight` / `{name}.bias` whose output is multiplied by
    /// `scale` (the residual blocks' branch scale, folded into weights and bias).
    pub(crate) fn conv(
        &self,
        name: &str,
        cin: usize,
        cout: usize,
        spec: ConvSpec,
        scale: f32,
    ) -> Result<Conv, NimaError> {
        let l = self.sub(name);
        let [kh, kw] = spec.kernel;
        let w = l.values("weight", &[cout, cin, kh, kw])?;
        let b = l.values("bias", &[cout])?;
        let w = if scale == 1.0 {
            w
        } else {
            w.into_iter().map(|v| v * scale).collect()
        };
        let b = if scale == 1.0 {
            b
        } else {
            b.into_iter().map(|v| v * scale).collect()
        };
        Ok(Conv::from_values(
            w,
            b,
            [cout, cin, kh, kw],
            spec,
            self.device,
        ))
    }
}

/// Multiplies output channel `o` of a `[cout, ...]` weight by `alpha[o]`.
fn scale_rows(mut w: Vec<f32>, alpha: &[f32]) -> Vec<f32> {
    let per = w.len() / alpha.len().max(1);
    for (row, a) in w.chunks_mut(per.max(1)).zip(alpha) {
        row.iter_mut().for_each(|v| *v *= a);
    }
    w
}

/// A convolution with bias.
#[derive(Debug, Clone)]
pub(crate) struct Conv {
    weight: Tensor<4>,
    bias: Tensor<1>,
    options: ConvOptions<2>,
}

impl Conv {
    fn from_values(
        w: Vec<f32>,
        b: Vec<f32>,
        shape: [usize; 4],
        spec: ConvSpec,
        device: &Device,
    ) -> Self {
        let cout = shape[0];
        Self {
            weight: Tensor::from_data(TensorData::new(w, shape), device),
            bias: Tensor::from_data(TensorData::new(b, [cout]), device),
            options: ConvOptions::new([spec.stride, spec.stride], spec.padding, [1, 1], 1),
        }
    }

    /// `conv(x) + bias`.
    pub(crate) fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        conv2d(
            x,
            self.weight.clone(),
            Some(self.bias.clone()),
            self.options.clone(),
        )
    }
}

/// timm's `ConvNormAct`: convolution, eval-mode batch norm (folded) and ReLU.
#[derive(Debug, Clone)]
pub(crate) struct ConvBn(Conv);

impl ConvBn {
    /// `relu(bn(conv(x)))`.
    pub(crate) fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        relu(self.0.forward(x))
    }
}

/// A chain of [`ConvBn`] (an `nn.Sequential` branch).
#[derive(Debug, Clone)]
pub(crate) struct Chain(pub Vec<ConvBn>);

impl Chain {
    /// Loads `{name}.0`, `{name}.1`, ... with `(in, out, spec)` per layer.
    pub(crate) fn load(
        l: &Loader,
        name: &str,
        layers: &[(usize, usize, ConvSpec)],
    ) -> Result<Self, NimaError> {
        let l = l.sub(name);
        layers
            .iter()
            .enumerate()
            .map(|(i, &(cin, cout, spec))| l.conv_bn(&i.to_string(), cin, cout, spec))
            .collect::<Result<Vec<_>, _>>()
            .map(Chain)
    }

    /// The layers one after the other.
    pub(crate) fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        self.0.iter().fold(x, |x, layer| layer.forward(x))
    }
}

/// `nn.MaxPool2d(3, stride=2)`: no padding, floor mode.
pub(crate) fn max_pool_3x3_s2(x: Tensor<4>) -> Tensor<4> {
    max_pool2d(x, MaxPoolOptions::new([3, 3]).with_stride([2, 2]))
}

/// `nn.AvgPool2d(3, stride=1, padding=1, count_include_pad=False)`.
pub(crate) fn avg_pool_3x3_s1(x: Tensor<4>) -> Tensor<4> {
    avg_pool2d(
        x,
        AvgPoolOptions::new([3, 3])
            .with_stride([1, 1])
            .with_padding([1, 1])
            .with_count_include_pad(false),
    )
}
