//! Plain data types of a scene.

use gb_core::RgbImage;
use serde::{Deserialize, Serialize};

/// A pinhole camera: intrinsics in pixels and a camera-to-world pose (OpenGL axes).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Focal length along x, in pixels.
    pub fx: f32,
    /// Focal length along y, in pixels.
    pub fy: f32,
    /// Principal point x, in pixels.
    pub cx: f32,
    /// Principal point y, in pixels.
    pub cy: f32,
    /// Camera-to-world transform, rows of a 3x4 `[R | t]` matrix.
    pub c2w: [[f32; 4]; 3],
}

impl Camera {
    /// The camera centre in world coordinates.
    pub fn origin(&self) -> [f32; 3] {
        [self.c2w[0][3], self.c2w[1][3], self.c2w[2][3]]
    }

    /// The unit world-space direction of the ray through pixel coordinates `(px, py)`
    /// (continuous; the centre of pixel (x, y) is `(x + 0.5, y + 0.5)`).
    pub fn ray_direction(&self, px: f32, py: f32) -> [f32; 3] {
        let d = [(px - self.cx) / self.fx, -(py - self.cy) / self.fy, -1.0];
        let r = &self.c2w;
        let w = [
            r[0][0] * d[0] + r[0][1] * d[1] + r[0][2] * d[2],
            r[1][0] * d[0] + r[1][1] * d[1] + r[1][2] * d[2],
            r[2][0] * d[0] + r[2][1] * d[1] + r[2][2] * d[2],
        ];
        let n = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
        [w[0] / n, w[1] / n, w[2] / n]
    }

    /// The world point at continuous pixel coordinates `(px, py)` and z-depth `z`: the
    /// inverse of [`Self::project`].
    pub fn unproject(&self, px: f32, py: f32, z: f32) -> [f32; 3] {
        let d = [(px - self.cx) / self.fx, -(py - self.cy) / self.fy, -1.0];
        let r = &self.c2w;
        [0, 1, 2].map(|i| r[i][3] + z * (r[i][0] * d[0] + r[i][1] * d[1] + r[i][2] * d[2]))
    }

    /// Projects a world point to continuous pixel coordinates and its z-depth; `None` when
    /// the point is behind the camera.
    pub fn project(&self, p: [f32; 3]) -> Option<([f32; 2], f32)> {
        let r = &self.c2w;
        let d = [p[0] - r[0][3], p[1] - r[1][3], p[2] - r[2][3]];
        // camera coords = R^T d
        let c = [
            r[0][0] * d[0] + r[1][0] * d[1] + r[2][0] * d[2],
            r[0][1] * d[0] + r[1][1] * d[1] + r[2][1] * d[2],
            r[0][2] * d[0] + r[1][2] * d[1] + r[2][2] * d[2],
        ];
        let z = -c[2];
        if z <= 0.0 {
            return None;
        }
        Some((
            [self.cx + self.fx * c[0] / z, self.cy - self.fy * c[1] / z],
            z,
        ))
    }
}

/// A binary object mask, row-major, `true` inside the object to remove.
#[derive(Debug, Clone, PartialEq)]
pub struct Mask {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width * height` flags.
    pub data: Vec<bool>,
}

impl Mask {
    /// Fraction of pixels inside the mask, in [0, 1].
    pub fn coverage(&self) -> f32 {
        if self.data.is_empty() {
            return 0.0;
        }
        self.data.iter().filter(|&&m| m).count() as f32 / self.data.len() as f32
    }

    /// The tight bounding box `(x0, y0, x1, y1)` (exclusive ends) of the mask, or `None`
    /// when it is empty.
    pub fn bbox(&self) -> Option<(usize, usize, usize, usize)> {
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for y in 0..self.height {
            for x in 0..self.width {
                if self.data[y * self.width + x] {
                    x0 = x0.min(x);
                    y0 = y0.min(y);
                    x1 = x1.max(x + 1);
                    y1 = y1.max(y + 1);
                }
            }
        }
        (x0 != usize::MAX).then_some((x0, y0, x1, y1))
    }
}

/// Which split a view belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    /// Training view (with the object and, for object removal, its mask).
    Train,
    /// Held-out test view (for object removal: captured without the object).
    Test,
}

/// One posed image with optional mask, depth and normals.
#[derive(Debug, Clone)]
pub struct View {
    /// File stem of the image, used to pair outputs with inputs.
    pub name: String,
    /// The camera that took it.
    pub camera: Camera,
    /// The image.
    pub image: RgbImage,
    /// Object mask (training views of an object-removal scene).
    pub mask: Option<Mask>,
    /// Z-depth per pixel (see the module docs), `width * height` values.
    pub depth: Option<Vec<f32>>,
    /// World-space unit normal per pixel, `width * height` entries.
    pub normal: Option<Vec<[f32; 3]>>,
    /// Train or test.
    pub split: Split,
}

/// How the scene's space is parameterised for sampling.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum SceneKind {
    /// A forward-facing capture (LLFF / SPIn-NeRF): rays are sampled between the near and
    /// far bounds, in inverse depth or NDC.
    ForwardFacing,
    /// A bounded scene inside an axis-aligned box (Blender, procedural scenes).
    Bounded {
        /// Minimum corner of the box.
        aabb_min: [f32; 3],
        /// Maximum corner of the box.
        aabb_max: [f32; 3],
    },
}

/// A loaded scene.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Human-readable name (usually the folder name).
    pub name: String,
    /// Parameterisation of space.
    pub kind: SceneKind,
    /// All views, train and test, in a stable order.
    pub views: Vec<View>,
    /// Near bound along rays (scene units).
    pub near: f32,
    /// Far bound along rays (scene units).
    pub far: f32,
    /// Background colour used for compositing RGBA images and empty rays.
    pub background: [f32; 3],
    /// Non-fatal problems found while loading (e.g. a resized mask).
    pub warnings: Vec<String>,
    /// Sparse depth per view name, from the COLMAP model a scene ships (`sparse/0`, read by
    /// the LLFF loader): pixel positions at the loaded resolution and z-depth in scene units.
    /// Empty for scenes without one.
    pub sparse_depth: std::collections::BTreeMap<String, Vec<super::colmap::SparseDepth>>,
}

impl Scene {
    /// The views of one split.
    pub fn split(&self, split: Split) -> impl Iterator<Item = &View> {
        self.views.iter().filter(move |v| v.split == split)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn project_inverts_ray_direction() {
        let cam = Camera {
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 50.0,
            cx: 32.0,
            cy: 24.0,
            c2w: [
                [0.0, 0.0, 1.0, 1.0],
                [0.0, 1.0, 0.0, 2.0],
                [-1.0, 0.0, 0.0, 3.0],
            ],
        };
        let d = cam.ray_direction(10.5, 7.5);
        let o = cam.origin();
        let p = [o[0] + 4.0 * d[0], o[1] + 4.0 * d[1], o[2] + 4.0 * d[2]];
        let (px, z) = cam.project(p).unwrap();
        assert!(
            (px[0] - 10.5).abs() < 1e-4 && (px[1] - 7.5).abs() < 1e-4,
            "{px:?}"
        );
        assert!(z > 0.0 && z < 4.0);
    }

    #[test]
    fn mask_bbox_and_coverage() {
        let mut m = Mask {
            width: 4,
            height: 3,
            data: vec![false; 12],
        };
        assert_eq!(m.bbox(), None);
        m.data[4 + 1] = true;
        m.data[8 + 2] = true;
        assert_eq!(m.bbox(), Some((1, 1, 3, 3)));
        assert!((m.coverage() - 2.0 / 12.0).abs() < 1e-6);
    }
}
