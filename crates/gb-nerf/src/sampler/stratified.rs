//! Stratified sampling along rays, with optional empty-space skipping.

use rand::Rng;

use super::{OccupancyGrid, RayBatch, SampleSet, SceneSpace, Spacing};

/// Estimated transmittance below which the rest of a ray is not evaluated.
pub const MIN_TRANSMITTANCE: f32 = 1e-4;

/// Each sample's position in its ray's normalised sampling coordinate `u` in `[0, 1]`
/// (near to far, uniform in `spacing`: distance or inverse distance), the coordinate in
/// which [`sample_rays`] spaces its bins evenly; every bin is `1 / samples` wide in it.
/// Rays that miss the volume get 0. Used by the distortion loss.
pub fn normalized_positions(rays: &RayBatch, samples: &SampleSet, spacing: Spacing) -> Vec<f32> {
    let s = samples.samples;
    let mut out = Vec::with_capacity(samples.t.len());
    for r in 0..samples.rays {
        let (t0, t1) = (rays.near[r], rays.far[r]);
        let hit = t0 < t1 && t0.is_finite() && t1.is_finite();
        for &t in &samples.t[r * s..(r + 1) * s] {
            let u = if !hit {
                0.0
            } else {
                match spacing {
                    Spacing::Linear => (t - t0) / (t1 - t0),
                    Spacing::InverseDepth => {
                        let (a, b) = (1.0 / t0.max(1e-12), 1.0 / t1.max(1e-12));
                        (a - 1.0 / t.max(1e-12)) / (a - b)
                    }
                }
            };
            out.push(if u.is_finite() {
                u.clamp(0.0, 1.0)
            } else {
                0.0
            });
        }
    }
    out
}

