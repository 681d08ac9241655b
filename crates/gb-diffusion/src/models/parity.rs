//! The `vae-encode`, `vae-decode` and `unet` arms of `cargo xtask parity`: read the named
//! inputs of a safetensors file (fixture layout), check them against the model config, and
//! run the component.

use std::path::{Path, PathBuf};

use burn::tensor::{Device, Tensor, TensorData};

use super::{AutoencoderKL, UNet2DConditionModel};
use crate::config::{AutoencoderKLConfig, UNet2DConditionConfig};
use crate::tensor_file::{read_f32, TensorFileError};

/// Error of a parity run on given inputs.
#[derive(Debug, thiserror::Error)]
pub enum ParityInputError {
    /// The inputs file or a tensor in it could not be read.
    #[error(transparent)]
    File(#[from] TensorFileError),
    /// An input tensor does not fit the model.
    #[error("inputs {path}: tensor `{name}`: {message}")]
    Input {
        /// The file.
        path: PathBuf,
        /// The tensor name.
        name: String,
        /// What is wrong.
        message: String,
    },
}

fn bad(path: &Path, name: &str, message: String) -> ParityInputError {
    ParityInputError::Input {
        path: path.to_path_buf(),
        name: name.into(),
        message,
    }
}

/// Reads f32 tensor `name` of rank `D` from `path` onto `device`.
pub fn read_tensor<const D: usize>(
    path: &Path,
    name: &str,
    device: &Device,
) -> Result<Tensor<D>, ParityInputError> {
    let (values, shape) = read_f32(path, name)?;
    if shape.len() != D {
        return Err(bad(
            path,
            name,
            format!("shape {shape:?}, expected rank {D}"),
        ));
    }
    Ok(Tensor::from_data(TensorData::new(values, shape), device))
}

fn check_image_sides(
    path: &Path,
    name: &str,
    dims: [usize; 4],
    channels: usize,
    factor: usize,
) -> Result<(), ParityInputError> {
    let [b, c, h, w] = dims;
    if b == 0 || c != channels || h == 0 || w == 0 || h % factor != 0 || w % factor != 0 {
        return Err(bad(
            path,
            name,
            format!("shape [{b}, {c}, {h}, {w}]: need [b, {channels}, h, w] with h and w positive multiples of {factor}"),
        ));
    }
    Ok(())
}

/// `vae-encode`: `image` `[b, 3, h, w]` in `[-1, 1]` to the latent `mean` (unscaled).
pub fn vae_encode(
    vae: &AutoencoderKL,
    cfg: &AutoencoderKLConfig,
    inputs: &Path,
    device: &Device,
) -> Result<Tensor<4>, ParityInputError> {
    let image: Tensor<4> = read_tensor(inputs, "image", device)?;
    check_image_sides(
        inputs,
        "image",
        image.dims(),
        cfg.in_channels,
        cfg.scale_factor(),
    )?;
    Ok(vae.encode_mean(image))
}

/// `vae-decode`: unscaled `latents` `[b, latent_channels, h, w]` to `image`.
pub fn vae_decode(
    vae: &AutoencoderKL,
    cfg: &AutoencoderKLConfig,
    inputs: &Path,
    device: &Device,
) -> Result<Tensor<4>, ParityInputError> {
    let latents: Tensor<4> = read_tensor(inputs, "latents", device)?;
    check_image_sides(inputs, "latents", latents.dims(), cfg.latent_channels, 1)?;
    Ok(vae.decode(latents))
}

/// `unet`: `sample` `[b, in_channels, h, w]`, `timestep` (one value or one per batch
/// item) and `encoder_hidden_states` `[b, m, cross_attention_dim]` to `out`.
pub fn unet(
    unet: &UNet2DConditionModel,
    cfg: &UNet2DConditionConfig,
    inputs: &Path,
    device: &Device,
) -> Result<Tensor<4>, ParityInputError> {
    let sample: Tensor<4> = read_tensor(inputs, "sample", device)?;
    let factor = 1 << (cfg.block_out_channels.len() - 1);
    check_image_sides(inputs, "sample", sample.dims(), cfg.in_channels, factor)?;
    let b = sample.dims()[0];
    let (t, _) = read_f32(inputs, "timestep")?;
    if t.len() != 1 && t.len() != b {
        return Err(bad(
            inputs,
            "timestep",
            format!("{} values for batch {b}", t.len()),
        ));
    }
    let ehs: Tensor<3> = read_tensor(inputs, "encoder_hidden_states", device)?;
    let [eb, m, ed] = ehs.dims();
    if eb != b || m == 0 || ed != cfg.cross_attention_dim {
        return Err(bad(
            inputs,
            "encoder_hidden_states",
            format!(
                "shape [{eb}, {m}, {ed}], need [{b}, m, {}]",
                cfg.cross_attention_dim
            ),
        ));
    }
    Ok(unet.forward(sample, &t, ehs))
}
