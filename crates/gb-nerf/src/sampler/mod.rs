//! Ray sampling: stratified samples between each ray's bounds, and an occupancy grid that
//! skips the field evaluations of samples in empty space.

pub mod occupancy;
pub mod space;
pub mod stratified;

use serde::{Deserialize, Serialize};

pub use occupancy::{OccupancyConfig, OccupancyGrid};
pub use space::{SceneSpace, Spacing};
pub use stratified::{normalized_positions, sample_rays};

/// A batch of rays `o + t d`. `d` is scaled so that its camera-space z component is -1,
/// which makes `t` the z-depth of the scene model.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RayBatch {
    /// Ray origins (world).
    pub origins: Vec<[f32; 3]>,
    /// Ray directions (world, camera-z normalised, not unit length).
    pub dirs: Vec<[f32; 3]>,
    /// Start of the sampled interval per ray.
    pub near: Vec<f32>,
    /// End of the sampled interval per ray (`near >= far`: the ray misses the volume).
    pub far: Vec<f32>,
}

impl RayBatch {
    /// Appends the rays of `other`.
    pub fn append(&mut self, other: RayBatch) {
        self.origins.extend(other.origins);
        self.dirs.extend(other.dirs);
        self.near.extend(other.near);
        self.far.extend(other.far);
    }

    /// Number of rays.
    pub fn len(&self) -> usize {
        self.origins.len()
    }

    /// Whether the batch holds no ray.
    pub fn is_empty(&self) -> bool {
        self.origins.is_empty()
    }
}

/// Sampler settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SamplerConfig {
    /// Stratified samples per ray (the dense, uniform budget).
    pub samples_per_ray: usize,
    /// Empty-space skipping; `None` evaluates every sample.
    pub occupancy: Option<OccupancyConfig>,
}

/// The samples of a ray batch, laid out densely as `[rays, samples]` for compositing; only
/// the samples listed in `slots` are evaluated by the field, the others have zero density.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SampleSet {
    /// Number of rays.
    pub rays: usize,
    /// Samples per ray.
    pub samples: usize,
    /// `rays * samples` sample distances (z-depth).
    pub t: Vec<f32>,
    /// `rays * samples` interval lengths in world units.
    pub delta: Vec<f32>,
    /// Dense index `ray * samples + i` of every evaluated sample.
    pub slots: Vec<u32>,
    /// Field coordinates of every evaluated sample.
    pub points: Vec<[f32; 3]>,
    /// World positions of every evaluated sample.
    pub world: Vec<[f32; 3]>,
    /// Unit world view direction of every evaluated sample.
    pub view_dirs: Vec<[f32; 3]>,
}

impl SampleSet {
    /// Field evaluations per ray (the dense budget is `samples`).
    pub fn evaluations_per_ray(&self) -> f32 {
        if self.rays == 0 {
            0.0
        } else {
            self.slots.len() as f32 / self.rays as f32
        }
    }
}
