//! The scene model shared by every loader, the trainer and the evaluation.
//!
//! Conventions (documented once, used everywhere):
//! - **Camera axes**: OpenGL / NeRF / nerfstudio: camera x right, y up, z backwards (the
//!   camera looks along -z). `c2w` maps camera coordinates to world coordinates. LLFF's
//!   "down, right, back" poses are converted on load.
//! - **Pixels**: pixel (x, y) has its centre at (x + 0.5, y + 0.5); images are row-major.
//! - **Depth**: z-depth, the distance along the camera's viewing axis (-z), in scene units;
//!   a value that is not finite or is <= 0 means "no depth here".
//! - **Normals**: unit vectors in world space; the zero vector means "no normal here".
//!
//! Loaders: [`llff`] (LLFF / SPIn-NeRF and the procedural benchmark), [`blender`]
//! (Blender / nerfstudio `transforms*.json`), and [`load`], which detects the format.
//! [`procedural`] generates the built-in benchmark scenes.

pub mod blender;
pub mod colmap;
mod detect;
mod error;
pub mod files;
mod info;
pub mod llff;
pub mod llff_poses;
pub mod masks;
pub mod npy;
pub mod procedural;
mod types;

pub use detect::{detect, load, LoadOptions, SceneFormat};
pub use error::SceneError;
pub use info::{SceneInfo, SplitInfo};
pub use types::{Camera, Mask, Scene, SceneKind, Split, View};
