//! gb-nerf: the NeRF half of gb-nerf-rs.
//!
//! - [`scene`]: the scene model (views, pinhole cameras, masks, depth, normals, splits,
//!   bounds) and its loaders.
//! - [`field`]: radiance fields (instant-ngp hash grid, vanilla positional-encoding MLP).
//! - [`sampler`]: scene parameterisation, stratified sampling, occupancy grid.
//! - [`render`]: rays for any pixel set, stable volume rendering, depth and normal maps.
//! - [`train`]: configuration, presets, the reconstruction trainer and checkpoints.

pub mod field;
pub mod render;
pub mod sampler;
pub mod scene;
pub mod train;
