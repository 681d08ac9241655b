//! The guidance crop of a training view and its rendering.
//!
//! - **Geometry** ([`CropGeometry`]): the mask's bounding box at the training resolution,
//!   grown by `crop_margin` of its size on each side and clamped to the image, seen by a
//!   virtual camera whose `R x R` image is that box resampled (gb-nerf's `crop_camera`; pixel
//!   `(i, j)` of the crop is the view's continuous pixel
//!   `(x0 + (i + 0.5) * w / R, y0 + (j + 0.5) * h / R)`).
//! - **Ground truth and mask of the crop**: bilinear (half-pixel centres, edge-clamped, the
//!   same sample positions as the rays) and nearest samples of the view's image and mask.
//! - **RGB prior input** ([`render_rgb_input`]): with `paste_on_ground_truth` only the rays
//!   inside the crop's mask are rendered and scattered into the crop, whose other pixels are
//!   the ground truth (`render * m + gt * (1 - m)`, the reference); with `render_only` every
//!   crop pixel is rendered. Either way the autodiff graph to the field is kept.
//! - **Normal-map prior input** ([`render_normal_input`]): the whole crop is rendered at
//!   `R / normal_render_divisor`, its normals come from the configured source (plane fit to
//!   the rendered z-depth with the crop's intrinsics, or density-gradient normals), the image
//!   `(n + 1) / 2` is upsampled bilinearly to `R x R`. The plane-fit window keeps the
//!   preset's physical size: `kernel * downsample` training pixels become
//!   `kernel * downsample * Rn / box_size` crop pixels (odd, at least 3), fitted at the
//!   crop's own resolution.
//!
//! Guidance crops are rendered at the stratified bin centres (no jitter), so that a step is
//! a deterministic function of the field, the view and the step's seed.

use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};
use burn::tensor::{Device, Tensor, TensorData};
use gb_core::{RgbImage, TensorValuesError};
use gb_diffusion::distill::prior_input::bilinear_resize;
use gb_diffusion::distill::{LatentEncoder, PriorInputMode};
use gb_nerf::field::NerfField;
use gb_nerf::render::image::{ImageSettings, NormalSource};
use gb_nerf::render::rays::{all_pixels, crop_camera, crop_pixels};
use gb_nerf::render::{
    density_gradient_normals, depth_to_normals, render_samples, render_samples_appearance_only,
    Intrinsics, PlaneFitConfig,
};
use gb_nerf::sampler::RayBatch;
use gb_nerf::scene::{Camera, Mask};
use gb_nerf::train::data::TrainView;
use rand_chacha::ChaCha8Rng;

use crate::error::InpaintError;

/// The crop of one training view (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct CropGeometry {
    /// `(x0, y0, x1, y1)`, exclusive ends, in training-resolution pixels.
    pub bbox: (usize, usize, usize, usize),
    /// The crop's square resolution `R` (the prior's).
    pub resolution: usize,
    /// The view's camera (training resolution).
    pub view_camera: Camera,
    /// The mask sampled (nearest) at the `R x R` crop pixels, row-major.
    pub mask: Vec<bool>,
    /// Row-major indices of the crop pixels inside the mask.
    pub masked: Vec<usize>,
}

impl CropGeometry {
    /// The crop of `view` at resolution `resolution` with `margin`; `None` when the view
    /// has no mask or an empty one.
    pub fn new(view: &TrainView, margin: f32, resolution: usize) -> Option<Self> {
        let mask = view.mask.as_ref()?;
        if mask.width != view.image.width || mask.height != view.image.height {
            return None;
        }
        let bbox = grown_bbox(mask, margin)?;
        let (w, h) = (mask.width, mask.height);
        let r = resolution;
        let mut crop_mask = Vec::with_capacity(r * r);
        for [px, py] in crop_pixels(bbox, r, r) {
            let x = (px.floor() as usize).min(w - 1);
            let y = (py.floor() as usize).min(h - 1);
            crop_mask.push(mask.data[y * w + x]);
        }
        let masked: Vec<usize> = crop_mask
            .iter()
            .enumerate()
            .filter_map(|(i, m)| m.then_some(i))
            .collect();
        if masked.is_empty() {
            return None;
        }
        Some(Self {
            bbox,
            resolution: r,
            view_camera: view.camera.clone(),
            mask: crop_mask,
            masked,
        })
    }

