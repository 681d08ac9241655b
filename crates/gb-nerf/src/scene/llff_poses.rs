//! `poses_bounds.npy`: parsing, LLFF-to-OpenGL axis conversion and scene normalisation.
// Component loops over xyz / matrix entries read clearer with indices than with zips.
#![allow(clippy::needless_range_loop)]

use super::npy::read_float_array;
use super::SceneError;
use std::path::Path;

/// One row of `poses_bounds.npy`, converted to OpenGL axes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LlffPose {
    /// Camera-to-world `[R | t]` with OpenGL camera axes (x right, y up, z back).
    pub c2w: [[f64; 4]; 3],
    /// Full-resolution image height from `hwf`.
    pub height: f64,
    /// Full-resolution image width from `hwf`.
    pub width: f64,
    /// Full-resolution focal length from `hwf`, in pixels.
    pub focal: f64,
    /// Near bound (distance along the viewing axis).
    pub near: f64,
    /// Far bound.
    pub far: f64,
}

/// Reads `poses_bounds.npy`: an `N x 17` float array whose rows are a row-major 3x5
/// `[R | t | hwf]` in LLFF's "down, right, back" axes plus near and far. The rotation's
/// columns are converted to OpenGL's "right, up, back": `[c1, -c0, c2]`.
pub fn read_poses_bounds(path: &Path) -> Result<Vec<LlffPose>, SceneError> {
    if !path.is_file() {
        return Err(SceneError::Missing {
            path: path.to_path_buf(),
            what: "poses_bounds.npy (LLFF poses)".into(),
        });
    }
    let arr = read_float_array(path)?;
    if arr.shape.len() != 2 || arr.shape[1] != 17 || arr.shape[0] == 0 {
        return Err(SceneError::PoseShape {
            path: path.to_path_buf(),
            shape: arr.shape,
        });
    }
    let n = arr.shape[0] as usize;
    let mut out = Vec::with_capacity(n);
    for row in 0..n {
        let r = &arr.data[row * 17..row * 17 + 17];
        if let Some(col) = r.iter().position(|v| !v.is_finite()) {
            return Err(SceneError::NonFinitePose {
                path: path.to_path_buf(),
                row,
                col,
                value: r[col],
            });
        }
        let m = |i: usize, j: usize| r[i * 5 + j];
        let mut c2w = [[0.0; 4]; 3];
        for (i, c2w_row) in c2w.iter_mut().enumerate() {
            *c2w_row = [m(i, 1), -m(i, 0), m(i, 2), m(i, 3)];
        }
        out.push(LlffPose {
            c2w,
            height: m(0, 4),
            width: m(1, 4),
            focal: m(2, 4),
            near: r[15],
            far: r[16],
        });
    }
    Ok(out)
}

/// Encodes OpenGL poses back to LLFF rows (the inverse of [`read_poses_bounds`]'s axis
/// conversion): columns `[-c1, c0, c2, t, hwf]`, then near and far.
pub fn encode_row(p: &LlffPose) -> [f64; 17] {
    let mut r = [0.0; 17];
    let hwf = [p.height, p.width, p.focal];
    for i in 0..3 {
        let c = &p.c2w[i];
        r[i * 5] = -c[1];
        r[i * 5 + 1] = c[0];
        r[i * 5 + 2] = c[2];
        r[i * 5 + 3] = c[3];
        r[i * 5 + 4] = hwf[i];
    }
    r[15] = p.near;
    r[16] = p.far;
    r
}

/// A similarity transform `x' = scale * R (x - center)` applied by the normalisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Normalization {
    /// Uniform scale.
    pub scale: f64,
    /// Rotation (world to normalised world), row-major.
    pub rotation: [[f64; 3]; 3],
    /// The old world point that becomes the origin.
    pub center: [f64; 3],
}

impl Normalization {
    /// The identity (no normalisation).
    pub fn identity() -> Self {
        Self {
            scale: 1.0,
            rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            center: [0.0; 3],
        }
    }

    /// NeRF's LLFF convention: recentre on the average camera pose (its axes become the
    /// world axes, its centre the origin) and scale by `1 / (0.75 * min near)`, so that the
    /// smallest near bound becomes 4/3 (NDC's near plane at 1 then lies in front of every
    /// camera).
    pub fn nerf_llff(poses: &[LlffPose]) -> Self {
        let n = poses.len().max(1) as f64;
        let mut center = [0.0; 3];
        let mut back = [0.0; 3];
        let mut up = [0.0; 3];
        for p in poses {
            for i in 0..3 {
                center[i] += p.c2w[i][3] / n;
                back[i] += p.c2w[i][2];
                up[i] += p.c2w[i][1];
            }
        }
        let z = normalize(back);
        let x = normalize(cross(up, z));
        let y = cross(z, x);
        let min_near = poses.iter().map(|p| p.near).fold(f64::INFINITY, f64::min);
        let scale = if min_near.is_finite() && min_near > 0.0 {
            1.0 / (0.75 * min_near)
        } else {
            1.0
        };
        // rotation = [x y z]^T (world -> average-camera frame)
        Self {
            scale,
            rotation: [x, y, z],
            center,
        }
    }

