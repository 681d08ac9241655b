//! Stratified sampling along rays, with optional empty-space skipping.

use rand::Rng;
use rayon::prelude::*;

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
/// Rays are marched in parallel (rayon); the jitter is drawn first, in ray order, so the
/// result and the random stream are those of a sequential march.
pub fn sample_rays<R: Rng>(
    rays: &RayBatch,
    space: &SceneSpace,
    samples: usize,
    occupancy: Option<&OccupancyGrid>,
    rng: Option<&mut R>,
) -> SampleSet {
    let s = samples.max(1);
    let n = rays.len();
    let hits = |r: usize| {
        let (t0, t1) = (rays.near[r], rays.far[r]);
        t0 < t1 && t0.is_finite() && t1.is_finite()
    };
    // The jitter is drawn first, in the order of the sequential march (ray by ray, only for
    // rays that hit the volume), so the random stream and the samples do not depend on how
    // the rays are then spread over the cores.
    let jitter: Option<Vec<f32>> = rng.map(|rng| {
        let mut v = vec![0.5f32; n * s];
        for r in (0..n).filter(|&r| hits(r)) {
            for j in &mut v[r * s..(r + 1) * s] {
                *j = rng.random::<f32>();
            }
        }
        v
    });
    let parts: Vec<SampleSet> = (0..n)
        .into_par_iter()
        .chunks(RAYS_PER_TASK)
        .map(|chunk| {
            let mut part = SampleSet::default();
            for r in chunk {
                let u = jitter.as_ref().map(|j| &j[r * s..(r + 1) * s]);
                march(rays, r, space, s, occupancy, u, &mut part);
            }
            part
        })
        .collect();
    let mut out = SampleSet {
        rays: n,
        samples: s,
        t: Vec::with_capacity(n * s),
        delta: Vec::with_capacity(n * s),
        ..Default::default()
    };
    for part in parts {
        out.t.extend(part.t);
        out.delta.extend(part.delta);
        out.slots.extend(part.slots);
        out.points.extend(part.points);
        out.world.extend(part.world);
        out.view_dirs.extend(part.view_dirs);
    }
    out
}

/// Rays per parallel task of [`sample_rays`].
const RAYS_PER_TASK: usize = 64;

/// The samples of ray `r` (see [`sample_rays`]), appended to `out`; `jitter` holds the ray's
/// `s` uniform draws (bin centres without it). `out.slots` are dense indices of the whole
/// batch.
fn march(
    rays: &RayBatch,
    r: usize,
    space: &SceneSpace,
    s: usize,
    occupancy: Option<&OccupancyGrid>,
    jitter: Option<&[f32]>,
    out: &mut SampleSet,
) {
    let spacing = space.spacing();
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
        let u = jitter.map_or(0.5, |j| j[i]);
        let t = e0 + (e1 - e0) * u;
        let delta = (e1 - e0).abs() * dlen;
        out.t.push(t);
        out.delta.push(delta);
        let p = [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]];
        if let Some(q) = space.to_field(p) {
            let keep = match occupancy {
                None => true,
                Some(g) => {
                    let cell = g.cell(q);
                    let alive = g.occupied[cell] && log_t > MIN_TRANSMITTANCE.ln();
                    if alive {
                        log_t -= g.density[cell].min(1e10) * delta;
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

    /// The parallel march of a batch (several tasks of rays, misses among them, jitter and
    /// an occupancy grid with running densities) equals marching its rays one at a time from
    /// the same random stream, which is the sequential definition; the stream ends in the
    /// same state.
    #[test]
    fn a_batch_equals_its_rays_marched_one_by_one() {
        let space = SceneSpace::Aabb {
            min: [-1.0; 3],
            max: [1.0; 3],
        };
        let n = 3 * RAYS_PER_TASK + 7;
        let mut rays = RayBatch::default();
        for r in 0..n {
            let a = r as f32 * 0.37;
            rays.origins.push([0.3 * a.sin(), 0.3 * a.cos(), 2.0]);
            rays.dirs.push([0.1 * a.cos(), -0.1 * a.sin(), -1.0]);
            // every fifth ray misses the volume
            let (near, far) = if r % 5 == 0 { (3.0, 1.0) } else { (1.0, 3.0) };
            rays.near.push(near);
            rays.far.push(far);
        }
        let mut grid = OccupancyGrid::new(4, 1.0);
        for c in 0..64 {
            grid.occupied[c] = c % 3 != 0;
            grid.density[c] = (c % 7) as f32 * 3.0;
        }
        let mut rng_batch = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let batch = sample_rays(&rays, &space, 24, Some(&grid), Some(&mut rng_batch));
        let mut rng_one = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut t = Vec::new();
        let mut slots = Vec::new();
        let mut points = Vec::new();
        for r in 0..n {
            let one = RayBatch {
                origins: vec![rays.origins[r]],
                dirs: vec![rays.dirs[r]],
                near: vec![rays.near[r]],
                far: vec![rays.far[r]],
            };
            let s = sample_rays(&one, &space, 24, Some(&grid), Some(&mut rng_one));
            t.extend(s.t);
            slots.extend(s.slots.iter().map(|k| k + (r * 24) as u32));
            points.extend(s.points);
        }
        assert_eq!(batch.t, t);
        assert_eq!(batch.slots, slots);
        assert_eq!(batch.points, points);
        assert!(!slots.is_empty() && slots.len() < n * 24, "{}", slots.len());
        assert_eq!(rng_batch.random::<u64>(), rng_one.random::<u64>());
    }
}
