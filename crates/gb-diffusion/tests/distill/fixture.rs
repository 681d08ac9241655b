//! A small latent-level scene shared by the formula tests, with its host-side closed form.

use burn::tensor::{Device, Tensor};
use gb_diffusion::distill::{
    AlphasCumprod, DistillOutput, DistillSettings, GuidanceMethod, LatentEncoder, LatentTarget,
    PromptEmbeddings, ScoreDistiller, TimestepConfig, Weighting,
};

use crate::distill::support::{host, rand01, randn, tensor, LinearPoolEncoder, MockUnet, LATENT_C};

pub const H: usize = 8;
pub const W: usize = 8;
pub const LH: usize = H / 2;
pub const LW: usize = W / 2;
pub const TIMESTEP: usize = 500;

/// SD 1.5's schedule.
pub fn sd_alphas() -> AlphasCumprod {
    AlphasCumprod::stable_diffusion()
}

/// Latent mask: the left half of the latent columns.
pub fn half_mask() -> Vec<f32> {
    (0..LH * LW)
        .map(|i| if i % LW < LW / 2 { 1.0 } else { 0.0 })
        .collect()
}

pub struct Scene {
    pub device: Device,
    pub image: Tensor<4>,
    pub mask: Vec<f32>,
    pub masked: Vec<f32>,
    pub noise: Vec<f32>,
    pub prompts: PromptEmbeddings,
    pub means: [f32; 3],
}

impl Scene {
    /// `image_values = None` gives a seeded random image.
    pub fn new(device: &Device, mask: Vec<f32>, image_values: Option<Vec<f32>>) -> Self {
        let emb = |seed| randn(seed, 3 * 5);
        let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
        let (t, u, n) = (emb(4), emb(5), emb(6));
        let means = [mean(&t), mean(&u), mean(&n)];
        let inner = device.clone();
        let values = image_values.unwrap_or_else(|| rand01(1, 3 * H * W));
        Self {
            device: device.clone(),
            image: tensor(values, [1, 3, H, W], &device.clone().autodiff()).require_grad(),
            mask,
            masked: randn(3, LATENT_C * LH * LW),
            noise: randn(7, LATENT_C * LH * LW),
            prompts: PromptEmbeddings {
                text: tensor(t, [1, 3, 5], &inner),
                unconditional: Some(tensor(u, [1, 3, 5], &inner)),
                negative: Some(tensor(n, [1, 3, 5], &inner)),
            },
            means,
        }
    }

    pub fn distiller(method: GuidanceMethod, weighting: Weighting) -> ScoreDistiller {
        let settings = DistillSettings {
            guidance: method,
            timesteps: TimestepConfig::default(),
            weighting,
            grad_clamp: None,
        };
        ScoreDistiller::new(&settings, sd_alphas(), 0).expect("valid settings")
    }

    /// Runs `step_with` at [`TIMESTEP`] with the fixed noise; returns output and image gradient.
    pub fn run(
        &self,
        distiller: &ScoreDistiller,
        unet: &MockUnet,
        encoder: &dyn LatentEncoder,
        timestep: usize,
    ) -> (DistillOutput, Vec<f32>) {
        let latents = encoder.encode(self.image.clone()).expect("encode");
        let target = LatentTarget {
            latents,
            mask_latent: tensor(self.mask.clone(), [1, 1, LH, LW], &self.device),
            masked_image_latents: tensor(self.masked.clone(), [1, LATENT_C, LH, LW], &self.device),
            prompts: &self.prompts,
        };
        let noise = tensor(self.noise.clone(), [1, LATENT_C, LH, LW], &self.device);
        let out = distiller
            .step_with(unet, target, timestep, noise)
            .expect("step");
        let grads = out.loss.backward();
        let image_grad = host(self.image.grad(&grads).expect("image gradient"));
        (out, image_grad)
    }

    /// The closed-form latent gradient of `method` at `timestep` for the linear encoder.
    pub fn expected(
        &self,
        method: &GuidanceMethod,
        timestep: usize,
        weighting: Weighting,
    ) -> Vec<f32> {
        let latents = LinearPoolEncoder::new(&self.device)
            .encode(self.image.clone().inner())
            .expect("encode");
        let z = host(latents);
        let ab = sd_alphas().at(timestep);
        let x_t: Vec<f32> = z
            .iter()
            .zip(&self.noise)
            .map(|(z, n)| (ab.sqrt() as f32) * z + ((1.0 - ab).sqrt() as f32) * n)
            .collect();
        let eps = |m: f32| {
            crate::distill::support::mock_eps_host(&x_t, m, &self.mask, &self.masked, LH * LW)
        };
        let (et, eu, en) = (eps(self.means[0]), eps(self.means[1]), eps(self.means[2]));
        let w = match weighting {
            Weighting::OneMinusAlphaBar => (1.0 - ab) as f32,
            Weighting::Constant => 1.0,
        };
        (0..x_t.len())
            .map(|i| {
                let dir = match *method {
                    GuidanceMethod::Sds { guidance_scale: s } => {
                        eu[i] + s * (et[i] - eu[i]) - self.noise[i]
                    }
                    GuidanceMethod::Csd { w1, w2, w3 } => {
                        w1 * et[i] + w3.unwrap_or(w2 - w1) * eu[i] - w2 * en[i]
                    }
                    GuidanceMethod::Bsd { w1, w2 } => w1 * et[i] - w2 * en[i],
                };
                dir * w * self.mask[i % (LH * LW)]
            })
            .collect()
    }
}
