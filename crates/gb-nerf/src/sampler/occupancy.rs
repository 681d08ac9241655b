//! An occupancy grid over the field's `[0, 1]^3` coordinates (instant-ngp style): a cell is
//! occupied while its running density estimate exceeds a threshold; samples in empty cells
//! are never evaluated.
//!
//! Update rule: every `update_every` steps after `warmup_steps`, `cells_per_update` cells
//! (all when 0) get `d <- max(decay * d, sigma(random point in the cell))`, and
//! `occupied = d > density_threshold`, where the threshold is the density at which a
//! typical sample interval reaches `opacity_threshold` opacity.

use gb_core::{read_f32, TensorValuesError};
use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::field::NerfField;

/// Settings of the occupancy grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OccupancyConfig {
    /// Cells per side.
    pub resolution: usize,
    /// Steps between updates.
    pub update_every: usize,
    /// Steps before the first update (every cell is occupied until then).
    pub warmup_steps: usize,
    /// Decay of the running density per update.
    pub decay: f32,
    /// Opacity of a typical sample interval below which a cell counts as empty.
    pub opacity_threshold: f32,
    /// Cells refreshed per update (0: all).
    pub cells_per_update: usize,
    /// Transmittance below which a ray stops being evaluated (early ray termination,
    /// nerfacc's `early_stop_eps`, whose default is 1e-4; 0: off, the default). See
    /// [`crate::render::termination`]: no preset enables it, because within their step
    /// counts the surfaces stay partly transparent and it skips almost nothing.
    #[serde(default)]
    pub early_stop_eps: f32,
}

/// The grid (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyGrid {
    /// Cells per side.
    pub resolution: usize,
    /// Running density estimate per cell (x fastest).
    pub density: Vec<f32>,
    /// Occupancy per cell.
    pub occupied: Vec<bool>,
    /// Density above which a cell is occupied.
    pub density_threshold: f32,
    /// Transmittance below which a ray stops being evaluated (0: off).
    pub early_stop_eps: f32,
}

impl OccupancyGrid {
    /// A grid with every cell occupied, without early ray termination.
    pub fn new(resolution: usize, density_threshold: f32) -> Self {
        let n = resolution.max(1).pow(3);
        Self {
            resolution: resolution.max(1),
            density: vec![0.0; n],
            occupied: vec![true; n],
            density_threshold,
            early_stop_eps: 0.0,
        }
    }

    /// The threshold density for an opacity threshold over a typical interval length.
    pub fn threshold_for(opacity_threshold: f32, typical_delta: f32) -> f32 {
        let a = opacity_threshold.clamp(1e-6, 0.999);
        -(1.0 - a).ln() / typical_delta.max(1e-12)
    }

    /// Index of the cell containing field point `q`.
    pub fn cell(&self, q: [f32; 3]) -> usize {
        let r = self.resolution;
        let c = q.map(|v| ((v.clamp(0.0, 1.0) * r as f32) as usize).min(r - 1));
        c[0] + c[1] * r + c[2] * r * r
    }

    /// Whether field point `q` lies in an occupied cell.
    pub fn is_occupied(&self, q: [f32; 3]) -> bool {
        self.occupied[self.cell(q)]
    }

    /// Fraction of occupied cells.
    pub fn occupied_fraction(&self) -> f32 {
        self.occupied.iter().filter(|o| **o).count() as f32 / self.occupied.len() as f32
    }

    /// Refreshes `cells` random cells (all when 0 or more than the grid) with densities of
    /// `field` (use a no-grad copy), decaying the others' estimates. Errors when the field's
    /// densities are not `f32` values (the grid is then left partly updated: a fatal error).
    pub fn update<R: Rng>(
        &mut self,
        field: &NerfField,
        cells: usize,
        decay: f32,
        rng: &mut R,
    ) -> Result<(), TensorValuesError> {
        let r = self.resolution;
        let total = self.density.len();
        let chosen: Vec<usize> = if cells == 0 || cells >= total {
            (0..total).collect()
        } else {
            (0..cells).map(|_| rng.random_range(0..total)).collect()
        };
        for d in self.density.iter_mut() {
            *d *= decay;
        }
        for chunk in chosen.chunks(1 << 15) {
            let pts: Vec<[f32; 3]> = chunk
                .iter()
                .map(|&c| {
                    let idx = [c % r, (c / r) % r, c / (r * r)];
                    idx.map(|i| (i as f32 + rng.random::<f32>()) / r as f32)
                })
                .collect();
            let sigma = read_f32(field.density(&pts), "occupancy-grid densities")?;
            for (&c, s) in chunk.iter().zip(sigma) {
                let s = if s.is_finite() { s } else { f32::MAX };
                self.density[c] = self.density[c].max(s);
            }
        }
        for (o, d) in self.occupied.iter_mut().zip(&self.density) {
            *o = *d > self.density_threshold;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn threshold_matches_opacity_definition() {
        let thr = OccupancyGrid::threshold_for(0.01, 0.02);
        assert!((1.0 - (-thr * 0.02f32).exp() - 0.01).abs() < 1e-6);
    }

    #[test]
    fn cells_index_x_fastest() {
        let g = OccupancyGrid::new(4, 1.0);
        assert_eq!(g.cell([0.0, 0.0, 0.0]), 0);
        assert_eq!(g.cell([0.3, 0.0, 0.0]), 1);
        assert_eq!(g.cell([0.0, 0.3, 0.0]), 4);
        assert_eq!(g.cell([1.0, 1.0, 1.0]), 63);
    }
}
