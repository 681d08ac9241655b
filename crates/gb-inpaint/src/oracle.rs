//! Oracle guidance, for experiments that separate the prior from the distillation: the RGB
//! term's prompt branch answered by the exact score of the true image
//! ([`gb_diffusion::distill::OracleEps`]) instead of the U-Net. The true image of a guided
//! view is its object-free image (a procedural scene's `clean/`), cropped as the render is.
//! With it, a guided run that does not beat `none` cannot blame the prior. No capture has
//! these images: a method with `[oracle]` is an upper bound, never a method to ship.
//!
//! `[oracle] clean = "DIR"` turns it on; `branches` (default `["text"]`) says which rows of
//! the batched call the oracle answers (`["text", "negative"]`: BSD's negative too, which
//! then also points at the truth).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use burn::tensor::{Device, Tensor};
use gb_core::RgbImage;
use gb_diffusion::distill::{Branch, LatentEncoder};
use gb_nerf::scene::{Scene, Split};
use serde::{Deserialize, Serialize};

use crate::crop::{crop_image, CropGeometry};
use crate::error::InpaintError;

/// `[oracle]` of a method (module docs). Left out of a written config while off.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OracleSettings {
    /// Folder of the object-free training views, `NAME.png` (`None`: off).
    pub clean: Option<PathBuf>,
    /// The branches of the RGB term the oracle answers.
    pub branches: Vec<Branch>,
}

impl Default for OracleSettings {
    fn default() -> Self {
        Self {
            clean: None,
            branches: vec![Branch::Text],
        }
    }
}

impl OracleSettings {
    /// Whether these are the default settings (off).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }
}

/// The object-free image of each training view of `scene` found in `dir` (`NAME.png`, the
/// view's full size), at `1 / downscale` resolution; `None` for the views without one. An
/// error names `field` and the file: not a folder, an unreadable image, a wrong size, no
/// training view's image at all.
pub fn load_object_free(
    scene: &Scene,
    dir: &Path,
    downscale: usize,
    field: &str,
) -> Result<Vec<Option<RgbImage>>, InpaintError> {
    let spec = |reason: String| InpaintError::Spec {
        field: field.to_string(),
        reason,
    };
    if !dir.is_dir() {
        return Err(spec(format!("{}: not a folder", dir.display())));
    }
    let train: Vec<&gb_nerf::scene::View> = scene.split(Split::Train).collect();
    let mut out = Vec::with_capacity(train.len());
    for view in &train {
        let path = dir.join(format!("{}.png", view.name));
        if !path.is_file() {
            out.push(None);
            continue;
        }
        let image = gb_core::read_rgb(&path, Some(scene.background))
            .map_err(|e| spec(format!("{}: cannot read the image: {e}", path.display())))?;
        if (image.width, image.height) != (view.image.width, view.image.height) {
            return Err(spec(format!(
                "{}: the image is {}x{}, the view '{}' is {}x{}",
                path.display(),
                image.width,
                image.height,
                view.name,
                view.image.width,
                view.image.height
            )));
        }
        out.push(Some(gb_nerf::train::data::downscale_image(
            &image,
            downscale.max(1),
        )));
    }
    if out.iter().all(Option::is_none) {
        return Err(spec(format!(
            "{}: holds no training view's image (NAME.png, e.g. {}.png)",
            dir.display(),
            train.first().map(|v| v.name.as_str()).unwrap_or("view")
        )));
    }
    Ok(out)
}

/// The true latents of the guided views (module docs), encoded on first use.
pub struct OracleTargets {
    images: Vec<Option<RgbImage>>,
    latents: HashMap<usize, Tensor<4>>,
    /// The branches the oracle answers.
    pub branches: Vec<Branch>,
}

impl OracleTargets {
    /// The targets of the object-free training-resolution `images` (by training view).
    pub fn new(images: Vec<Option<RgbImage>>, branches: Vec<Branch>) -> Self {
        Self {
            images,
            latents: HashMap::new(),
            branches,
        }
    }

    /// The true latents `[1, C, h, w]` of training view `view`'s crop `geometry` at the
    /// prior's `resolution`; `None` when the view has no object-free image.
    pub fn latents(
        &mut self,
        view: usize,
        geometry: &CropGeometry,
        resolution: usize,
        encoder: &dyn LatentEncoder,
        device: &Device,
    ) -> Result<Option<Tensor<4>>, InpaintError> {
        if let Some(z) = self.latents.get(&view) {
            return Ok(Some(z.clone()));
        }
        let Some(image) = self.images.get(view).and_then(Option::as_ref) else {
            return Ok(None);
        };
        let crop = crop_image(image, geometry.bbox, resolution, device);
        let z = encoder
            .encode(crop.mul_scalar(2.0).sub_scalar(1.0))?
            .inner();
        self.latents.insert(view, z.clone());
        Ok(Some(z))
    }
}
