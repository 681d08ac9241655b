//! One distillation step on a rendered view: compose, crop, resize, encode with autodiff,
//! then the latent step. `backward()` on the returned loss carries the guidance gradient
//! through the encoder and the resize back to the render.

use burn::tensor::Tensor;

use super::conditioning::ViewConditioning;
use super::eps::{InpaintEpsPredictor, LatentEncoder};
use super::error::DistillError;
use super::prior_input::{compose, crop_resize, PriorInputMode};
use super::step::{DistillOutput, LatentTarget, PromptEmbeddings, ScoreDistiller};

/// The models a view step needs.
pub struct ViewStepModels<'a> {
    /// The inpainting U-Net (or any eps-predictor).
    pub unet: &'a dyn InpaintEpsPredictor,
    /// The VAE encoder (or any differentiable latent encoder).
    pub encoder: &'a dyn LatentEncoder,
}

/// The prior input image of a render: composed per `mode`, cropped to the mask's box and
/// resized to the prior's resolution; values in `[0, 1]`, graph kept.
pub fn prior_image(
    render: Tensor<4>,
    view: &ViewConditioning,
    view_index: usize,
    mode: PriorInputMode,
) -> Result<Tensor<4>, DistillError> {
    if render.dims() != view.ground_truth.dims() {
        return Err(DistillError::Shape {
            tensor: "render",
            actual: render.dims().to_vec(),
            expected: format!("the view's image shape {:?}", view.ground_truth.dims()),
        });
    }
    let full = compose(
        render,
        Some(&view.ground_truth),
        &view.mask_full,
        mode,
        view_index,
    )?;
    Ok(crop_resize(full, &view.bbox, view.resolution, false))
}

/// One step of `distiller` on `render` (`[1, 3, H, W]` in `[0, 1]`, autodiff) of a view
/// whose conditioning is cached.
pub fn distill_view(
    distiller: &mut ScoreDistiller,
    models: &ViewStepModels<'_>,
    render: Tensor<4>,
    view: &ViewConditioning,
    view_index: usize,
    mode: PriorInputMode,
    prompts: &PromptEmbeddings,
) -> Result<DistillOutput, DistillError> {
    let image = prior_image(render, view, view_index, mode)?;
    let latents = models
        .encoder
        .encode(image.mul_scalar(2.0).sub_scalar(1.0))?;
    distiller.step(
        models.unet,
        LatentTarget {
            latents,
            mask_latent: view.mask_latent.clone(),
            masked_image_latents: view.masked_image_latents.clone(),
            prompts,
        },
    )
}