    /// The virtual camera whose `res x res` image is the crop.
    pub fn camera(&self, res: usize) -> Camera {
        crop_camera(&self.view_camera, self.bbox, res, res)
    }

    /// The crop's mask as a `[1, 1, R, R]` tensor of 0/1 on `device`.
    pub fn mask_tensor(&self, device: &Device) -> Tensor<4> {
        let r = self.resolution;
        let v: Vec<f32> = self.mask.iter().map(|m| f32::from(u8::from(*m))).collect();
        Tensor::from_data(TensorData::new(v, [1, 1, r, r]), device)
    }

    /// The preset's plane fit carried over to a crop rendered at `res` (module docs).
    pub fn plane_fit_for(&self, cfg: PlaneFitConfig, res: usize) -> PlaneFitConfig {
        let (x0, y0, x1, y1) = self.bbox;
        let size = 0.5 * ((x1 - x0) + (y1 - y0)) as f32;
        let window = (cfg.kernel.max(1) * cfg.downsample.max(1)) as f32 * res as f32 / size;
        let k = (window.round() as usize).max(3);
        PlaneFitConfig {
            kernel: k | 1,
            downsample: 1,
        }
    }
}

/// The mask's bounding box `(x0, y0, x1, y1)` (exclusive ends) grown by `margin` of its
/// size on each side and clamped to the image; `None` for an empty mask.
pub fn grown_bbox(mask: &Mask, margin: f32) -> Option<(usize, usize, usize, usize)> {
    let (x0, y0, x1, y1) = mask.bbox()?;
    let grow = |lo: usize, hi: usize, size: usize| {
        let m = ((hi - lo) as f32 * margin).round() as usize;
        (lo.saturating_sub(m), (hi + m).min(size))
    };
    let (x0, x1) = grow(x0, x1, mask.width);
    let (y0, y1) = grow(y0, y1, mask.height);
    Some((x0, y0, x1, y1))
}

/// The bilinear samples (half-pixel centres, edge-clamped) of `image` at the crop's pixel
/// positions, as a `[1, 3, R, R]` tensor on `device`.
pub fn crop_image(
    image: &RgbImage,
    bbox: (usize, usize, usize, usize),
    r: usize,
    device: &Device,
) -> Tensor<4> {
    let mut chw = vec![0.0f32; 3 * r * r];
    for (k, [px, py]) in crop_pixels(bbox, r, r).into_iter().enumerate() {
        let v = image.bilinear(px, py);
        for ch in 0..3 {
            chw[ch * r * r + k] = v[ch];
        }
    }
    Tensor::from_data(TensorData::new(chw, [1, 3, r, r]), device)
}

/// The crop's mask at latent resolution `[1, 1, R/f, R/f]` (nearest, as diffusers'
/// inpainting pipeline downsamples it), on `device`.
pub fn latent_mask(mask: Tensor<4>, factor: usize) -> Tensor<4> {
    let r = mask.dims()[2];
    let size = r / factor.max(1);
    let mut options = InterpolateOptions::new(InterpolateMode::Nearest);
    options.align_corners = false;
    interpolate(mask, options.with_output_size([size, size]))
}

/// The latents of the masked crop: `encode((image * 2 - 1) * (1 - mask))`, without a graph.
pub fn masked_image_latents(
    encoder: &dyn LatentEncoder,
    image: Tensor<4>,
    mask: &Tensor<4>,
) -> Result<Tensor<4>, InpaintError> {
    let keep = mask.ones_like() - mask.clone();
    let masked = image.mul_scalar(2.0).sub_scalar(1.0) * keep.repeat_dim(1, 3);
    Ok(encoder.encode(masked)?.inner())
}

/// What rendering needs from the trainer.
#[derive(Clone, Copy)]
pub struct RenderContext<'a> {
    /// The field (autodiff device).
    pub field: &'a NerfField,
    /// How rays are cast, sampled and composited: the trainer's image settings (its chunk
    /// size is not used here).
    pub settings: ImageSettings<'a>,
    /// Whether the RGB prior input's graph reaches only the colour head (the method's
    /// `rgb_moves_geometry = false`); the normal map always reaches the geometry.
    pub rgb_appearance_only: bool,
}

impl RenderContext<'_> {
    /// The ray of `camera` through the continuous pixel `pixel`, within the scene's bounds.
    pub fn ray_through(&self, camera: &Camera, pixel: [f32; 2]) -> RayBatch {
        self.settings.rays(camera, &[pixel])
    }
}