    /// Transforms a point.
    pub fn point(&self, p: [f64; 3]) -> [f64; 3] {
        let d = [
            p[0] - self.center[0],
            p[1] - self.center[1],
            p[2] - self.center[2],
        ];
        let r = self.direction(d);
        [r[0] * self.scale, r[1] * self.scale, r[2] * self.scale]
    }

    /// Rotates a direction (normals, camera axes); no scale.
    pub fn direction(&self, d: [f64; 3]) -> [f64; 3] {
        let m = &self.rotation;
        [
            m[0][0] * d[0] + m[0][1] * d[1] + m[0][2] * d[2],
            m[1][0] * d[0] + m[1][1] * d[1] + m[1][2] * d[2],
            m[2][0] * d[0] + m[2][1] * d[1] + m[2][2] * d[2],
        ]
    }

    /// Transforms a camera-to-world pose.
    pub fn pose(&self, c2w: &[[f64; 4]; 3]) -> [[f64; 4]; 3] {
        let mut out = [[0.0; 4]; 3];
        for j in 0..3 {
            let col = self.direction([c2w[0][j], c2w[1][j], c2w[2][j]]);
            for i in 0..3 {
                out[i][j] = col[i];
            }
        }
        let t = self.point([c2w[0][3], c2w[1][3], c2w[2][3]]);
        for i in 0..3 {
            out[i][3] = t[i];
        }
        out
    }
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalize(a: [f64; 3]) -> [f64; 3] {
    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    if n > 0.0 {
        [a[0] / n, a[1] / n, a[2] / n]
    } else {
        [0.0, 0.0, 1.0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encode_then_parse_round_trips() {
        let p = LlffPose {
            c2w: [
                [0.0, 0.6, 0.8, 1.0],
                [1.0, 0.0, 0.0, 2.0],
                [0.0, 0.8, -0.6, 3.0],
            ],
            height: 48.0,
            width: 64.0,
            focal: 50.0,
            near: 1.5,
            far: 9.0,
        };
        let row = encode_row(&p);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("poses_bounds.npy");
        std::fs::write(
            &path,
            super::super::npy::encode_f64(&[1, 17], &row).unwrap(),
        )
        .unwrap();
        let back = read_poses_bounds(&path).unwrap();
        assert_eq!(back, vec![p]);
    }

    #[test]
    fn llff_down_right_back_becomes_right_up_back() {
        // An LLFF camera with identity [down, right, back] columns means: camera down = world x,
        // camera right = world y. In OpenGL, camera right (x) = world y, camera up = -world x.
        let mut row = [0.0; 17];
        row[0] = 1.0; // R[0][0]
        row[6] = 1.0; // R[1][1]
        row[12] = 1.0; // R[2][2]
        row[4] = 10.0;
        row[9] = 20.0;
        row[14] = 30.0;
        row[15] = 1.0;
        row[16] = 2.0;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("poses_bounds.npy");
        std::fs::write(
            &path,
            super::super::npy::encode_f64(&[1, 17], &row).unwrap(),
        )
        .unwrap();
        let p = read_poses_bounds(&path).unwrap()[0];
        let col = |j: usize| [p.c2w[0][j], p.c2w[1][j], p.c2w[2][j]];
        assert_eq!(col(0), [0.0, 1.0, 0.0]);
        assert_eq!(col(1), [-1.0, 0.0, 0.0]);
        assert_eq!(col(2), [0.0, 0.0, 1.0]);
        assert_eq!((p.height, p.width, p.focal), (10.0, 20.0, 30.0));
    }

    #[test]
    fn normalization_maps_average_pose_to_identity_and_near_to_four_thirds() {
        let mk = |x: f64, near: f64| LlffPose {
            c2w: [
                [0.0, 0.0, 1.0, x],
                [0.0, 1.0, 0.0, 1.0],
                [-1.0, 0.0, 0.0, 2.0],
            ],
            height: 1.0,
            width: 1.0,
            focal: 1.0,
            near,
            far: 10.0,
        };
        let poses = [mk(-1.0, 3.0), mk(1.0, 6.0)];
        let n = Normalization::nerf_llff(&poses);
        assert!((n.scale * 0.75 * 3.0 - 1.0).abs() < 1e-12);
        let avg = n.pose(&[
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 1.0, 0.0, 1.0],
            [-1.0, 0.0, 0.0, 2.0],
        ]);
        let id = [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
        ];
        for i in 0..3 {
            for j in 0..4 {
                assert!((avg[i][j] - id[i][j]).abs() < 1e-12, "{avg:?}");
            }
        }
    }
}
