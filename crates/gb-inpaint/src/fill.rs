//! `cargo xtask fill`: a reference view ([`crate::reference`]) filled in 2D, for a user
//! without a 2D inpainting tool. `--with` picks the fill:
//!
//! - `fsr`: frequency-selective reconstruction ([`gb_fill::fsr`]), no weights;
//! - `smooth`: the membrane fill ([`gb_fill::smooth`]), no weights, no texture;
//! - `prior`: the diffusion prior itself, by multi-step sampling (DDIM with classifier-free
//!   guidance, the known region blended in after each step), not distillation. The view's
//!   guidance crop (its mask's bounding box grown by `margin`, as the guided run crops it:
//!   [`CropGeometry`]) is resampled to the prior's resolution, inpainted with the prompts the
//!   guided methods use (the scene's captions in `"RGB image, {caption}"`, negative
//!   `"RGB image, {object_caption}"`) and the prior's geometric LoRA when it has one, and
//!   pasted back into the masked pixels (bilinear).
//!
//! Every pixel outside the mask is the input's.

use std::path::{Path, PathBuf};

use gb_core::RgbImage;
use gb_diffusion::inpaint::{inpaint, InpaintRequest};
use gb_diffusion::pipeline::SdComponents;
use gb_nerf::render::rays::crop_pixels;
use gb_nerf::scene::{Scene, Split};
use gb_nerf::train::data::prepare_view;

use crate::crop::CropGeometry;
use crate::error::InpaintError;
pub use crate::method::{AutoReference, FillWith};
use crate::method::{PromptOverrides, SceneCaptions};
use crate::prior::LORA_FILE_NAME;

/// What `fill` needs besides the scene and the view.
#[derive(Debug, Clone)]
pub struct FillOptions {
    /// Which fill.
    pub with: FillWith,
    /// The settings of [`FillWith::Fsr`].
    pub fsr: gb_fill::FsrSettings,
    /// `tiny`, a diffusers inpainting folder or a hub id.
    pub prior: String,
    /// LoRA files merged in order; `None`: the prior's own geometric LoRA when it has one.
    pub lora: Option<Vec<PathBuf>>,
    /// Prompts replacing the guided methods' templates.
    pub prompts: PromptOverrides,
    /// DDIM steps.
    pub steps: usize,
    /// Classifier-free guidance scale (diffusers' convention).
    pub guidance: f64,
    /// Seed of the initial noise.
    pub seed: u64,
    /// Crop margin (the guided run's `crop_margin`).
    pub margin: f32,
    /// The backend.
    pub device: gb_core::BackendKind,
}

impl Default for FillOptions {
    fn default() -> Self {
        Self {
            with: FillWith::default(),
            fsr: gb_fill::FsrSettings::default(),
            prior: "tiny".into(),
            lora: None,
            prompts: PromptOverrides::default(),
            steps: 50,
            guidance: 7.5,
            seed: 0,
            margin: 0.25,
            device: gb_core::BackendKind::default(),
        }
    }
}

/// What [`fill_view`] made.
#[derive(Debug, Clone)]
pub struct Fill {
    /// The view at full resolution with its masked pixels filled.
    pub image: RgbImage,
    /// The view's file stem.
    pub view: String,
    /// Which fill made it.
    pub with: FillWith,
    /// What the prior's fill used (`None` for the fills without weights).
    pub prior: Option<PriorFill>,
    /// Masked pixels filled.
    pub filled_pixels: usize,
}

/// The prior, LoRA files and prompts of a [`FillWith::Prior`] fill.
#[derive(Debug, Clone)]
pub struct PriorFill {
    /// The prior folder.
    pub prior: PathBuf,
    /// The LoRA files merged.
    pub lora: Vec<PathBuf>,
    /// The prompt and negative prompt.
    pub prompts: (String, String),
}

fn view_error(view: &str, scene: &Path, reason: String) -> InpaintError {
    InpaintError::Spec {
        field: format!("--view {view} (scene {})", scene.display()),
        reason,
    }
}

