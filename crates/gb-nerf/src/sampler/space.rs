//! Scene parameterisation: where rays are sampled and how world points map to the field's
//! normalised coordinates `[0, 1]^3`.
//!
//! - **Bounded** scenes (Blender, procedural): an axis-aligned box; field coordinates are the
//!   box-normalised position, samples are uniform in distance between the ray's entry and
//!   exit of the box (intersected with the scene's near/far).
//! - **Forward-facing** captures (LLFF / SPIn-NeRF): samples are uniform in inverse depth
//!   between the scene's near and far bounds, and field coordinates are the normalised
//!   device coordinates (NDC) of a reference camera (the first training view):
//!   `x = fx/(W/2) * X/z`, `y = fy/(H/2) * Y/z`, `z' = 1 - 2 near / z` for a camera-space
//!   point `(X, Y, -z)`, mapped to `[0, 1]` with a margin of `xy_margin` around the reference
//!   frustum. NDC makes the scene unit-scaled whatever its metric size, and gives the hash
//!   grid resolution in inverse depth, where a forward-facing capture has its detail.

use serde::{Deserialize, Serialize};

use crate::scene::{Camera, Scene, SceneKind, Split};

/// How samples are spaced along a ray.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Spacing {
    /// Uniform in distance.
    Linear,
    /// Uniform in inverse distance (disparity).
    InverseDepth,
}

/// The parameterisation of space (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub enum SceneSpace {
    /// An axis-aligned box.
    Aabb {
        /// Minimum corner.
        min: [f32; 3],
        /// Maximum corner.
        max: [f32; 3],
    },
    /// NDC of a reference camera.
    Ndc {
        /// The reference camera.
        reference: Camera,
        /// Near bound (z-depth) of the NDC warp.
        near: f32,
        /// Field coordinates cover `[-xy_margin, xy_margin]` in NDC x and y.
        xy_margin: f32,
    },
}

impl SceneSpace {
    /// The parameterisation a scene asks for.
    pub fn from_scene(scene: &Scene) -> Self {
        match &scene.kind {
            SceneKind::Bounded { aabb_min, aabb_max } => SceneSpace::Aabb {
                min: *aabb_min,
                max: *aabb_max,
            },
            SceneKind::ForwardFacing => {
                let reference = scene
                    .split(Split::Train)
                    .next()
                    .or(scene.views.first())
                    .map(|v| v.camera.clone())
                    .unwrap_or(Camera {
                        width: 1,
                        height: 1,
                        fx: 1.0,
                        fy: 1.0,
                        cx: 0.5,
                        cy: 0.5,
                        c2w: [
                            [1.0, 0.0, 0.0, 0.0],
                            [0.0, 1.0, 0.0, 0.0],
                            [0.0, 0.0, 1.0, 0.0],
                        ],
                    });
                SceneSpace::Ndc {
                    reference,
                    near: scene.near.max(1e-6),
                    xy_margin: 1.5,
                }
            }
        }
    }

    /// How samples are spaced along rays.
    pub fn spacing(&self) -> Spacing {
        match self {
            SceneSpace::Aabb { .. } => Spacing::Linear,
            SceneSpace::Ndc { .. } => Spacing::InverseDepth,
        }
    }

    /// Field coordinates of a world point, or `None` outside the modelled volume.
    pub fn to_field(&self, p: [f32; 3]) -> Option<[f32; 3]> {
        let q = match self {
            SceneSpace::Aabb { min, max } => {
                [0, 1, 2].map(|i| (p[i] - min[i]) / (max[i] - min[i]).max(1e-12))
            }
            SceneSpace::Ndc {
                reference,
                near,
                xy_margin,
            } => {
                let r = &reference.c2w;
                let d = [p[0] - r[0][3], p[1] - r[1][3], p[2] - r[2][3]];
                let c = [0, 1, 2].map(|j| r[0][j] * d[0] + r[1][j] * d[1] + r[2][j] * d[2]);
                let z = -c[2];
                if z <= 0.0 {
                    return None;
                }
                let x = reference.fx / (reference.width as f32 * 0.5) * c[0] / z;
                let y = reference.fy / (reference.height as f32 * 0.5) * c[1] / z;
                let zn = 1.0 - 2.0 * near / z;
                [
                    x / xy_margin * 0.5 + 0.5,
                    y / xy_margin * 0.5 + 0.5,
                    zn * 0.5 + 0.5,
                ]
            }
        };
        q.iter().all(|v| (0.0..=1.0).contains(v)).then_some(q)
    }

    /// The sampled interval `[t0, t1]` of a ray `o + t d` (z-depth parameter), intersected
    /// with `[near, far]`; `t0 >= t1` means the ray misses the volume.
    pub fn ray_bounds(&self, o: [f32; 3], d: [f32; 3], near: f32, far: f32) -> (f32, f32) {
        match self {
            SceneSpace::Aabb { min, max } => {
                let (mut t0, mut t1) = (near, far);
                for i in 0..3 {
                    if d[i].abs() < 1e-12 {
                        if o[i] < min[i] || o[i] > max[i] {
                            return (far, far);
                        }
                        continue;
                    }
                    let (a, b) = ((min[i] - o[i]) / d[i], (max[i] - o[i]) / d[i]);
                    t0 = t0.max(a.min(b));
                    t1 = t1.min(a.max(b));
                }
                (t0, t1)
            }
            SceneSpace::Ndc { .. } => (near, far),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aabb_bounds_and_coordinates() {
        let s = SceneSpace::Aabb {
            min: [-1.0; 3],
            max: [1.0; 3],
        };
        let (t0, t1) = s.ray_bounds([0.0, 0.0, 5.0], [0.0, 0.0, -1.0], 0.1, 100.0);
        assert!((t0 - 4.0).abs() < 1e-6 && (t1 - 6.0).abs() < 1e-6);
        let (t0, t1) = s.ray_bounds([0.0, 3.0, 5.0], [0.0, 0.0, -1.0], 0.1, 100.0);
        assert!(t0 >= t1);
        assert_eq!(s.to_field([0.0, 0.5, -1.0]), Some([0.5, 0.75, 0.0]));
        assert_eq!(s.to_field([0.0, 1.5, 0.0]), None);
    }

    #[test]
    fn ndc_maps_near_to_zero_and_infinity_to_one() {
        let cam = Camera {
            width: 40,
            height: 30,
            fx: 40.0,
            fy: 40.0,
            cx: 20.0,
            cy: 15.0,
            c2w: [
                [1.0, 0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 0.0],
            ],
        };
        let s = SceneSpace::Ndc {
            reference: cam,
            near: 2.0,
            xy_margin: 1.0,
        };
        let q = s.to_field([0.0, 0.0, -2.0]).unwrap();
        assert!((q[2] - 0.0).abs() < 1e-6 && (q[0] - 0.5).abs() < 1e-6);
        let q = s.to_field([0.0, 0.0, -1e8]).unwrap();
        assert!((q[2] - 1.0).abs() < 1e-6);
        // the frustum edge maps to the border
        let q = s.to_field([-10.0 * 0.5, 0.0, -10.0]).unwrap();
        assert!(q[0].abs() < 1e-6, "{q:?}");
    }
}
