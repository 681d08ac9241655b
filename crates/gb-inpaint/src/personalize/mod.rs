//! Per-scene personalisation of the prior, as MALD-NeRF's per-scene LoRA and RefFusion do:
//! before guidance starts, a LoRA is fine-tuned on the scene's own unmasked training pixels
//! with random holes, by gb-finetune's self-supervised inpainting loss, so that the prior
//! fills the object's hole with this scene's appearance rather than its training set's.
//!
//! - **Data** ([`patches`]): square patches of the training views at the guidance crop's size
//!   that touch no object mask (the object is never shown to the prior), captioned with the
//!   run's appearance prompt; when fewer than [`MIN_PATCHES`] fit (a large object), the side
//!   shrinks by a quarter at a time. RGB only: a scene has no ground-truth normal maps.
//!   A view with an object-free image gives its masked squares too, from that image: each
//!   reference view of the run ([`crate::reference`]), and each view with an image in the
//!   `object_free` folder (a clean plate per view; a procedural scene's `clean/` is exact
//!   ground truth, which makes the personalised prior the `prior-oracle` of
//!   `bench quality --oracle`).
//! - **Training**: a fresh LoRA (`rank`, `alpha`) on the U-Net attention projections of the
//!   prior with its geometric LoRA (if the method uses one) merged, trained for `steps` AdamW
//!   steps on the run's backend. Every other weight is frozen.
//! - **Cache**: `OUT/personalize/lora.safetensors` (diffusers/PEFT format) and
//!   `OUT/personalize/personalize.json` (what it was trained from and its losses). A run whose
//!   prior and LoRA contents (fingerprinted, wherever they lie), prompt, settings and patches
//!   match reuses it; anything else retrains.
//! - **Loss report**: the inpainting loss on [`EVAL_BATCHES`] fixed batches of the same
//!   patches with fresh holes, noise and timesteps that training never draws, before and
//!   after. It is not a held-out loss: the patches' pixels are trained on.
//!
//! Enabled with `[personalize] steps = N` in the method config or `--personalize N`; it works
//! with any prior folder (the tiny prior, SD 1.5 inpainting).

pub mod patches;

use std::path::{Path, PathBuf};
use std::time::Instant;

use gb_core::{Devices, RgbImage};
use gb_finetune::train::batch::make_batch;
use gb_finetune::train::loss::inpainting_loss;
use gb_finetune::train::{FinetuneTrainer, PriorModels};
use gb_finetune::FinetuneError;
use gb_nerf::scene::{Scene, Split};
use gb_nerf::train::data::TrainData;
use gb_nerf::train::DepthSupervision;
use serde::{Deserialize, Serialize};

use crate::error::InpaintError;
pub use crate::method::PersonalizeSettings;
pub use patches::ScenePatches;

/// Fresh-mask batches the loss is reported on.
pub const EVAL_BATCHES: usize = 8;
/// The step index the fresh-mask batches are drawn at: far beyond any run, so that their
/// holes, noise and timesteps are never trained on.
const EVAL_STEP: usize = 1 << 40;
/// Fewest patches personalisation trains on before it shrinks them.
pub const MIN_PATCHES: usize = 32;
/// The smallest patch side, training pixels.
pub const MIN_PATCH_SIDE: usize = 16;
/// The cache's folder in the run folder.
pub const FOLDER: &str = "personalize";

/// What personalisation did (`metrics.json`'s `personalize`, and the cache file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PersonalizeReport {
    /// The LoRA file, relative to the run folder.
    pub lora: PathBuf,
    /// AdamW steps.
    pub steps: usize,
    /// Patches it trained on.
    pub patches: usize,
    /// Their side, training-resolution pixels.
    pub patch_side: usize,
    /// Views whose object-free image was trained on, masked region included.
    #[serde(default)]
    pub object_free_views: usize,
    /// Mean inpainting loss on the fresh-mask batches of the patches before training.
    pub loss_before: f64,
    /// The same after training.
    pub loss_after: f64,
    /// Wall time of the training, seconds (of the run that trained it).
    pub seconds: f64,
    /// Whether this run reused the cache.
    pub cached: bool,
}