/// The reconstruction's disparity loss ([`gb_nerf::train::losses::disparity_loss`]) of
/// `disparity [n]` toward depths given as `(near / depth, valid)` pairs, flattened.
pub fn disparity_toward(disparity: Tensor<1>, pairs: Vec<f32>, near: f32) -> Tensor<1> {
    let n = pairs.len() / 2;
    let pairs = Tensor::<2>::from_data(TensorData::new(pairs, [n, 2]), &disparity.device());
    let gt = pairs.clone().slice([0..n, 0..1]).reshape([n]);
    let valid = pairs.slice([0..n, 1..2]).reshape([n]);
    gb_nerf::train::losses::disparity_loss(disparity, gt, valid, near)
}

/// The `(near / depth, valid)` pair of a target depth (invalid when not a positive number).
pub fn disparity_pair(near: f32, depth: f32) -> [f32; 2] {
    if depth.is_finite() && depth > 0.0 {
        [near / depth, 1.0]
    } else {
        [0.0, 0.0]
    }
}

/// The per-view constants of the RGB guidance, computed once per view.
#[derive(Debug, Clone)]
pub struct ViewGuidance {
    /// The crop.
    pub geometry: CropGeometry,
    /// Ground-truth crop `[1, 3, R, R]` in `[0, 1]` (plain device).
    pub ground_truth: Tensor<4>,
    /// The crop's mask `[1, 1, R, R]` (plain device).
    pub mask: Tensor<4>,
    /// The mask at latent resolution (plain device).
    pub mask_latent: Tensor<4>,
    /// Latents of the masked ground-truth crop (the RGB guidance's conditioning).
    pub masked_image_latents: Tensor<4>,
}

impl ViewGuidance {
    /// Computes the constants of `view` (training view index `index`, for errors).
    pub fn new(
        index: usize,
        view: &TrainView,
        margin: f32,
        resolution: usize,
        encoder: &dyn LatentEncoder,
        device: &Device,
    ) -> Result<Self, InpaintError> {
        let geometry = CropGeometry::new(view, margin, resolution).ok_or_else(|| {
            InpaintError::Distill(gb_diffusion::distill::DistillError::EmptyMask(format!(
                "of training view {index}"
            )))
        })?;
        let ground_truth = crop_image(&view.image, geometry.bbox, resolution, device);
        let mask = geometry.mask_tensor(device);
        let mask_latent = latent_mask(mask.clone(), encoder.downsample_factor());
        let masked_image_latents = masked_image_latents(encoder, ground_truth.clone(), &mask)?;
        Ok(Self {
            geometry,
            ground_truth,
            mask,
            mask_latent,
            masked_image_latents,
        })
    }
}

/// Renders `pixels` (continuous coordinates of `camera`) with the autodiff graph: colour
/// `[N, 3]`, z-depth `[N]` and, for density-gradient normals, camera-space normals `[N, 3]`.
fn render_pixels(
    ctx: &RenderContext<'_>,
    camera: &Camera,
    pixels: &[[f32; 2]],
    want_normals: bool,
    appearance_only: bool,
) -> Result<(Tensor<2>, Tensor<1>, Option<Tensor<2>>), TensorValuesError> {
    let rays = ctx.settings.rays(camera, pixels);
    let samples = ctx.settings.samples::<ChaCha8Rng>(ctx.field, &rays, None)?;
    let out = if appearance_only {
        render_samples_appearance_only(ctx.field, &samples, ctx.settings.background)
    } else {
        render_samples(ctx.field, &samples, ctx.settings.background)
    };
    let normals = match (want_normals, ctx.settings.normals) {
        (true, NormalSource::DensityGradient { step }) => Some(density_gradient_normals(
            ctx.field,
            ctx.settings.space,
            &samples,
            out.weights.clone(),
            out.opacity.clone(),
            &camera.c2w,
            step,
        )),
        _ => None,
    };
    Ok((out.rgb, out.depth, normals))
}