/// Samples `samples` stratified points per ray: the ray's interval is split into equal bins
/// (in distance, or in inverse distance for [`Spacing::InverseDepth`]); each sample lies at
/// a uniformly jittered position in its bin (`rng` given) or at the bin centre, and
/// represents the whole bin (`delta` = bin length in world units). Samples outside the
/// modelled volume, and, when `occupancy` is given, in cells it marks empty, are not
/// evaluated (zero density). With an occupancy grid the march also stops early: the
/// transmittance is estimated from the grid's running densities, and samples after it falls
/// below [`MIN_TRANSMITTANCE`] are not evaluated (they would carry weights below it).
pub fn sample_rays<R: Rng>(
    rays: &RayBatch,
    space: &SceneSpace,
    samples: usize,
    occupancy: Option<&OccupancyGrid>,
    mut rng: Option<&mut R>,
) -> SampleSet {
    let s = samples.max(1);
    let n = rays.len();
    let mut out = SampleSet {
        rays: n,
        samples: s,
        t: Vec::with_capacity(n * s),
        delta: Vec::with_capacity(n * s),
        ..Default::default()
    };
    let spacing = space.spacing();
    for r in 0..n {
        let (o, d) = (rays.origins[r], rays.dirs[r]);
        let dlen = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let unit = if dlen > 0.0 {
            d.map(|v| v / dlen)
        } else {
            [0.0, 0.0, -1.0]
        };
        let (t0, t1) = (rays.near[r], rays.far[r]);
        let hit = t0 < t1 && t0.is_finite() && t1.is_finite();
        // bin edges through a monotone map u in [0, 1] -> t
        let edge = |u: f32| -> f32 {
            match spacing {
                Spacing::Linear => t0 + (t1 - t0) * u,
                Spacing::InverseDepth => {
                    let (a, b) = (1.0 / t0.max(1e-12), 1.0 / t1.max(1e-12));
                    1.0 / (a + (b - a) * u)
                }
            }
        };
        let mut log_t = 0.0f32;
        for i in 0..s {
            if !hit {
                out.t.push(t1.max(t0).max(0.0));
                out.delta.push(0.0);
                continue;
            }
            let (e0, e1) = (edge(i as f32 / s as f32), edge((i + 1) as f32 / s as f32));
            let u = match rng.as_deref_mut() {
                Some(rng) => rng.random::<f32>(),
                None => 0.5,
            };
            let t = e0 + (e1 - e0) * u;
            out.t.push(t);
            out.delta.push((e1 - e0).abs() * dlen);
            let p = [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]];
            if let Some(q) = space.to_field(p) {
                let keep = match occupancy {
                    None => true,
                    Some(g) => {
                        let cell = g.cell(q);
                        let alive = g.occupied[cell] && log_t > MIN_TRANSMITTANCE.ln();
                        if alive {
                            log_t -= g.density[cell].min(1e10) * out.delta[r * s + i];
                        }
                        alive
                    }
                };
                if keep {
                    out.slots.push((r * s + i) as u32);
                    out.points.push(q);
                    out.world.push(p);
                    out.view_dirs.push(unit);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn one_ray(near: f32, far: f32) -> RayBatch {
        RayBatch {
            origins: vec![[0.0, 0.0, 2.0]],
            dirs: vec![[0.0, 0.0, -1.0]],
            near: vec![near],
            far: vec![far],
        }
    }

    #[test]
    fn bins_tile_the_interval() {
        let space = SceneSpace::Aabb {
            min: [-1.0; 3],
            max: [1.0; 3],
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
        let s = sample_rays(&one_ray(1.0, 3.0), &space, 8, None, Some(&mut rng));
        let total: f32 = s.delta.iter().sum();
        assert!((total - 2.0).abs() < 1e-5);
        for (i, t) in s.t.iter().enumerate() {
            assert!(*t >= 1.0 + 0.25 * i as f32 - 1e-6 && *t <= 1.0 + 0.25 * (i + 1) as f32 + 1e-6);
        }
        assert_eq!(s.slots.len(), 8);
    }

    #[test]
    fn bin_centres_are_evenly_spaced_in_the_normalised_coordinate() {
        let rays = one_ray(1.0, 3.0);
        for spacing in [Spacing::Linear, Spacing::InverseDepth] {
            let mut set = SampleSet {
                rays: 1,
                samples: 4,
                ..Default::default()
            };
            let (a, b) = (1.0f32, 1.0 / 3.0);
            set.t = (0..4)
                .map(|i| {
                    let u = (i as f32 + 0.5) / 4.0;
                    match spacing {
                        Spacing::Linear => 1.0 + 2.0 * u,
                        Spacing::InverseDepth => 1.0 / (a + (b - a) * u),
                    }
                })
                .collect();
            let u = normalized_positions(&rays, &set, spacing);
            for (i, v) in u.iter().enumerate() {
                assert!(
                    (v - (i as f32 + 0.5) / 4.0).abs() < 1e-5,
                    "{spacing:?}: {u:?}"
                );
            }
        }
        let mut empty = SampleSet {
            rays: 1,
            samples: 2,
            ..Default::default()
        };
        empty.t = vec![3.0, 3.0];
        assert_eq!(
            normalized_positions(&one_ray(3.0, 3.0), &empty, Spacing::Linear),
            [0.0, 0.0]
        );
    }

    #[test]
    fn missing_ray_has_zero_intervals_and_no_evaluations() {
        let space = SceneSpace::Aabb {
            min: [-1.0; 3],
            max: [1.0; 3],
        };
        let s = sample_rays::<rand_chacha::ChaCha8Rng>(&one_ray(3.0, 3.0), &space, 4, None, None);
        assert!(s.delta.iter().all(|d| *d == 0.0));
        assert!(s.slots.is_empty());
    }

    #[test]
    fn occupancy_skips_empty_cells_and_terminates_behind_opaque_cells() {
        let space = SceneSpace::Aabb {
            min: [-1.0; 3],
            max: [1.0; 3],
        };
        // ray along -z through the box from z = 1 to z = -1, 16 samples
        let rays = one_ray(1.0, 3.0);
        let mut grid = OccupancyGrid::new(4, 1.0);
        // only the cells with field z in [0.25, 0.75) (world z in [-0.5, 0.5)) are occupied
        for c in 0..64 {
            let z = c / 16;
            grid.occupied[c] = z == 1 || z == 2;
        }
        let s = sample_rays::<rand_chacha::ChaCha8Rng>(&rays, &space, 16, Some(&grid), None);
        assert_eq!(
            s.slots.len(),
            8,
            "half of the samples lie in occupied cells"
        );
        // an opaque running density in the first occupied layer stops the march there:
        // 4 samples of delta 0.125 at density 40 give T = exp(-20) < 1e-4 after 2 samples
        for c in 0..64 {
            grid.density[c] = if c / 16 == 2 { 40.0 } else { 0.0 };
        }
        let s = sample_rays::<rand_chacha::ChaCha8Rng>(&rays, &space, 16, Some(&grid), None);
        assert_eq!(s.slots.len(), 2, "{:?}", s.slots);
    }
}