/// What the cache is valid for: the contents (not the paths) of the prior folder and the
/// LoRA, the prompt, the settings and the patches.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct CacheKey {
    prior: String,
    lora: Option<String>,
    prompt: String,
    settings: PersonalizeSettings,
    patches: String,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct CacheFile {
    key: CacheKey,
    report: PersonalizeReport,
}

fn finetune_err(context: &str) -> impl Fn(FinetuneError) -> InpaintError + '_ {
    move |e| InpaintError::Personalize {
        reason: format!("{context}: {e}"),
    }
}

/// The mean inpainting loss of `trainer`'s prior on [`EVAL_BATCHES`] batches of `source`
/// with holes, noise and timesteps that training never draws (its patches are trained on).
pub fn fresh_mask_loss(
    trainer: &FinetuneTrainer,
    source: &ScenePatches,
) -> Result<f64, FinetuneError> {
    let cfg = &trainer.config;
    let latent = cfg.resolution / trainer.models.vae_factor;
    let channels = trainer.models.vae.latent_channels;
    let schedule = trainer.models.alphas_cumprod.len();
    let mut sum = 0.0;
    for micro in 0..EVAL_BATCHES {
        let batch = make_batch(source, cfg, EVAL_STEP, micro, channels, latent, schedule)?;
        let loss = inpainting_loss(
            &trainer.models,
            &trainer.models.trainable,
            &batch,
            trainer.device(),
            cfg.train_text_encoder,
        )?;
        sum += loss.detach().into_scalar::<f64>();
    }
    Ok(sum / EVAL_BATCHES as f64)
}

/// Everything personalisation needs from the run.
pub struct PersonalizeInputs<'a> {
    /// The scene (its training views and masks).
    pub scene: &'a Scene,
    /// The preset's training-image downscale (the guidance crops' resolution).
    pub downscale: usize,
    /// The method's crop margin.
    pub crop_margin: f32,
    /// The prior folder.
    pub prior: &'a Path,
    /// The LoRA the method attaches, merged before training.
    pub lora: Option<&'a Path>,
    /// The prior's square resolution.
    pub resolution: usize,
    /// The appearance prompt the patches are captioned with.
    pub prompt: &'a str,
    /// The settings.
    pub settings: &'a PersonalizeSettings,
    /// The run's reference views: their images are trained on, masked region included.
    pub references: &'a [crate::reference::ReferenceView],
    /// The run's devices; training is on `devices.train`.
    pub devices: Devices,
    /// The run folder (the cache lives in `OUT/personalize/`).
    pub out: &'a Path,
}

/// The object-free image of each training view at the training resolution, where there is
/// one: the run's references, then the `object_free` folder's `NAME.png` (module docs). An
/// error names the setting and the file: an unreadable folder or image, a wrong size, a
/// folder without any training view's image.
pub fn object_free_images(i: &PersonalizeInputs) -> Result<Vec<Option<RgbImage>>, InpaintError> {
    let mut out: Vec<Option<RgbImage>> = vec![None; i.scene.split(Split::Train).count()];
    for r in i.references {
        if let Some(slot) = out.get_mut(r.view) {
            *slot = Some(r.image.clone());
        }
    }
    if let Some(dir) = i.settings.object_free.as_deref() {
        let found = crate::oracle::load_object_free(
            i.scene,
            dir,
            i.downscale,
            "[personalize] object_free",
        )?;
        for (slot, image) in out.iter_mut().zip(found) {
            if slot.is_none() {
                *slot = image;
            }
        }
    }
    Ok(out)
}

/// The scene's training patches at the guidance crop's size (see [`patches`]); an error when
/// no view has a mask or no patch avoids the masks.
pub fn scene_patches(i: &PersonalizeInputs) -> Result<ScenePatches, InpaintError> {
    let data = TrainData::from_scene(i.scene, i.downscale, DepthSupervision::None)?;
    let object_free = object_free_images(i)?;
    let side = patches::crop_side(&data.views, i.crop_margin).ok_or_else(|| {
        InpaintError::Personalize {
            reason: format!("scene '{}' has no masked training view", i.scene.name),
        }
    })?;
    // a large object leaves few mask-free squares of the crop's size: shrink them until
    // there are enough (the prior then sees the scene at a somewhat finer scale)
    let mut side = side;
    let patches = |side| ScenePatches::with_object_free(&data.views, &object_free, side, i.prompt);
    let mut source = patches(side);
    while source.rects.len() < MIN_PATCHES && side > MIN_PATCH_SIDE {
        side = (side * 3 / 4).max(MIN_PATCH_SIDE);
        source = patches(side);
    }
    if source.rects.is_empty() {
        return Err(InpaintError::Personalize {
            reason: format!(
                "no {side}x{side} patch of a training view of '{}' avoids the object masks",
                i.scene.name
            ),
        });
    }
    Ok(source)
}

