//! COLMAP sparse models (`sparse/0`): cameras, registered images and 3D points, read from
//! COLMAP's binary (`cameras.bin`, `images.bin`, `points3D.bin`) or text (`*.txt`) files,
//! which hold the same model. SPIn-NeRF scenes ship one; the reference codebase line
//! (DS-NeRF and its descendants) supervises depth with its points.
//!
//! Conventions are COLMAP's: an image's pose maps world to camera, `x_cam = R(q) X + t`, with
//! `q = (qw, qx, qy, qz)`, the camera looking along `+z`, `x` right and `y` down; pixel
//! coordinates put the centre of the top-left pixel at `(0.5, 0.5)`. [`Model::sparse_depth`]
//! gives an image's observed points as `(x, y, z-depth)`.
//!
//! [`write_text`] and [`write_binary`] write a model in either form (tests, and generators
//! that emit sparse points the way COLMAP would).

mod binary;
mod text;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub use binary::write_binary;
pub use text::write_text;

use super::SceneError;

/// COLMAP's camera models: `(id, name, number of parameters)`.
pub const CAMERA_MODELS: [(i32, &str, usize); 11] = [
    (0, "SIMPLE_PINHOLE", 3),
    (1, "PINHOLE", 4),
    (2, "SIMPLE_RADIAL", 4),
    (3, "RADIAL", 5),
    (4, "OPENCV", 8),
    (5, "OPENCV_FISHEYE", 8),
    (6, "FULL_OPENCV", 12),
    (7, "FOV", 5),
    (8, "SIMPLE_RADIAL_FISHEYE", 4),
    (9, "RADIAL_FISHEYE", 5),
    (10, "THIN_PRISM_FISHEYE", 12),
];

/// One camera (intrinsics).
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    /// COLMAP's model name (`PINHOLE`, `SIMPLE_RADIAL`, ...).
    pub model: String,
    /// Image width in pixels.
    pub width: u64,
    /// Image height in pixels.
    pub height: u64,
    /// The model's parameters (focal lengths, principal point, distortion), COLMAP's order.
    pub params: Vec<f64>,
}

/// One registered image.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// World-to-camera rotation as a unit quaternion `(qw, qx, qy, qz)`.
    pub qvec: [f64; 4],
    /// World-to-camera translation.
    pub tvec: [f64; 3],
    /// Its camera's id.
    pub camera_id: i32,
    /// The image file's name (relative to the image folder).
    pub name: String,
    /// Its 2D keypoints `(x, y)` with the id of their 3D point (`-1`: none).
    pub points2d: Vec<([f64; 2], i64)>,
}

/// One 3D point.
#[derive(Debug, Clone, PartialEq)]
pub struct Point3d {
    /// Position in world units.
    pub xyz: [f64; 3],
    /// Colour.
    pub rgb: [u8; 3],
    /// Mean reprojection error, pixels.
    pub error: f64,
    /// Observations: `(image id, keypoint index)`.
    pub track: Vec<(i32, u32)>,
}

/// A sparse model: cameras, images and points by their ids.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Model {
    /// Cameras by id.
    pub cameras: BTreeMap<i32, Camera>,
    /// Registered images by id.
    pub images: BTreeMap<i32, Image>,
    /// 3D points by id.
    pub points: BTreeMap<u64, Point3d>,
}

/// A point observed in one image: pixel position and its z-depth in that camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SparseDepth {
    /// Pixel x (COLMAP's: 0.5 is the centre of the first column).
    pub x: f32,
    /// Pixel y.
    pub y: f32,
    /// z-depth (distance along the camera's viewing axis), world units.
    pub depth: f32,
    /// The point's mean reprojection error, pixels (DS-NeRF weighs by it).
    pub error: f32,
}

/// The number of parameters of camera model `id`, or `None` for an unknown model.
pub fn model_params(id: i32) -> Option<(&'static str, usize)> {
    CAMERA_MODELS
        .iter()
        .find(|m| m.0 == id)
        .map(|&(_, name, n)| (name, n))
}

/// The id of camera model `name`, or `None` for an unknown model.
pub fn model_id(name: &str) -> Option<(i32, usize)> {
    CAMERA_MODELS
        .iter()
        .find(|m| m.1 == name)
        .map(|&(id, _, n)| (id, n))
}

