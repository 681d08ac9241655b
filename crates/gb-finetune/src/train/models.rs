//! The networks a fine-tuning run touches, loaded from a diffusers folder, built fresh from
//! config files (training from scratch), and written back as a diffusers folder.

use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::tensor::{Device, Int, Tensor};

use gb_diffusion::checkpoint::{keymap, save_module};
use gb_diffusion::clip::text_model::ClipTextModel;
use gb_diffusion::config::{
    AutoencoderKLConfig, ClipTextConfig, SchedulerConfig, UNet2DConditionConfig,
};
use gb_diffusion::lora::LoraFile;
use gb_diffusion::models::{AutoencoderKL, UNet2DConditionModel};
use gb_diffusion::pipeline::SdComponents;
use gb_diffusion::scheduler::alphas_cumprod;
use gb_diffusion::tokenizer::ClipTokenizer;

use crate::FinetuneError;

/// Every float parameter of `m` by its path (LoRA factors included: their paths contain
/// `.lora.`), as `f32` values: what a run compares to show which weights moved. A parameter
/// that cannot be read is an error naming it, never a missing entry.
pub fn parameter_values<M: Module>(
    m: &M,
) -> Result<std::collections::BTreeMap<String, Vec<f32>>, FinetuneError> {
    use burn::store::{bridge, ModuleSnapshot};
    m.collect(None, None, false)
        .into_iter()
        .map(|t| {
            let name = t.name.clone();
            let unreadable = |e: String| FinetuneError::Diffusion {
                context: format!("reading parameter {name}"),
                message: e,
            };
            let data = bridge::into_data(t).map_err(|e| unreadable(format!("{e:?}")))?;
            let values = data
                .convert::<f32>()
                .try_to_vec::<f32>()
                .map_err(|e| unreadable(format!("{e:?}")))?;
            Ok((name, values))
        })
        .collect()
}

/// The trainable pair: a U-Net and a text encoder in one module, so that one optimiser,
/// one record and one gradient clip cover both.
#[derive(Module, Debug)]
pub struct Trainable {
    /// The 9-channel inpainting U-Net.
    pub unet: UNet2DConditionModel,
    /// The CLIP text encoder.
    pub text_encoder: ClipTextModel,
}

/// Every component of an inpainting prior that fine-tuning needs.
pub struct PriorModels {
    /// CLIP tokenizer.
    pub tokenizer: ClipTokenizer,
    /// U-Net and text encoder (on the training device, which may be an autodiff device).
    pub trainable: Trainable,
    /// The frozen VAE (its encoder makes latents and masked-image latents).
    pub vae: AutoencoderKL,
    /// U-Net config (kept to write the folder back).
    pub unet_config: UNet2DConditionConfig,
    /// VAE image-to-latent factor.
    pub vae_factor: usize,
    /// VAE config (the sampler's view needs it).
    pub vae_config: AutoencoderKLConfig,
    /// Scheduler config of the prior.
    pub scheduler: SchedulerConfig,
    /// `alphas_cumprod[t]` of the training schedule.
    pub alphas_cumprod: Vec<f64>,
    /// The folder the prior came from (configs and tokenizer are copied from it on save).
    pub source: PathBuf,
}

fn diffusion(context: &str, path: &Path) -> impl Fn(String) -> FinetuneError {
    let context = format!("{context} ({})", path.display());
    move |message| FinetuneError::Diffusion {
        context: context.clone(),
        message,
    }
}

/// Refuses a U-Net (config file `path`) that is not an inpainting U-Net for latents of
/// `latent_channels`: input `2 * latent_channels + 1` (noisy latent, mask, masked-image
/// latent; 9 for Stable Diffusion) and output `latent_channels`.
fn check_inpainting(
    unet: &UNet2DConditionConfig,
    latent_channels: usize,
    path: &Path,
) -> Result<(), FinetuneError> {
    if unet.is_inpainting_for(latent_channels) {
        return Ok(());
    }
    Err(FinetuneError::Invalid {
        path: path.to_path_buf(),
        message: format!(
            "in_channels = {} and out_channels = {}; fine-tuning needs an inpainting U-Net \
             for the VAE's {latent_channels} latent channels: in_channels = {} (noisy latent, \
             mask, masked-image latent) and out_channels = {latent_channels}",
            unet.in_channels,
            unet.out_channels,
            2 * latent_channels + 1
        ),
    })
}

