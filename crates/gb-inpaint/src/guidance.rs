//! One guidance term: a prior input image (RGB crop or normal map, `[1, 3, R, R]` in
//! `[0, 1]`, with its autodiff graph) becomes the loss
//! `lambda * s(t) * (z * g.detach()).sum()`, `z = encode(2 * image - 1)`, whose gradient
//! with respect to the image is exactly `lambda * s(t) * J_enc^T g` (see
//! [`crate::method`] for `g`, `s(t)` and the scale of lambda). The U-Net call inside
//! gb-diffusion's [`ScoreDistiller`] runs without a graph.

use burn::tensor::Tensor;
use gb_diffusion::distill::{
    Branch, DistillSettings, InpaintEpsPredictor, LatentEncoder, LatentTarget, OracleEps,
    PromptEmbeddings, ScoreDistiller, StepDiagnostics,
};
use serde::Serialize;

use crate::error::InpaintError;
use crate::prior::SdPrior;

/// Which image a term guides.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Modality {
    /// The RGB render (appearance prompt).
    Rgb,
    /// The normal map (geometry prompt).
    Normal,
}

impl Modality {
    /// A small integer that separates the seeds of the two modalities.
    pub fn salt(self) -> u64 {
        match self {
            Modality::Rgb => 1,
            Modality::Normal => 2,
        }
    }
}

/// The conditioning of one term: the latent mask and the masked-image latents.
#[derive(Debug, Clone)]
pub struct TermConditioning<'a> {
    /// Mask at latent resolution `[1, 1, h, w]`.
    pub mask_latent: &'a Tensor<4>,
    /// Latents of the masked image `[1, C, h, w]`.
    pub masked_image_latents: &'a Tensor<4>,
    /// Text embeddings of the term's prompts.
    pub prompts: &'a PromptEmbeddings,
    /// Oracle guidance ([`crate::oracle`]): the true latents `[1, C, h, w]` and the branches
    /// they answer instead of the U-Net.
    pub oracle: Option<(Tensor<4>, &'a [Branch])>,
}

/// The result of one term.
#[derive(Debug)]
pub struct TermOutput {
    /// `lambda * s(t) * (z * g.detach()).sum()`, with the graph to the image.
    pub loss: Tensor<1>,
    /// The latent gradient `g` before `lambda * s(t)` (no graph).
    pub gradient: Tensor<4>,
    /// `lambda * s(t)`.
    pub scale: f64,
    /// The distiller's diagnostics (timestep, weight, U-Net calls, gradient norm).
    pub diagnostics: StepDiagnostics,
}

/// A seeded distiller for one term: its timestep and noise depend only on `seed`, and the
/// annealed schedule sees `iteration` (the number of earlier terms of this modality), so a
/// resumed run draws the same timesteps.
pub fn distiller_for(
    settings: &DistillSettings,
    prior: &SdPrior,
    seed: u64,
    iteration: usize,
) -> Result<ScoreDistiller, InpaintError> {
    let mut d = ScoreDistiller::new(settings, prior.alphas.clone(), seed)?;
    d.set_iteration(iteration);
    Ok(d)
}

/// Computes one term on `image`. `at = Some((timestep_index, noise))` fixes the timestep
/// and noise (tests); otherwise the distiller samples them.
#[allow(clippy::too_many_arguments)]
pub fn guidance_term(
    distiller: &mut ScoreDistiller,
    prior: &SdPrior,
    image: Tensor<4>,
    cond: &TermConditioning<'_>,
    lambda: f64,
    reference_chain_rule: bool,
    at: Option<(usize, Tensor<4>)>,
) -> Result<TermOutput, InpaintError> {
    let latents = prior
        .encoder
        .encode(image.mul_scalar(2.0).sub_scalar(1.0))?;
    let target = LatentTarget {
        latents,
        mask_latent: cond.mask_latent.clone(),
        masked_image_latents: cond.masked_image_latents.clone(),
        prompts: cond.prompts,
    };
    let branches = distiller.guidance().branches();
    let oracle = cond.oracle.as_ref().map(|(clean, answered)| OracleEps {
        inner: &prior.unet,
        clean: clean.clone(),
        alphas: &prior.alphas,
        branches,
        oracle_branches: answered,
    });
    let unet: &dyn InpaintEpsPredictor = match &oracle {
        Some(o) => o,
        None => &prior.unet,
    };
    let out = match at {
        Some((timestep, noise)) => distiller.step_with(unet, target, timestep, noise)?,
        None => distiller.step(unet, target)?,
    };
    let chain = if reference_chain_rule {
        out.diagnostics.alpha_bar.sqrt()
    } else {
        1.0
    };
    let scale = lambda * chain;
    Ok(TermOutput {
        loss: out.loss.mul_scalar(scale),
        gradient: out.gradient,
        scale,
        diagnostics: out.diagnostics,
    })
}