/// A COLMAP file could not be read.
pub(crate) fn bad(path: &Path, reason: impl Into<String>) -> SceneError {
    SceneError::Colmap {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

impl Model {
    /// Reads the model in `dir` (a `sparse/0` folder): the binary files when
    /// `cameras.bin` exists ([`is_binary`]), else the text files. Errors name the file and, for text, the
    /// line.
    pub fn read(dir: &Path) -> Result<Self, SceneError> {
        let model = if is_binary(dir) {
            binary::read(dir)?
        } else if dir.join("cameras.txt").is_file() {
            text::read(dir)?
        } else {
            return Err(SceneError::Missing {
                path: dir.join("cameras.bin"),
                what: "COLMAP model (cameras/images/points3D as .bin or .txt)".into(),
            });
        };
        model.check(dir)?;
        Ok(model)
    }

    /// Every image's camera exists (the loader looks it up).
    fn check(&self, dir: &Path) -> Result<(), SceneError> {
        for (id, im) in &self.images {
            if !self.cameras.contains_key(&im.camera_id) {
                return Err(bad(
                    &images_file(dir),
                    format!(
                        "image {id} ({}) names camera {}, which the model lacks",
                        im.name, im.camera_id
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The points observed in `image` with their z-depth in its camera (points behind the
    /// camera are left out).
    pub fn sparse_depth(&self, image: &Image) -> Vec<SparseDepth> {
        let r = rotation(image.qvec);
        image
            .points2d
            .iter()
            .filter_map(|&([x, y], id)| {
                let p = self.points.get(&u64::try_from(id).ok()?)?;
                let z = (0..3).map(|k| r[2][k] * p.xyz[k]).sum::<f64>() + image.tvec[2];
                (z > 0.0).then_some(SparseDepth {
                    x: x as f32,
                    y: y as f32,
                    depth: z as f32,
                    error: p.error as f32,
                })
            })
            .collect()
    }

    /// Matches a scene's views by name (file stems: `IMG_2707` matches `IMG_2707.jpg`, the
    /// full-resolution image COLMAP registered) to registered images; the error names the
    /// model's images file (in `dir`) and the first view it lacks.
    pub fn match_stems<'a>(
        &self,
        dir: &Path,
        stems: impl IntoIterator<Item = &'a str>,
    ) -> Result<Vec<&Image>, SceneError> {
        let images = images_file(dir);
        stems
            .into_iter()
            .map(|n| {
                self.images
                    .values()
                    .find(|im| Path::new(&im.name).file_stem() == Some(n.as_ref()))
                    .ok_or_else(|| {
                        bad(
                            &images,
                            format!(
                                "has no registered image for view {n} ({} images registered)",
                                self.images.len()
                            ),
                        )
                    })
            })
            .collect()
    }
}

/// COLMAP's world-to-camera pose `(qvec, tvec)` of a camera given as an OpenGL
/// camera-to-world `[R | t]` (x right, y up, looking along -z; [`crate::scene::Camera`]).
pub fn pose_of_camera(c2w: &[[f64; 4]; 3]) -> ([f64; 4], [f64; 3]) {
    // OpenGL -> OpenCV camera axes: flip y and z, then invert the rigid transform
    let r: [[f64; 3]; 3] =
        std::array::from_fn(|i| std::array::from_fn(|j| c2w[j][i] * [1.0, -1.0, -1.0][i]));
    let o = [c2w[0][3], c2w[1][3], c2w[2][3]];
    let t = std::array::from_fn(|i| -(0..3).map(|j| r[i][j] * o[j]).sum::<f64>());
    (quaternion(&r), t)
}

/// The unit quaternion `(w, x, y, z)` of a rotation matrix (Shepperd's method), `w >= 0`.
pub fn quaternion(r: &[[f64; 3]; 3]) -> [f64; 4] {
    let tr = r[0][0] + r[1][1] + r[2][2];
    let q = if tr > 0.0 {
        let s = (tr + 1.0).sqrt() * 2.0;
        [
            0.25 * s,
            (r[2][1] - r[1][2]) / s,
            (r[0][2] - r[2][0]) / s,
            (r[1][0] - r[0][1]) / s,
        ]
    } else if r[0][0] > r[1][1] && r[0][0] > r[2][2] {
        let s = (1.0 + r[0][0] - r[1][1] - r[2][2]).sqrt() * 2.0;
        [
            (r[2][1] - r[1][2]) / s,
            0.25 * s,
            (r[0][1] + r[1][0]) / s,
            (r[0][2] + r[2][0]) / s,
        ]
    } else if r[1][1] > r[2][2] {
        let s = (1.0 + r[1][1] - r[0][0] - r[2][2]).sqrt() * 2.0;
        [
            (r[0][2] - r[2][0]) / s,
            (r[0][1] + r[1][0]) / s,
            0.25 * s,
            (r[1][2] + r[2][1]) / s,
        ]
    } else {
        let s = (1.0 + r[2][2] - r[0][0] - r[1][1]).sqrt() * 2.0;
        [
            (r[1][0] - r[0][1]) / s,
            (r[0][2] + r[2][0]) / s,
            (r[1][2] + r[2][1]) / s,
            0.25 * s,
        ]
    };
    if q[0] < 0.0 {
        q.map(|v| -v)
    } else {
        q
    }
}

/// Whether the model in `dir` is read from its binary files (`cameras.bin` exists).
pub fn is_binary(dir: &Path) -> bool {
    dir.join("cameras.bin").is_file()
}

/// The images file of the model in `dir` (`images.bin` or `images.txt`), which errors about
/// registered images name.
fn images_file(dir: &Path) -> PathBuf {
    dir.join(if is_binary(dir) {
        "images.bin"
    } else {
        "images.txt"
    })
}

/// The rotation matrix of a unit quaternion `(w, x, y, z)` (normalised first).
pub fn rotation(q: [f64; 4]) -> [[f64; 3]; 3] {
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300);
    let [w, x, y, z] = q.map(|v| v / n);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// The folder of a scene's COLMAP model, when it ships one: `DIR/sparse/0`.
pub fn model_dir(scene_dir: &Path) -> Option<PathBuf> {
    let d = scene_dir.join("sparse/0");
    (d.join("cameras.bin").is_file() || d.join("cameras.txt").is_file()).then_some(d)
}
