//! The two model interfaces score distillation needs, so that it does not depend on a
//! particular U-Net or VAE implementation: an inpainting eps-predictor and a differentiable
//! latent encoder. Adapters to the crate's Stable Diffusion modules implement them; tests use
//! closed-form mocks.

use burn::tensor::Tensor;

use super::error::DistillError;

/// The inputs of one batched call of an inpainting noise predictor. All tensors share the
/// batch size `N` (rows of the batch) and carry no autodiff graph.
#[derive(Debug, Clone)]
pub struct EpsBatch {
    /// Noisy latents `x_t`, `[N, C, h, w]`.
    pub noisy_latents: Tensor<4>,
    /// The diffusion timestep index shared by every row (0 ..= num_train_timesteps - 1).
    pub timestep: usize,
    /// Text embeddings, `[N, L, D]` (CLIP's last hidden state for SD).
    pub text_embeddings: Tensor<3>,
    /// The inpainting mask at latent resolution, `[N, 1, h, w]`, 1 = region to fill.
    pub mask: Tensor<4>,
    /// Latents of the masked image (image with the masked region blanked), `[N, C, h, w]`.
    pub masked_image_latents: Tensor<4>,
}

impl EpsBatch {
    /// Number of rows in the batch.
    pub fn batch_size(&self) -> usize {
        self.noisy_latents.dims()[0]
    }
}

/// An inpainting noise predictor `eps(x_t, t, y, mask, masked_latents)`, e.g. the SD 1.5
/// inpainting U-Net (which concatenates `[x_t, mask, masked_latents]` into 9 channels).
///
/// Called without an autodiff graph: implementations should run their module in `valid()`
/// mode on the inner (non-autodiff) device of the inputs.
pub trait InpaintEpsPredictor {
    /// Predicts the noise for every row of `batch`; returns `[N, C, h, w]`.
    fn predict_eps(&self, batch: EpsBatch) -> Result<Tensor<4>, DistillError>;
}

/// A differentiable image-to-latent encoder (a VAE encoder followed by the scaling factor).
///
/// `encode` must keep the autodiff graph of its input so that a gradient on the latents
/// reaches the image.
pub trait LatentEncoder {
    /// Encodes images `[B, 3, H, W]` with values in `[-1, 1]` into scaled latents
    /// `[B, C, H / f, W / f]` where `f` is [`LatentEncoder::downsample_factor`].
    fn encode(&self, image: Tensor<4>) -> Result<Tensor<4>, DistillError>;

    /// Spatial downsampling factor `f` between image and latent (8 for Stable Diffusion).
    fn downsample_factor(&self) -> usize;
}
