//! Whole-image rendering without autodiff, in ray chunks: colour, depth, opacity and
//! camera-space normals.

use burn::module::Module;
use burn::tensor::{Tensor, TensorData};
use gb_core::{f32_values, TensorValuesError};
use serde::{Deserialize, Serialize};

use super::normals::{depth_to_normals, Intrinsics, PlaneFitConfig};
use super::rays::{all_pixels, camera_rays};
use super::{density_gradient_normals, render_samples, sample_and_prune, Background};
use crate::field::NerfField;
use crate::sampler::{OccupancyGrid, RayBatch, SampleSet, SceneSpace};
use crate::scene::Camera;

/// Where normals come from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum NormalSource {
    /// Local plane fit to the rendered depth (MVIP-NeRF / GB-NeRF).
    PlaneFit(PlaneFitConfig),
    /// Central finite differences of the density, with this world-space step.
    DensityGradient {
        /// Finite-difference step in world units.
        step: f32,
    },
}

/// A rendered image.
#[derive(Debug, Clone)]
pub struct ImageRender {
    /// Colour.
    pub rgb: gb_core::RgbImage,
    /// Z-depth per pixel.
    pub depth: Vec<f32>,
    /// Accumulated opacity per pixel.
    pub opacity: Vec<f32>,
    /// Unit camera-space normals per pixel (see [`super::normals`]).
    pub normals: Vec<[f32; 3]>,
    /// Mean field evaluations per ray.
    pub evaluations_per_ray: f32,
}

/// Settings shared by image renders.
#[derive(Debug, Clone, Copy)]
pub struct ImageSettings<'a> {
    /// Scene parameterisation.
    pub space: &'a SceneSpace,
    /// Near bound.
    pub near: f32,
    /// Far bound.
    pub far: f32,
    /// Samples per ray.
    pub samples_per_ray: usize,
    /// Empty-space skipping.
    pub occupancy: Option<&'a OccupancyGrid>,
    /// Background.
    pub background: Background,
    /// Normal source.
    pub normals: NormalSource,
    /// Rays per chunk.
    pub chunk: usize,
}

impl ImageSettings<'_> {
    /// The rays of `camera` through the continuous pixels `pixels`, within these bounds.
    pub fn rays(&self, camera: &Camera, pixels: &[[f32; 2]]) -> RayBatch {
        camera_rays(camera, pixels, self.space, self.near, self.far)
    }

    /// The samples of `rays` in `field` with these settings' samples per ray and skipping,
    /// jittered by `rng` (none: the fixed positions an image render uses).
    pub fn samples<R: rand::Rng>(
        &self,
        field: &NerfField,
        rays: &RayBatch,
        rng: Option<&mut R>,
    ) -> Result<SampleSet, TensorValuesError> {
        sample_and_prune(
            field,
            rays,
            self.space,
            self.samples_per_ray,
            self.occupancy,
            rng,
        )
    }
}

/// Renders the rays of `camera` through `pixels` as an image render samples them (no
/// jitter, the settings' skipping), with `field`'s graph.
pub(crate) fn render_pixels(
    field: &NerfField,
    camera: &Camera,
    pixels: &[[f32; 2]],
    settings: &ImageSettings,
) -> Result<(super::VolumeOutput, SampleSet), TensorValuesError> {
    let rays = settings.rays(camera, pixels);
    let samples = settings.samples::<rand_chacha::ChaCha8Rng>(field, &rays, None)?;
    Ok((
        render_samples(field, &samples, settings.background),
        samples,
    ))
}

/// Renders every pixel of `camera` with a no-grad copy of `field`.
///
/// Errors when a rendered tensor does not hold `f32` values (a backend or precision surprise
/// is reported, never turned into an empty render).
pub fn render_image(
    field: &NerfField,
    camera: &Camera,
    settings: &ImageSettings,
) -> Result<ImageRender, TensorValuesError> {
    let field = field.valid();
    let pixels = all_pixels(camera.width, camera.height);
    let n = pixels.len();
    let mut rgb = Vec::with_capacity(n * 3);
    let mut depth = Vec::with_capacity(n);
    let mut opacity = Vec::with_capacity(n);
    let mut normals = Vec::with_capacity(n);
    let mut evals = 0usize;
    for chunk in pixels.chunks(settings.chunk.max(1)) {
        let (out, samples) = render_pixels(&field, camera, chunk, settings)?;
        evals += samples.slots.len();
        if let NormalSource::DensityGradient { step } = settings.normals {
            let nt = density_gradient_normals(
                &field,
                settings.space,
                &samples,
                out.weights.clone(),
                out.opacity.clone(),
                &camera.c2w,
                step,
            );
            let v = f32_values(nt.into_data(), "rendered normals")?;
            normals.extend(v.chunks(3).map(|c| [c[0], c[1], c[2]]));
        }
        rgb.extend(f32_values(out.rgb.into_data(), "rendered colour")?);
        depth.extend(f32_values(out.depth.into_data(), "rendered depth")?);
        opacity.extend(f32_values(out.opacity.into_data(), "rendered opacity")?);
    }
    if let NormalSource::PlaneFit(cfg) = settings.normals {
        let device = field.device();
        let d = Tensor::<2>::from_data(
            TensorData::new(depth.clone(), [camera.height, camera.width]),
            &device,
        );
        let v = f32_values(
            depth_to_normals(d, Intrinsics::of(camera), cfg).into_data(),
            "plane-fit normals",
        )?;
        normals = v.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
    }
    Ok(ImageRender {
        rgb: gb_core::RgbImage {
            width: camera.width,
            height: camera.height,
            data: rgb,
        },
        depth,
        opacity,
        normals,
        evaluations_per_ray: evals as f32 / n.max(1) as f32,
    })
}
