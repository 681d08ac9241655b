//! Conditioning caches: each prompt's text embedding and each training view's mask and
//! masked-image latent are computed once and reused every step.

use std::collections::HashMap;

use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};
use burn::tensor::Tensor;

use super::eps::LatentEncoder;
use super::error::DistillError;
use super::guidance::{Branch, Guidance};
use super::prior_input::{crop_resize, mask_bbox, MaskBox};
use super::step::PromptEmbeddings;

/// A text encoder: prompt to embedding `[1, L, D]` (CLIP's last hidden state for SD).
pub trait PromptEncoder {
    /// Encodes one prompt.
    fn encode_prompt(&self, prompt: &str) -> Result<Tensor<3>, DistillError>;
}

/// Text embeddings cached by prompt string.
#[derive(Debug, Default)]
pub struct PromptCache {
    embeddings: HashMap<String, Tensor<3>>,
}

impl PromptCache {
    /// An empty cache.
    pub fn new() -> Self {
        Self::default()
    }

    /// The embedding of `prompt`, encoding it on first use.
    pub fn embedding(
        &mut self,
        encoder: &dyn PromptEncoder,
        prompt: &str,
    ) -> Result<Tensor<3>, DistillError> {
        if let Some(e) = self.embeddings.get(prompt) {
            return Ok(e.clone());
        }
        let e = encoder.encode_prompt(prompt)?;
        self.embeddings.insert(prompt.to_string(), e.clone());
        Ok(e)
    }

    /// Number of distinct prompts encoded so far.
    pub fn len(&self) -> usize {
        self.embeddings.len()
    }

    /// True when nothing has been encoded yet.
    pub fn is_empty(&self) -> bool {
        self.embeddings.is_empty()
    }

    /// The embeddings `guidance` needs: `prompt` for the text branch, `""` for the
    /// unconditional branch and `negative` for the negative branch.
    pub fn for_guidance(
        &mut self,
        encoder: &dyn PromptEncoder,
        guidance: &dyn Guidance,
        prompt: &str,
        negative: &str,
    ) -> Result<PromptEmbeddings, DistillError> {
        let text = self.embedding(encoder, prompt)?;
        let mut out = PromptEmbeddings {
            text,
            unconditional: None,
            negative: None,
        };
        for &branch in guidance.branches() {
            match branch {
                Branch::Text => {}
                Branch::Unconditional => out.unconditional = Some(self.embedding(encoder, "")?),
                Branch::Negative => out.negative = Some(self.embedding(encoder, negative)?),
            }
        }
        Ok(out)
    }
}

/// Everything about one training view that does not change during distillation.
#[derive(Debug, Clone)]
pub struct ViewConditioning {
    /// Bounding box of the mask in the full image.
    pub bbox: MaskBox,
    /// Binary mask at full image resolution, `[1, 1, H, W]` (for pasting).
    pub mask_full: Tensor<4>,
    /// Ground-truth image at full resolution, `[1, 3, H, W]` in `[0, 1]`.
    pub ground_truth: Tensor<4>,
    /// Binary mask of the crop at latent resolution, `[1, 1, R/f, R/f]`.
    pub mask_latent: Tensor<4>,
    /// Latents of the masked crop (ground truth with the mask blanked), `[1, C, R/f, R/f]`.
    pub masked_image_latents: Tensor<4>,
    /// Prior resolution `R`.
    pub resolution: usize,
}

impl ViewConditioning {
    /// Computes a view's conditioning: the mask's bounding box; the crop of the binary mask
    /// (nearest) at prior resolution and, downsampled (nearest, as diffusers' inpainting
    /// pipeline), at latent resolution; the masked crop `gt * (mask < 0.5)` in `[-1, 1]`
    /// encoded without a graph. `ground_truth` `[1, 3, H, W]` in `[0, 1]`, `mask`
    /// `[1, 1, H, W]` with 1 = remove; both on a non-autodiff device.
    pub fn new(
        view: usize,
        encoder: &dyn LatentEncoder,
        ground_truth: Tensor<4>,
        mask: Tensor<4>,
        resolution: usize,
    ) -> Result<Self, DistillError> {
        let [_, _, h, w] = ground_truth.dims();
        if mask.dims() != [1, 1, h, w] || ground_truth.dims()[..2] != [1, 3] {
            return Err(DistillError::Shape {
                tensor: "mask / ground truth",
                actual: [mask.dims(), ground_truth.dims()].concat(),
                expected: format!("mask [1, 1, {h}, {w}] and image [1, 3, {h}, {w}]"),
            });
        }
        let f = encoder.downsample_factor();
        if resolution == 0 || !resolution.is_multiple_of(f) {
            return Err(DistillError::Config {
                field: "resolution",
                message: format!(
                    "{resolution} is not a positive multiple of the encoder's factor {f}"
                ),
            });
        }
        let host: Vec<f32> = mask
            .clone()
            .into_data()
            .try_into_vec_as::<f32>()
            .map_err(|e| DistillError::Readback("mask", format!("{e:?}")))?;
        let bbox = mask_bbox(&host, w, h, &format!("of view {view}"))?;
        let mask_full = mask.greater_equal_elem(0.5).float();
        let mask_prior = crop_resize(mask_full.clone(), &bbox, resolution, true);
        let mut options = InterpolateOptions::new(InterpolateMode::Nearest);
        options.align_corners = false;
        let latent_size = resolution / f;
        let mask_latent = interpolate(
            mask_prior.clone(),
            options.with_output_size([latent_size, latent_size]),
        );
        let gt_prior = crop_resize(ground_truth.clone(), &bbox, resolution, false);
        let keep = mask_prior.ones_like() - mask_prior;
        let masked = (gt_prior.mul_scalar(2.0).sub_scalar(1.0)) * keep.repeat_dim(1, 3);
        let masked_image_latents = encoder.encode(masked)?.inner();
        Ok(Self {
            bbox,
            mask_full,
            ground_truth,
            mask_latent,
            masked_image_latents,
            resolution,
        })
    }
}

/// Per-view conditioning, computed once per training view.
#[derive(Debug, Default)]
pub struct ViewCache {
    views: HashMap<usize, ViewConditioning>,
}

impl ViewCache {
    /// An empty cache.
    pub fn new() -> Self {
        Self::default()
    }

    /// Computes and stores view `view`'s conditioning unless it is cached already.
    pub fn prepare_view(
        &mut self,
        view: usize,
        encoder: &dyn LatentEncoder,
        ground_truth: Tensor<4>,
        mask: Tensor<4>,
        resolution: usize,
    ) -> Result<&ViewConditioning, DistillError> {
        if let std::collections::hash_map::Entry::Vacant(slot) = self.views.entry(view) {
            slot.insert(ViewConditioning::new(
                view,
                encoder,
                ground_truth,
                mask,
                resolution,
            )?);
        }
        self.get(view)
    }

    /// The cached conditioning of `view`.
    pub fn get(&self, view: usize) -> Result<&ViewConditioning, DistillError> {
        self.views.get(&view).ok_or(DistillError::UnknownView(view))
    }

    /// Number of cached views.
    pub fn len(&self) -> usize {
        self.views.len()
    }

    /// True when no view is cached.
    pub fn is_empty(&self) -> bool {
        self.views.is_empty()
    }
}
