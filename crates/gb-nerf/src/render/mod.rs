//! Rendering: rays through any pixel set, field evaluation on the samples that matter, and
//! stable volume compositing into colour, depth, disparity, opacity and normals.

pub mod image;
pub mod normals;
pub mod profile;
pub mod rays;
pub mod termination;
pub mod volume;

use burn::tensor::{Tensor, TensorData};
use gb_core::TensorValuesError;
use rand::Rng;

use crate::field::NerfField;
use crate::sampler::{sample_rays, OccupancyGrid, RayBatch, SampleSet, SceneSpace};

pub use image::{render_image, ImageRender};
pub use normals::{depth_to_normals, normals_to_image, Intrinsics, PlaneFitConfig};
pub use profile::{render_profiles, RayProfile};
pub use volume::{composite, Background, VolumeOutput};

/// Expands per-sample values `[M, C]` of the evaluated samples to the dense `[R * S, C]`
/// layout, with zeros for the skipped samples (differentiable: [`gb_core::gather_rows`], whose
/// backward is fast on every backend).
fn expand_dense<const D: usize>(values: Tensor<D>, samples: &SampleSet) -> Tensor<D> {
    let device = values.device();
    let m = samples.slots.len();
    let dense = samples.rays * samples.samples;
    let mut map = vec![m as i64; dense];
    for (k, slot) in samples.slots.iter().enumerate() {
        map[*slot as usize] = k as i64;
    }
    let mut zero_shape = values.dims();
    zero_shape[0] = 1;
    let padded = Tensor::cat(vec![values, Tensor::zeros(zero_shape, &device)], 0);
    gb_core::gather_rows(padded, gb_core::row_indices(map, &device))
}

/// Most samples evaluated by one field call. A training batch of the `paper` preset (4096
/// rays x 128 samples) in one call needs a 512 MB hash-grid intermediate and more compute
/// workgroups than a dispatch may hold on Vulkan (65,535 per dimension), so larger sample
/// sets are evaluated in chunks of this size and concatenated (still differentiable).
pub const FIELD_CHUNK_SAMPLES: usize = 1 << 16;

/// `field.forward` over `points`/`dirs` in chunks of [`FIELD_CHUNK_SAMPLES`].
fn forward_chunked(
    field: &NerfField,
    points: &[[f32; 3]],
    dirs: &[[f32; 3]],
    appearance_only: bool,
) -> (Tensor<1>, Tensor<2>) {
    if points.len() <= FIELD_CHUNK_SAMPLES {
        return field.forward_with(points, dirs, appearance_only);
    }
    let (sigmas, rgbs): (Vec<_>, Vec<_>) = points
        .chunks(FIELD_CHUNK_SAMPLES)
        .zip(dirs.chunks(FIELD_CHUNK_SAMPLES))
        .map(|(p, d)| field.forward_with(p, d, appearance_only))
        .unzip();
    (Tensor::cat(sigmas, 0), Tensor::cat(rgbs, 0))
}

/// Evaluates `field` on the evaluated samples of `samples` and composites them.
pub fn render_samples(
    field: &NerfField,
    samples: &SampleSet,
    background: Background,
) -> VolumeOutput {
    render_samples_with(field, samples, background, Trainable::All)
}

/// [`render_samples`] with the density detached from the graph: a loss on the colour moves
/// the field's colour, and its geometry only through the features the two share. For a
/// target that knows a surface's colour but not where the surface is (a reference view,
/// `gb_inpaint::reference`).
pub fn render_samples_fixed_geometry(
    field: &NerfField,
    samples: &SampleSet,
    background: Background,
) -> VolumeOutput {
    render_samples_with(field, samples, background, Trainable::NotDensity)
}

/// [`render_samples`] with everything but the colour head detached: a loss on the colour
/// moves neither the density nor the encoding and features it shares with the density.
pub fn render_samples_appearance_only(
    field: &NerfField,
    samples: &SampleSet,
    background: Background,
) -> VolumeOutput {
    render_samples_with(field, samples, background, Trainable::AppearanceOnly)
}

/// Which part of the field a render's graph reaches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Trainable {
    All,
    NotDensity,
    AppearanceOnly,
}

fn render_samples_with(
    field: &NerfField,
    samples: &SampleSet,
    background: Background,
    trainable: Trainable,
) -> VolumeOutput {
    let device = field.device();
    let (r, s) = (samples.rays, samples.samples);
    let (sigma, rgb) = forward_chunked(
        field,
        &samples.points,
        &samples.view_dirs,
        trainable == Trainable::AppearanceOnly,
    );
    let sigma = expand_dense(sigma, samples).reshape([r, s]);
    let sigma = if trainable == Trainable::NotDensity {
        sigma.detach()
    } else {
        sigma
    };
    let rgb = expand_dense(rgb, samples).reshape([r, s, 3]);
    let t = Tensor::<2>::from_data(TensorData::new(samples.t.clone(), [r, s]), &device);
    let delta = Tensor::<2>::from_data(TensorData::new(samples.delta.clone(), [r, s]), &device);
    composite(sigma, rgb, t, delta, background)
}

