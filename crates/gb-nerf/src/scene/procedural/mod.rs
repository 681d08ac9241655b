//! The procedural object-removal benchmark: an analytic ray tracer ([`geometry`],
//! [`texture`], [`world`]) renders built-in scenes ([`scenes`]: `stairs`, `fence`) from a
//! forward-facing, hand-held-looking arc of cameras ([`cameras`]), with exact ground truth.
//!
//! [`write()`] stores a scene in the SPIn-NeRF layout, which [`crate::scene::llff::load`]
//! reads back (depth and normals included):
//!
//! ```text
//! poses_bounds.npy           N x 17 float64, LLFF convention; near/far = min/max GT z-depth
//! images_1/view_NNN.png      8-bit RGB; the first K sorted views are TEST views rendered
//!                            WITHOUT the object, the others TRAIN views WITH it
//! images_1/label/NAME.png    train masks, 0/255: the exact object coverage (a pixel is in
//!                            the mask when any of its 2x2 subsamples sees the object first),
//!                            grown by `dilate` pixels
//! images_1/test_label/NAME.png  test masks: where the object would be (same rule)
//! clean/NAME.png             every TRAIN view rendered WITHOUT the object (exact ground
//!                            truth for oracle experiments; no loader reads it unless told)
//! depth_1/NAME.npy           float32 [H, W]: z-depth of the pixel-centre ray's first hit,
//!                            i.e. the distance along the camera's viewing axis (-z), in
//!                            world units; 0 = no hit (does not occur in the built-in scenes).
//!                            Train views: the scene with the object; test views: without.
//! normal_1/NAME.npy          float32 [H, W, 3]: unit WORLD-space normal at that hit,
//!                            facing the camera (world axes: y up, cameras look along -z)
//! scene.json                 generator parameters and the scene's bounding box
//!                            (`aabb_min`, `aabb_max` over every surface point a TRAIN
//!                            view sees)
//! sparse/0/*.bin             a COLMAP model as a real capture has one: every view's pose,
//!                            and train-view surface points seen by at least two train
//!                            views, with about half a pixel of noise ([`sparse`])
//! README.md                  this description
//! ```
//!
//! Shading is Lambertian with an ambient term and no shadows or reflections, so removing
//! the object changes exactly the pixels inside its (undilated) mask. Everything is
//! single-threaded and seeded (ChaCha8), so the same options give byte-identical files.
//!
//! [`rgb_normal_pairs`] / [`write_pairs`] give RGB / normal-map pairs with captions for
//! fine-tuning: the normal map image is `(n + 1) / 2` of the unit CAMERA-space normal
//! (OpenGL camera axes: x right, y up, z towards the viewer), averaged over the subsamples.

pub mod cameras;
pub mod geometry;
pub mod render;
pub mod scenes;
pub mod sparse;
pub mod texture;
pub mod world;
mod writer;

pub use scenes::SceneName;
pub use writer::{write, write_pairs, write_scene_pairs, PROCEDURAL_README};

use super::masks::dilate;
use super::{Mask, SceneError, Split};
use cameras::PinholeF64;
use gb_core::RgbImage;
use render::Render;
use scenes::SceneSpec;

/// Options of the generator.
#[derive(Debug, Clone, PartialEq)]
pub struct ProceduralOptions {
    /// Which scene.
    pub name: SceneName,
    /// Seed of textures, object placement and camera wobble.
    pub seed: u64,
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Number of views (train + test).
    pub views: usize,
    /// Number of test views (rendered without the object).
    pub test_views: usize,
    /// Mask dilation radius in pixels (0 = exact masks).
    pub dilate: usize,
}

impl Default for ProceduralOptions {
    fn default() -> Self {
        Self {
            name: SceneName::Stairs,
            seed: 0,
            width: 200,
            height: 150,
            views: 24,
            test_views: 8,
            dilate: 0,
        }
    }
}

impl ProceduralOptions {
    /// Checks the options.
    pub fn validate(&self) -> Result<(), SceneError> {
        if self.width < 8 || self.height < 8 || self.width > 8192 || self.height > 8192 {
            return Err(SceneError::Option(format!(
                "image size {}x{} must be between 8 and 8192",
                self.width, self.height
            )));
        }
        if self.views < 2 || self.views > 10_000 {
            return Err(SceneError::Option(format!(
                "views = {} must be between 2 and 10000",
                self.views
            )));
        }
        if self.test_views >= self.views {
            return Err(SceneError::Option(format!(
                "test views ({}) must be fewer than views ({})",
                self.test_views, self.views
            )));
        }
        Ok(())
    }
}