/// `[N, C]` values of the rows `rows` of an `R x R` image, other rows zero, as
/// `[1, C, R, R]` (differentiable: [`gb_core::gather_rows`], whose backward is fast on every
/// backend).
fn scatter_rows(values: Tensor<2>, rows: &[usize], r: usize) -> Tensor<4> {
    let device = values.device();
    let [n, c] = values.dims();
    let mut map = vec![n as i64; r * r];
    for (k, &row) in rows.iter().enumerate() {
        map[row] = k as i64;
    }
    let padded = Tensor::cat(vec![values, Tensor::zeros([1, c], &device)], 0);
    let dense = gb_core::gather_rows(padded, gb_core::row_indices(map, &device));
    dense.reshape([r, r, c]).permute([2, 0, 1]).unsqueeze_dim(0)
}

/// Moves a constant tensor onto the autodiff device of `like` when needed.
fn like_device(x: Tensor<4>, like: &Tensor<4>) -> Tensor<4> {
    if like.is_autodiff() && !x.is_autodiff() {
        x.autodiff()
    } else {
        x
    }
}

/// The RGB prior input `[1, 3, R, R]` in `[0, 1]` (module docs), and the number of rays
/// rendered. Errors when early ray termination cannot read the field's densities.
pub fn render_rgb_input(
    ctx: &RenderContext<'_>,
    view: &ViewGuidance,
    mode: PriorInputMode,
) -> Result<(Tensor<4>, usize), TensorValuesError> {
    let g = &view.geometry;
    let r = g.resolution;
    let camera = g.camera(r);
    let grid = all_pixels(r, r);
    match mode {
        PriorInputMode::RenderOnly => {
            let (rgb, _, _) = render_pixels(ctx, &camera, &grid, false, ctx.rgb_appearance_only)?;
            let image = rgb.reshape([r, r, 3]).permute([2, 0, 1]).unsqueeze_dim(0);
            Ok((image, r * r))
        }
        PriorInputMode::PasteOnGroundTruth => {
            let pixels: Vec<[f32; 2]> = g.masked.iter().map(|&i| grid[i]).collect();
            let (rgb, _, _) = render_pixels(ctx, &camera, &pixels, false, ctx.rgb_appearance_only)?;
            let inside = scatter_rows(rgb, &g.masked, r);
            let keep = view.mask.ones_like() - view.mask.clone();
            let outside = like_device(view.ground_truth.clone() * keep.repeat_dim(1, 3), &inside);
            Ok((inside + outside, pixels.len()))
        }
    }
}

/// The normal-map prior input `[1, 3, R, R]` = `(n + 1) / 2` (module docs), and the number
/// of rays rendered. Errors when early ray termination cannot read the field's densities.
pub fn render_normal_input(
    ctx: &RenderContext<'_>,
    view: &ViewGuidance,
    divisor: usize,
) -> Result<(Tensor<4>, usize), TensorValuesError> {
    let g = &view.geometry;
    let r = g.resolution;
    let rn = (r / divisor.max(1)).max(4).min(r);
    let camera = g.camera(rn);
    let grid = all_pixels(rn, rn);
    let want_gradient = matches!(ctx.settings.normals, NormalSource::DensityGradient { .. });
    let (_, depth, normals) = render_pixels(ctx, &camera, &grid, want_gradient, false)?;
    let plane_fit = |cfg: PlaneFitConfig| {
        depth_to_normals(
            depth.clone().reshape([rn, rn]),
            Intrinsics::of(&camera),
            g.plane_fit_for(cfg, rn),
        )
    };
    let normals: Tensor<3> = match (ctx.settings.normals, normals) {
        (NormalSource::DensityGradient { .. }, Some(n)) => n.reshape([rn, rn, 3]),
        (NormalSource::PlaneFit(cfg), _) => plane_fit(cfg),
        // not reached: density-gradient normals are always rendered above
        (NormalSource::DensityGradient { .. }, None) => plane_fit(PlaneFitConfig::default()),
    };
    let image = normals
        .add_scalar(1.0)
        .mul_scalar(0.5)
        .permute([2, 0, 1])
        .unsqueeze_dim::<4>(0);
    let image = if rn == r {
        image
    } else {
        bilinear_resize(image, r, r)
    };
    Ok((image, rn * rn))
}

/// True when `view` has a mask with at least one pixel at its own resolution (a view the
/// guidance can crop).
pub fn has_guidance_crop(view: &TrainView) -> bool {
    view.mask.as_ref().is_some_and(|m: &Mask| {
        m.width == view.image.width && m.height == view.image.height && m.bbox().is_some()
    })
}
