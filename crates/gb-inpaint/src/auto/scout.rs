//! Surface points for the pseudo-holes of a scene that brings none.
//!
//! The pseudo-holes sit on observed surfaces ([`super::pseudo_hole`]), found from the
//! scene's COLMAP points or its depth maps. A real capture may have neither: SPIn-NeRF's
//! `statue` ships LLFF poses without `sparse/0`. Then a short unguided **scout** field is
//! trained on the scene (the object's masks withheld, as `--method none` trains), and its
//! depth on the grid of [`super::pseudo_hole::SURFACE_STRIDE`] pixels that the depth maps are
//! read on, where the ray is opaque and outside the mask, becomes the scene's sparse points
//! for the placement only. The depth is
//! the weights' mean sample depth, not the rendered depth, which adds the missing opacity at
//! the far bound. The run and the trials never see these points.

use std::time::Instant;

use gb_core::Devices;
use gb_nerf::scene::colmap::SparseDepth;
use gb_nerf::scene::{Scene, Split};
use gb_nerf::train::{DepthSupervision, NerfConfig, Trainer};
use serde::{Deserialize, Serialize};

use super::pseudo_hole::grid_outside_mask;
use crate::error::InpaintError;

/// The least accumulated opacity of a ray whose depth is a surface point.
pub const MIN_OPACITY: f32 = 0.5;

/// Where the pseudo-holes' surface points came from (`metrics.json`'s `auto.surface`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case", tag = "from")]
pub enum SurfaceSource {
    /// The scene's COLMAP points or depth maps.
    #[default]
    Scene,
    /// A scout field's rendered depth (module docs).
    Scout {
        /// Its training steps.
        steps: usize,
        /// The surface points it gave.
        points: usize,
        /// Its wall time (training and the depth renders), seconds.
        seconds: f64,
    },
}

/// Whether `scene` brings surface points of its own outside the masks: sparse points or
/// depth maps of its training views ([`super::pseudo_hole::has_surface_points`]).
pub fn has_surface(scene: &Scene) -> bool {
    super::pseudo_hole::has_surface_points(scene)
}

/// `scene` with the scout field's depth as the sparse points of its training views (module
/// docs): a field of `config` trained `steps` steps on colour alone, on `devices`.
pub fn scouted(
    scene: &Scene,
    config: &NerfConfig,
    devices: &Devices,
    steps: usize,
    progress: bool,
) -> Result<(Scene, SurfaceSource), InpaintError> {
    let start = Instant::now();
    let mut config = config.clone();
    config.train.steps = steps.max(1);
    config.train.depth = DepthSupervision::None;
    let mut trainer = Trainer::new(scene, config, devices.clone())?;
    trainer.fit(None, progress)?;
    let mut out = scene.clone();
    let mut points = 0;
    for view in scene.split(Split::Train) {
        let pixels = grid_outside_mask(view);
        let profiles = trainer.ray_profiles(&view.camera, &pixels)?;
        let found: Vec<SparseDepth> = profiles
            .iter()
            .filter(|p| p.opacity >= MIN_OPACITY)
            .filter_map(|p| {
                let depth = surface_depth(&p.t, &p.weights)?;
                Some(SparseDepth {
                    x: p.pixel[0],
                    y: p.pixel[1],
                    depth,
                    error: 0.0,
                })
            })
            .collect();
        points += found.len();
        out.sparse_depth.insert(view.name.clone(), found);
    }
    if points == 0 {
        return Err(InpaintError::Spec {
            field: "lambda_rgb / lambda_normal = \"auto\"".into(),
            reason: format!(
                "the scene has no COLMAP points or depth maps outside the masks, and a scout \
                 field of {} steps rendered no opaque surface there to place a pseudo-hole on",
                steps.max(1)
            ),
        });
    }
    let source = SurfaceSource::Scout {
        steps: steps.max(1),
        points,
        seconds: start.elapsed().as_secs_f64(),
    };
    tracing::info!(?source, "auto weights: surface points from a scout field");
    Ok((out, source))
}

/// The weights' mean of the sample depths `t` (`None` for a ray that hits nothing or a
/// non-finite result).
fn surface_depth(t: &[f32], weights: &[f32]) -> Option<f32> {
    let total: f32 = weights.iter().sum();
    let depth = t.iter().zip(weights).map(|(t, w)| t * w).sum::<f32>() / total;
    (total > 0.0 && depth.is_finite() && depth > 0.0).then_some(depth)
}