/// The fine-tuning run of the per-scene LoRA: the prior with the method's LoRA merged, fresh
/// adapters attached, on the autodiff device of the run's backend.
pub fn new_trainer(i: &PersonalizeInputs) -> Result<FinetuneTrainer, InpaintError> {
    let device = i.devices.train.clone();
    let base = i.lora.map(crate::prior::read_lora).transpose()?;
    let models = PriorModels::load_merged(i.prior, base.as_ref(), &device)
        .map_err(finetune_err("loading the prior"))?;
    FinetuneTrainer::new(models, i.settings.recipe(i.resolution), &device)
        .map_err(finetune_err("personalisation settings"))
}

/// Trains (or reuses from the cache) the per-scene LoRA; see the module docs.
pub fn personalize(i: &PersonalizeInputs) -> Result<PersonalizeReport, InpaintError> {
    let source = scene_patches(i)?;
    let object_free_views = source.object_free_views;
    let side = source.rects[0].side;
    let dir = i.out.join(FOLDER);
    let (lora_path, json_path) = (dir.join("lora.safetensors"), dir.join("personalize.json"));
    let contents = |p: &Path| {
        gb_core::fingerprint::contents(p)
            .map(|h| format!("{h:016x}"))
            .map_err(|e| InpaintError::io(p, e))
    };
    let key = CacheKey {
        prior: contents(i.prior)?,
        lora: i.lora.map(contents).transpose()?,
        prompt: i.prompt.to_string(),
        settings: i.settings.clone(),
        patches: format!("{:016x}", source.fingerprint()),
    };
    if let Some(cached) = std::fs::read_to_string(&json_path)
        .ok()
        .and_then(|t| serde_json::from_str::<CacheFile>(&t).ok())
        .filter(|c| c.key == key && lora_path.is_file())
    {
        tracing::info!(lora = %lora_path.display(), "personalisation: reusing the cached LoRA");
        return Ok(PersonalizeReport {
            cached: true,
            ..cached.report
        });
    }
    std::fs::create_dir_all(&dir).map_err(|e| InpaintError::io(&dir, e))?;
    let mut trainer = new_trainer(i)?;
    let loss_before =
        fresh_mask_loss(&trainer, &source).map_err(finetune_err("fresh-mask loss"))?;
    tracing::info!(
        patches = source.rects.len(),
        side,
        object_free_views,
        steps = i.settings.steps,
        loss_before,
        "personalisation: training a per-scene LoRA"
    );
    let started = Instant::now();
    let bar = gb_core::progress::bar(i.settings.steps as u64);
    for _ in 0..i.settings.steps {
        trainer
            .train_step(&source)
            .map_err(finetune_err("training"))?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    let seconds = started.elapsed().as_secs_f64();
    let loss_after = fresh_mask_loss(&trainer, &source).map_err(finetune_err("fresh-mask loss"))?;
    let tmp = dir.join("lora.safetensors.partial");
    trainer
        .export_lora(&tmp)
        .map_err(finetune_err("writing the LoRA"))?;
    std::fs::rename(&tmp, &lora_path).map_err(|e| InpaintError::io(&lora_path, e))?;
    let report = PersonalizeReport {
        lora: Path::new(FOLDER).join("lora.safetensors"),
        steps: i.settings.steps,
        patches: source.rects.len(),
        patch_side: side,
        object_free_views,
        loss_before,
        loss_after,
        seconds,
        cached: false,
    };
    tracing::info!(loss_before, loss_after, seconds, "personalisation done");
    let text = serde_json::to_vec_pretty(&CacheFile {
        key,
        report: report.clone(),
    })
    .map_err(|e| InpaintError::io(&json_path, std::io::Error::other(e)))?;
    gb_core::write_atomic(&json_path, &text).map_err(|e| InpaintError::io(&json_path, e))?;
    Ok(report)
}