/// One generated view.
#[derive(Debug, Clone, PartialEq)]
pub struct GeneratedView {
    /// File stem (`view_NNN`).
    pub name: String,
    /// Train (with the object) or test (without).
    pub split: Split,
    /// Its camera.
    pub camera: PinholeF64,
    /// The render (with the object for train views, without for test views).
    pub render: Render,
    /// The mask written for it (object coverage, dilated).
    pub mask: Mask,
}

/// A generated scene in memory.
#[derive(Debug, Clone, PartialEq)]
pub struct GeneratedScene {
    /// The options used.
    pub options: ProceduralOptions,
    /// The world and rig.
    pub spec: SceneSpec,
    /// Views in file (sorted-name) order: the test views first.
    pub views: Vec<GeneratedView>,
}

/// The cameras in file order (test views first) and their splits, without rendering.
pub fn cameras_in_file_order(
    opts: &ProceduralOptions,
    spec: &SceneSpec,
) -> Vec<(PinholeF64, Split)> {
    let arc = cameras::arc(&spec.rig, opts.views, opts.width, opts.height, opts.seed);
    let test = cameras::test_positions(opts.views, opts.test_views);
    let mut out: Vec<(PinholeF64, Split)> = test.iter().map(|&j| (arc[j], Split::Test)).collect();
    out.extend(
        arc.iter()
            .enumerate()
            .filter(|(j, _)| !test.contains(j))
            .map(|(_, c)| (*c, Split::Train)),
    );
    out
}

/// Renders every view of a scene.
pub fn generate(opts: &ProceduralOptions) -> Result<GeneratedScene, SceneError> {
    opts.validate()?;
    let spec = scenes::build(opts.name, opts.seed);
    let cams = cameras_in_file_order(opts, &spec);
    let bar =
        gb_core::progress::bar(cams.len() as u64).with_message(format!("rendering {}", opts.name));
    let mut views = Vec::with_capacity(cams.len());
    for (i, (camera, split)) in cams.into_iter().enumerate() {
        let render = render::render(&spec.world, &camera, split == Split::Train);
        let exact = Mask {
            width: opts.width,
            height: opts.height,
            data: render.coverage.clone(),
        };
        let mask = dilate(&exact, opts.dilate);
        views.push(GeneratedView {
            name: format!("view_{i:03}"),
            split,
            camera,
            render,
            mask,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(GeneratedScene {
        options: opts.clone(),
        spec,
        views,
    })
}

/// An RGB image, its normal map and a caption, for fine-tuning a normal prior.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbNormalPair {
    /// Stem of the output files.
    pub name: String,
    /// The RGB image.
    pub rgb: RgbImage,
    /// `(n + 1) / 2` of the unit camera-space normal (OpenGL camera axes).
    pub normal: RgbImage,
    /// What the image shows.
    pub caption: String,
}

/// The normal-map image of a render: `(n + 1) / 2` of the camera-space normal; pixels with
/// no hit are `(0.5, 0.5, 0.5)`.
pub fn normal_map_image(r: &Render) -> RgbImage {
    let (w, h) = (r.rgb.width, r.rgb.height);
    let mut img = RgbImage::filled(w, h, [0.5; 3]);
    for (i, n) in r.normal_camera.iter().enumerate() {
        img.set(
            i % w,
            i / w,
            [(n[0] + 1.0) * 0.5, (n[1] + 1.0) * 0.5, (n[2] + 1.0) * 0.5],
        );
    }
    img
}

/// RGB / normal pairs of every view of a generated scene (names `SCENE_sSEED_view_NNN`).
pub fn pairs_of(scene: &GeneratedScene) -> Vec<RgbNormalPair> {
    scene
        .views
        .iter()
        .map(|v| RgbNormalPair {
            name: format!("{}_s{}_{}", scene.options.name, scene.options.seed, v.name),
            rgb: v.render.rgb.clone(),
            normal: normal_map_image(&v.render),
            caption: match v.split {
                Split::Train => scene.spec.caption_with_object.clone(),
                Split::Test => scene.spec.caption_without_object.clone(),
            },
        })
        .collect()
}

/// Generates a scene and returns its RGB / normal pairs.
pub fn rgb_normal_pairs(opts: &ProceduralOptions) -> Result<Vec<RgbNormalPair>, SceneError> {
    Ok(pairs_of(&generate(opts)?))
}
