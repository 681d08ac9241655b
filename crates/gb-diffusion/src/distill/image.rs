//! Score distillation straight into the masked pixels of one image: the 2D playground of
//! `distill-image`. Each [`ImageDistillation::step`] is one distillation step through the
//! prior on the image's mask box (the render pasted on the input outside the mask,
//! [`PriorInputMode::PasteOnGroundTruth`]), then one step of Burn's Adam on the pixels,
//! clamped to `[0, 1]`. Pixels outside the mask get no gradient, so they keep their values.

use burn::optim::{Adam, AdamConfig, AdamState, Optimizer};
use burn::tensor::{Tensor, TensorData};
use gb_core::RgbImage;

use super::{
    distill_view, DistillError, DistillSettings, MaskBox, PriorInputMode, PromptCache,
    PromptEmbeddings, ScoreDistiller, SdPrior, StepDiagnostics, ViewConditioning, ViewStepModels,
};

/// Adam's epsilon on the pixels (PyTorch's default; Burn's is 1e-5).
const ADAM_EPSILON: f32 = 1e-8;

/// What an image distillation needs besides the prior, the image and the prompts.
#[derive(Debug, Clone)]
pub struct ImageDistillConfig {
    /// The guidance, its timesteps, weighting and clamp.
    pub settings: DistillSettings,
    /// Adam's learning rate on the pixels (values in `[0, 1]`).
    pub lr: f64,
    /// Seed of the timesteps and noise.
    pub seed: u64,
    /// The prior's input resolution; `None` is the prior's native one.
    pub resolution: Option<usize>,
}

/// One image under distillation: its pixels, the optimiser's state and the cached
/// conditioning of its mask and prompts.
pub struct ImageDistillation<'a> {
    prior: &'a SdPrior,
    distiller: ScoreDistiller,
    view: ViewConditioning,
    prompts: PromptEmbeddings,
    pixels: Tensor<4>,
    adam: Adam,
    state: Option<AdamState<4>>,
    lr: f64,
    resolution: usize,
    width: usize,
    height: usize,
}

impl<'a> ImageDistillation<'a> {
    /// Prepares `image` for distillation inside `mask` (one value per pixel, row-major, 1 =
    /// optimised) toward `prompt`, away from `negative` (CSD, BSD), on the prior's device.
    /// Errors on a mask of another size or an empty one, and on bad settings.
    pub fn new(
        prior: &'a SdPrior,
        image: &RgbImage,
        mask: &[f32],
        prompt: &str,
        negative: &str,
        cfg: &ImageDistillConfig,
    ) -> Result<Self, DistillError> {
        let (width, height) = (image.width, image.height);
        if mask.len() != width * height {
            return Err(DistillError::Shape {
                tensor: "mask",
                actual: vec![mask.len()],
                expected: format!(
                    "{} values, one per pixel of the {width}x{height} image",
                    width * height
                ),
            });
        }
        if !(cfg.lr.is_finite() && cfg.lr > 0.0) {
            return Err(DistillError::Config {
                field: "lr",
                message: format!("must be a positive number, got {}", cfg.lr),
            });
        }
        let device = prior.device.clone();
        let resolution = cfg.resolution.unwrap_or(prior.resolution);
        let distiller = ScoreDistiller::new(&cfg.settings, prior.alphas.clone(), cfg.seed)?;
        let pixels = image_tensor(image, &device);
        let mask = Tensor::<4>::from_data(
            TensorData::new(mask.to_vec(), [1, 1, height, width]),
            &device,
        );
        let view = ViewConditioning::new(0, &prior.encoder, pixels.clone(), mask, resolution)?;
        let prompts =
            PromptCache::new().for_guidance(&prior.text, distiller.guidance(), prompt, negative)?;
        Ok(Self {
            prior,
            distiller,
            view,
            prompts,
            pixels,
            adam: AdamConfig::new().with_epsilon(ADAM_EPSILON).build(),
            state: None,
            lr: cfg.lr,
            resolution,
            width,
            height,
        })
    }

    /// One step: the distillation gradient on the pixels, then Adam, clamped to `[0, 1]`.
    pub fn step(&mut self) -> Result<StepDiagnostics, DistillError> {
        let render = self.pixels.clone().autodiff().require_grad();
        let models = ViewStepModels {
            unet: &self.prior.unet,
            encoder: &self.prior.encoder,
        };
        let out = distill_view(
            &mut self.distiller,
            &models,
            render.clone(),
            &self.view,
            0,
            PriorInputMode::PasteOnGroundTruth,
            &self.prompts,
        )?;
        let grads = out.loss.backward();
        let grad = render.grad(&grads).ok_or_else(|| {
            DistillError::Readback("pixel gradient", "no gradient reached the pixels".into())
        })?;
        let (pixels, state) = self
            .adam
            .step(self.lr, self.pixels.clone(), grad, self.state.take());
        self.pixels = pixels.clamp(0.0, 1.0);
        self.state = state;
        Ok(out.diagnostics)
    }

    /// The pixels now, as an image.
    pub fn image(&self) -> Result<RgbImage, DistillError> {
        let data = self
            .pixels
            .clone()
            .squeeze_dim::<3>(0)
            .permute([1, 2, 0])
            .into_data()
            .try_into_vec_as::<f32>()
            .map_err(|e| DistillError::Readback("pixels", format!("{e:?}")))?;
        Ok(RgbImage {
            width: self.width,
            height: self.height,
            data,
        })
    }

    /// The mask's box in the image, which the prior sees.
    pub fn mask_box(&self) -> &MaskBox {
        &self.view.bbox
    }

    /// The prior's input resolution.
    pub fn resolution(&self) -> usize {
        self.resolution
    }

    /// The guidance's name (`sds`, `csd`, `bsd`).
    pub fn guidance_name(&self) -> &'static str {
        self.distiller.guidance().name()
    }
}

/// `image` as a `[1, 3, H, W]` tensor on `device`.
fn image_tensor(image: &RgbImage, device: &burn::tensor::Device) -> Tensor<4> {
    Tensor::<3>::from_data(
        TensorData::new(image.data.clone(), [image.height, image.width, 3]),
        device,
    )
    .permute([2, 0, 1])
    .unsqueeze()
}