fn scheduler_of(root: &Path) -> Result<SchedulerConfig, FinetuneError> {
    let path = root.join("scheduler").join("scheduler_config.json");
    if path.is_file() {
        SchedulerConfig::from_file(&path)
            .map_err(|e| diffusion("scheduler config", &path)(e.to_string()))
    } else {
        Ok(SchedulerConfig::default())
    }
}

impl PriorModels {
    /// Loads tokenizer, text encoder, U-Net, VAE and scheduler of a diffusers inpainting
    /// folder onto `device` (use an autodiff device to train).
    pub fn load(root: &Path, device: &Device) -> Result<Self, FinetuneError> {
        Self::load_merged(root, None, device)
    }

    /// [`Self::load`], with the LoRA `lora` merged into the U-Net and text-encoder weights
    /// first (a prior's geometric LoRA, which a per-scene LoRA is then trained on top of).
    pub fn load_merged(
        root: &Path,
        lora: Option<&LoraFile>,
        device: &Device,
    ) -> Result<Self, FinetuneError> {
        let mut c = SdComponents::load(root, device, device)
            .map_err(|e| diffusion(e.component, root)(e.source.to_string()))?;
        if let Some(file) = lora {
            c = c
                .merge_lora(file)
                .map_err(|e| diffusion("merging the LoRA", &file.path)(e.to_string()))?
                .0;
        }
        check_inpainting(
            &c.unet_config,
            c.vae_config.latent_channels,
            &root.join("unet").join("config.json"),
        )?;
        let (tokenizer, unet, text_encoder, unet_config) =
            (c.tokenizer, c.unet, c.text_encoder, c.unet_config);
        let (vae, vae_config, scheduler) = (c.vae, c.vae_config, c.scheduler);
        Ok(Self {
            tokenizer,
            trainable: Trainable { unet, text_encoder },
            vae: vae.no_grad(),
            unet_config,
            vae_factor: vae_config.scale_factor(),
            vae_config,
            alphas_cumprod: alphas_cumprod(&scheduler),
            scheduler,
            source: root.to_path_buf(),
        })
    }

    /// Builds freshly initialised networks from the config files of a diffusers-layout
    /// recipe folder (`unet/config.json`, `text_encoder/config.json`, `tokenizer/`,
    /// `scheduler/`), with the VAE taken from `vae` (a trained autoencoder). Burn's default
    /// initialisers are seeded from the device RNG (`device.seed`).
    pub fn from_scratch(
        recipe: &Path,
        vae: AutoencoderKL,
        vae_config: &AutoencoderKLConfig,
        device: &Device,
    ) -> Result<Self, FinetuneError> {
        let unet_path = recipe.join("unet").join("config.json");
        let unet_config = UNet2DConditionConfig::from_file(&unet_path)
            .map_err(|e| diffusion("unet config", &unet_path)(e.to_string()))?;
        check_inpainting(&unet_config, vae_config.latent_channels, &unet_path)?;
        let text_path = recipe.join("text_encoder").join("config.json");
        let text =
            std::fs::read_to_string(&text_path).map_err(|e| FinetuneError::io(&text_path, e))?;
        let text_config: ClipTextConfig =
            serde_json::from_str(&text).map_err(|e| FinetuneError::Invalid {
                path: text_path.clone(),
                message: e.to_string(),
            })?;
        let tok_dir = recipe.join("tokenizer");
        let tokenizer = ClipTokenizer::from_dir(&tok_dir)
            .map_err(|e| diffusion("tokenizer", &tok_dir)(e.to_string()))?;
        let scheduler = scheduler_of(recipe)?;
        Ok(Self {
            tokenizer,
            trainable: Trainable {
                unet: UNet2DConditionModel::new(&unet_config, device),
                text_encoder: ClipTextModel::new(&text_config, device),
            },
            vae: vae.no_grad(),
            unet_config,
            vae_factor: vae_config.scale_factor(),
            vae_config: vae_config.clone(),
            alphas_cumprod: alphas_cumprod(&scheduler),
            scheduler,
            source: recipe.to_path_buf(),
        })
    }