/// Fills the masked pixels of training view `view` (a file name or stem) of `scene`
/// (loaded from `scene_dir`) with `opts.with` (module docs). Errors name the flag: an unknown
/// view, a view without a mask or with an empty one, a prior or LoRA that does not load.
pub fn fill_view(
    scene: &Scene,
    scene_dir: &Path,
    view: &str,
    opts: &FillOptions,
) -> Result<Fill, InpaintError> {
    let stem = Path::new(view)
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_else(|| view.to_string());
    let v = scene
        .split(Split::Train)
        .find(|v| v.name == view || v.name == stem)
        .ok_or_else(|| {
            view_error(
                view,
                scene_dir,
                format!("'{view}' is not a training view of scene '{}'", scene.name),
            )
        })?;
    if opts.with != FillWith::Prior {
        return classical_fill(v, scene_dir, view, opts);
    }
    let full = prepare_view(v, 1);
    if opts.steps == 0 {
        return Err(InpaintError::Spec {
            field: "--steps".into(),
            reason: "must be at least 1".into(),
        });
    }
    let prior_dir = gb_diffusion::checkpoint::resolve_prior(&opts.prior)?;
    let device = opts.device.device();
    let mut prior = SdComponents::load_inpainting(&prior_dir, &device)?;
    let lora = match &opts.lora {
        Some(list) => list.clone(),
        None => {
            let own = prior_dir.join(LORA_FILE_NAME);
            if own.is_file() {
                vec![own]
            } else {
                Vec::new()
            }
        }
    };
    for l in &lora {
        prior = prior
            .with_lora(l)
            .map_err(|e| InpaintError::Lora {
                path: l.clone(),
                reason: e.to_string(),
            })?
            .0;
    }
    let r = prior.unet_config.native_resolution(prior.vae_factor());
    let geometry = CropGeometry::new(&full, opts.margin, r).ok_or_else(|| {
        view_error(
            view,
            scene_dir,
            format!("view '{}' has no mask, so there is nothing to fill", v.name),
        )
    })?;
    let positions = crop_pixels(geometry.bbox, r, r);
    let mut rgb = Vec::with_capacity(r * r * 3);
    for [px, py] in &positions {
        rgb.extend_from_slice(&full.image.bilinear(*px, *py));
    }
    let mask: Vec<f32> = geometry
        .mask
        .iter()
        .map(|m| f32::from(u8::from(*m)))
        .collect();
    let captions = SceneCaptions::read(scene_dir);
    let method = crate::MethodConfig::load(crate::method::DEFAULT_METHOD)?;
    let prompts = method.resolve_prompts(&captions, &opts.prompts);
    let req = InpaintRequest {
        width: r,
        height: r,
        rgb,
        mask,
        prompt: prompts.appearance.clone(),
        negative_prompt: prompts.negative.clone(),
        steps: opts.steps,
        guidance: opts.guidance,
        seed: opts.seed,
        init_latents: None,
        blend_known: true,
    };
    let bar = gb_core::progress::bar(opts.steps as u64).with_message("fill");
    let out = inpaint(&prior, &req, |_, _| bar.inc(1))?;
    bar.finish_and_clear();
    let values = gb_core::read_f32(out, "filled crop").map_err(gb_nerf::train::NerfError::from)?;
    // [1, 3, r, r] planar to an RgbImage
    let mut crop = RgbImage::filled(r, r, [0.0; 3]);
    for i in 0..r * r {
        crop.set(
            i % r,
            i / r,
            [values[i], values[r * r + i], values[2 * r * r + i]],
        );
    }
    let (x0, y0, x1, y1) = geometry.bbox;
    let (bw, bh) = ((x1 - x0) as f32, (y1 - y0) as f32);
    let mut image = v.image.clone();
    let m = full.mask.as_ref().expect("a crop implies a mask");
    let mut filled = 0;
    for y in 0..m.height {
        for x in 0..m.width {
            if m.data[y * m.width + x] {
                let u = (x as f32 + 0.5 - x0 as f32) / bw * r as f32;
                let w = (y as f32 + 0.5 - y0 as f32) / bh * r as f32;
                image.set(x, y, crop.bilinear(u, w));
                filled += 1;
            }
        }
    }
    Ok(Fill {
        image,
        view: v.name.clone(),
        with: FillWith::Prior,
        prior: Some(PriorFill {
            prior: prior_dir,
            lora,
            prompts: (prompts.appearance, prompts.negative),
        }),
        filled_pixels: filled,
    })
}