/// The samples of `rays` that the field evaluates: stratified (jittered when `rng` is
/// given), without the empty cells of `occupancy` and, with its `early_stop_eps`, without
/// the samples behind where each ray's transmittance runs out ([`termination`]; densities
/// that cannot be read back for it are the error).
pub fn sample_and_prune<R: Rng>(
    field: &NerfField,
    rays: &RayBatch,
    space: &SceneSpace,
    samples_per_ray: usize,
    occupancy: Option<&OccupancyGrid>,
    rng: Option<&mut R>,
) -> Result<SampleSet, TensorValuesError> {
    let samples = sample_rays(rays, space, samples_per_ray, occupancy, rng);
    match occupancy {
        Some(grid) => termination::prune_occluded(field, samples, grid.early_stop_eps),
        None => Ok(samples),
    }
}

/// Samples `rays` (jittered when `rng` is given, skipping empty cells of `occupancy` and,
/// with its `early_stop_eps`, the samples behind where each ray's transmittance runs out:
/// [`termination`]) and renders them. The outputs keep the autodiff graph of `field`.
pub fn render_rays<R: Rng>(
    field: &NerfField,
    space: &SceneSpace,
    rays: &RayBatch,
    samples_per_ray: usize,
    occupancy: Option<&OccupancyGrid>,
    background: Background,
    rng: Option<&mut R>,
) -> Result<(VolumeOutput, SampleSet), TensorValuesError> {
    let samples = sample_and_prune(field, rays, space, samples_per_ray, occupancy, rng)?;
    let out = render_samples(field, &samples, background);
    Ok((out, samples))
}

/// Camera-space normals `[R, 3]` from the density gradient (central finite differences with
/// world step `step` at every evaluated sample, `n = -grad sigma / |grad sigma|`), averaged
/// with the compositing weights `[R, S]` and rotated by the transpose of the camera rotation
/// `c2w`. The missing opacity adds the background normal `(0, 0, 1)`; see
/// [`normals`] for the convention.
pub fn density_gradient_normals(
    field: &NerfField,
    space: &SceneSpace,
    samples: &SampleSet,
    weights: Tensor<2>,
    opacity: Tensor<1>,
    c2w: &[[f32; 4]; 3],
    step: f32,
) -> Tensor<2> {
    let device = field.device();
    let (r, s) = (samples.rays, samples.samples);
    let m = samples.world.len();
    let mut pts = Vec::with_capacity(6 * m);
    for axis in 0..3 {
        for sign in [1.0f32, -1.0] {
            for (p, q) in samples.world.iter().zip(&samples.points) {
                let mut o = *p;
                o[axis] += sign * step;
                pts.push(space.to_field(o).unwrap_or(*q));
            }
        }
    }
    let d = field.density(&pts).reshape([6, m]);
    let grad: Vec<Tensor<2>> = (0..3)
        .map(|a| {
            (d.clone().narrow(0, 2 * a, 1) - d.clone().narrow(0, 2 * a + 1, 1)).reshape([m, 1])
        })
        .collect();
    let grad = Tensor::cat(grad, 1).mul_scalar(-0.5 / step); // [M, 3] = -grad
    let len = grad.clone().square().sum_dim(1).add_scalar(1e-20).sqrt();
    let n = grad / len;
    let n = expand_dense(n, samples).reshape([r, s, 3]);
    let n_world = (n * weights.unsqueeze_dim::<3>(2))
        .sum_dim(1)
        .reshape([r, 3]);
    let rot: Vec<f32> = (0..3)
        .flat_map(|i| (0..3).map(move |j| c2w[i][j]))
        .collect();
    let rot = Tensor::<2>::from_data(TensorData::new(rot, [3, 3]), &device);
    let n_cam = n_world.matmul(rot);
    let bg = Tensor::<2>::from_data(TensorData::new(vec![0.0f32, 0.0, 1.0], [1, 3]), &device);
    let n_cam = n_cam + opacity.neg().add_scalar(1.0).reshape([r, 1]) * bg;
    let len = n_cam.clone().square().sum_dim(1).add_scalar(1e-12).sqrt();
    n_cam / len
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sample set over the chunk size is evaluated in chunks that agree with one call.
    #[test]
    fn chunked_field_evaluation_matches_one_call() {
        let device = gb_core::BackendKind::Flex.device();
        let field = crate::field::tiny_hash_config().init(&device);
        let n = FIELD_CHUNK_SAMPLES + 1234;
        let pts: Vec<[f32; 3]> = (0..n)
            .map(|i| {
                let f = i as f32 / n as f32;
                [f, (f * 7.3).fract(), (f * 13.1).fract()]
            })
            .collect();
        let dirs = vec![[0.0, 0.6, -0.8]; n];
        let (s1, c1) = forward_chunked(&field, &pts, &dirs, false);
        let (s2, c2) = field.forward(&pts, &dirs);
        assert_eq!(s1.dims(), [n]);
        assert_eq!(c1.dims(), [n, 3]);
        let ds: f32 = (s1 - s2).abs().max().into_scalar();
        let dc: f32 = (c1 - c2).abs().max().into_scalar();
        assert!(
            ds <= 1e-5 && dc <= 1e-6,
            "sigma diff {ds}, colour diff {dc}"
        );
    }
}