    /// Token ids `[n, 77]` of `prompts`.
    pub fn token_ids(
        &self,
        prompts: &[String],
        device: &Device,
    ) -> Result<Tensor<2, Int>, FinetuneError> {
        let mut rows = Vec::with_capacity(prompts.len());
        for p in prompts {
            let ids = self
                .tokenizer
                .encode(p)
                .map_err(|e| FinetuneError::diffusion(format!("tokenizing {p:?}"), e))?;
            rows.push(ids.into_iter().map(i64::from).collect::<Vec<i64>>());
        }
        self.trainable
            .text_encoder
            .ids_tensor(&rows, device)
            .map_err(|e| FinetuneError::diffusion("text encoder ids", e))
    }

    /// Writes the prior as a diffusers inpainting folder at `out`: `model_index.json`,
    /// `unet/`, `text_encoder/`, `vae/` (weights as `*.safetensors`, configs and tokenizer
    /// copied from the source folder, `vae/config.json` with `vae_scaling_factor` when
    /// given) and `scheduler/`. LoRA adapters must be merged first.
    pub fn save_folder(
        &self,
        out: &Path,
        vae_config_json: &serde_json::Value,
    ) -> Result<(), FinetuneError> {
        let src = &self.source;
        for dir in ["unet", "text_encoder", "vae", "tokenizer", "scheduler"] {
            std::fs::create_dir_all(out.join(dir))
                .map_err(|e| FinetuneError::io(out.join(dir), e))?;
        }
        let copy = |rel: &str| -> Result<(), FinetuneError> {
            let from = src.join(rel);
            if from.is_file() {
                std::fs::copy(&from, out.join(rel)).map_err(|e| FinetuneError::io(&from, e))?;
            }
            Ok(())
        };
        for rel in [
            "model_index.json",
            "unet/config.json",
            "text_encoder/config.json",
            "scheduler/scheduler_config.json",
            "tokenizer/vocab.json",
            "tokenizer/merges.txt",
            "tokenizer/tokenizer_config.json",
            "tokenizer/special_tokens_map.json",
        ] {
            copy(rel)?;
        }
        let vae_json =
            serde_json::to_string_pretty(vae_config_json).map_err(|e| FinetuneError::Invalid {
                path: out.join("vae/config.json"),
                message: e.to_string(),
            })?;
        gb_core::write_atomic(&out.join("vae/config.json"), vae_json.as_bytes())
            .map_err(|e| FinetuneError::io(out.join("vae/config.json"), e))?;
        let unet_section = if self.unet_config.use_linear_projection {
            keymap::UNET_LINEAR_PROJECTION
        } else {
            keymap::UNET
        };
        let save = |m: &dyn Fn(&Path) -> Result<(), gb_diffusion::checkpoint::CheckpointError>,
                    rel: &str| {
            let path = out.join(rel);
            m(&path).map_err(|e| diffusion("writing weights", &path)(e.to_string()))
        };
        save(
            &|p| save_module(&self.trainable.unet, p, &unet_section),
            "unet/diffusion_pytorch_model.safetensors",
        )?;
        save(
            &|p| save_module(&self.trainable.text_encoder, p, &keymap::TEXT_ENCODER),
            "text_encoder/model.safetensors",
        )?;
        save(
            &|p| save_module(&self.vae, p, &keymap::VAE),
            "vae/diffusion_pytorch_model.safetensors",
        )?;
        Ok(())
    }
}