/// [`FillWith::Fsr`] or [`FillWith::Smooth`] of view `v` at its full resolution.
fn classical_fill(
    v: &gb_nerf::scene::View,
    scene_dir: &Path,
    view: &str,
    opts: &FillOptions,
) -> Result<Fill, InpaintError> {
    let mask = v.mask.as_ref().ok_or_else(|| {
        view_error(
            view,
            scene_dir,
            format!("view '{}' has no mask, so there is nothing to fill", v.name),
        )
    })?;
    let size = (mask.width, mask.height);
    let image = match opts.with {
        FillWith::Fsr => gb_fill::fsr::fill(&v.image, &mask.data, size, &opts.fsr),
        _ => gb_fill::smooth::fill(&v.image, &mask.data, size),
    }
    .map_err(|e| view_error(view, scene_dir, format!("view '{}': {e}", v.name)))?;
    Ok(Fill {
        image,
        view: v.name.clone(),
        with: opts.with,
        prior: None,
        filled_pixels: mask.data.iter().filter(|m| **m).count(),
    })
}

/// Loads the scene folder `scene_dir` and fills its view `view` ([`fill_view`]).
pub fn fill(scene_dir: &Path, view: &str, opts: &FillOptions) -> Result<Fill, InpaintError> {
    let (_, scene) = gb_nerf::scene::load(scene_dir, &gb_nerf::scene::LoadOptions::default())
        .map_err(|source| InpaintError::Scene {
            what: "loading scene",
            path: scene_dir.to_path_buf(),
            source: Box::new(source),
        })?;
    fill_view(&scene, scene_dir, view, opts)
}

/// `--reference auto` (issue 46): the middle masked training view of `scene` (the view that
/// the reference oracle and `bench quality`'s reference rows use, so that an automatic
/// reference compares like for like with the exact one), filled by frequency-selective
/// reconstruction, is written to `dir/reference-auto-VIEW.png`. Returns its `VIEW.png=PATH`
/// pair (the path absolute) and the record.
pub fn auto_reference(
    scene: &Scene,
    scene_dir: &Path,
    dir: &Path,
) -> Result<(String, AutoReference), InpaintError> {
    let v = crate::reference::middle_masked_view(scene).ok_or_else(|| InpaintError::Spec {
        field: "--reference auto".into(),
        reason: format!(
            "scene {} has no training view with a mask to fill",
            scene_dir.display()
        ),
    })?;
    let opts = FillOptions {
        with: FillWith::Fsr,
        ..FillOptions::default()
    };
    let filled = fill_view(scene, scene_dir, &v.name, &opts)?;
    std::fs::create_dir_all(dir).map_err(|e| InpaintError::io(dir, e))?;
    let png = std::path::absolute(dir.join(format!("reference-auto-{}.png", v.name)))
        .map_err(|e| InpaintError::io(dir, e))?;
    gb_core::write_rgb_png(&png, &filled.image)
        .map_err(|e| InpaintError::io(&png, std::io::Error::other(e.to_string())))?;
    tracing::info!(view = %v.name, path = %png.display(), "--reference auto: the view filled by fsr");
    Ok((
        format!("{}.png={}", v.name, png.display()),
        AutoReference {
            view: v.name.clone(),
            with: opts.with,
            fsr: opts.fsr,
        },
    ))
}
