//! Training data: the training views (optionally downscaled) and the pool of unmasked pixels
//! that rays are drawn from.

use gb_core::RgbImage;

use super::DepthSupervision;
use crate::scene::{Camera, Mask, Scene, Split, View};

/// One training view, at the training resolution.
#[derive(Debug, Clone)]
pub struct TrainView {
    /// Camera at the training resolution.
    pub camera: Camera,
    /// Image at the training resolution.
    pub image: RgbImage,
    /// Object mask (pixels excluded from the RGB loss), if any.
    pub mask: Option<Mask>,
    /// Ground-truth z-depth (`<= 0` or non-finite: none), if any.
    pub depth: Option<Vec<f32>>,
}

/// A training pixel: view index and integer pixel coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelRef {
    /// Index into [`TrainData::views`].
    pub view: u32,
    /// Column.
    pub x: u32,
    /// Row.
    pub y: u32,
}

/// A sparse depth sample: where a reconstructed 3D point (COLMAP's `points3D`) projects in
/// a training view, at the training resolution, and its z-depth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SparseSample {
    /// Index into [`TrainData::views`].
    pub view: u32,
    /// Continuous pixel x (0.5 is the centre of the first column).
    pub x: f32,
    /// Continuous pixel y.
    pub y: f32,
    /// z-depth, world units.
    pub depth: f32,
}

/// All training views, their unmasked pixels and the depth that supervises them.
#[derive(Debug, Clone)]
pub struct TrainData {
    /// The views; their dense `depth` is kept only under [`DepthSupervision::Dense`].
    pub views: Vec<TrainView>,
    /// Every pixel outside the masks.
    pub pixels: Vec<PixelRef>,
    /// The scene's sparse points outside the masks, under [`DepthSupervision::Sparse`].
    pub sparse: Vec<SparseSample>,
}

/// Downscales a camera by an integer factor.
pub fn downscale_camera(c: &Camera, f: usize) -> Camera {
    let s = 1.0 / f as f32;
    Camera {
        width: c.width / f,
        height: c.height / f,
        fx: c.fx * s,
        fy: c.fy * s,
        cx: c.cx * s,
        cy: c.cy * s,
        c2w: c.c2w,
    }
}

/// Box-downscales an image by an integer factor.
pub fn downscale_image(img: &RgbImage, f: usize) -> RgbImage {
    if f <= 1 {
        return img.clone();
    }
    let (w, h) = (img.width / f, img.height / f);
    let mut out = RgbImage::filled(w, h, [0.0; 3]);
    let inv = 1.0 / (f * f) as f32;
    for y in 0..h {
        for x in 0..w {
            let mut acc = [0.0f32; 3];
            for dy in 0..f {
                for dx in 0..f {
                    let c = img.get(x * f + dx, y * f + dy);
                    (0..3).for_each(|i| acc[i] += c[i]);
                }
            }
            out.set(x, y, acc.map(|v| v * inv));
        }
    }
    out
}

/// Downscales a mask by an integer factor: a pixel is masked when any pixel of its block is.
pub fn downscale_mask(m: &Mask, f: usize) -> Mask {
    if f <= 1 {
        return m.clone();
    }
    let (w, h) = (m.width / f, m.height / f);
    let mut data = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            data[y * w + x] =
                (0..f).any(|dy| (0..f).any(|dx| m.data[(y * f + dy) * m.width + x * f + dx]));
        }
    }
    Mask {
        width: w,
        height: h,
        data,
    }
}

fn downscale_depth(d: &[f32], width: usize, height: usize, f: usize) -> Vec<f32> {
    if f <= 1 {
        return d.to_vec();
    }
    let (w, h) = (width / f, height / f);
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let (mut s, mut n) = (0.0f32, 0);
            for dy in 0..f {
                for dx in 0..f {
                    let v = d[(y * f + dy) * width + x * f + dx];
                    if v.is_finite() && v > 0.0 {
                        s += v;
                        n += 1;
                    }
                }
            }
            out[y * w + x] = if n == f * f { s / n as f32 } else { 0.0 };
        }
    }
    out
}

/// One view at the training resolution.
pub fn prepare_view(v: &View, f: usize) -> TrainView {
    TrainView {
        camera: downscale_camera(&v.camera, f),
        image: downscale_image(&v.image, f),
        mask: v.mask.as_ref().map(|m| downscale_mask(m, f)),
        depth: v
            .depth
            .as_ref()
            .map(|d| downscale_depth(d, v.image.width, v.image.height, f)),
    }
}

/// Whether pixel `(x, y)` of `v` lies under its mask.
fn masked(v: &TrainView, x: usize, y: usize) -> bool {
    v.mask
        .as_ref()
        .is_some_and(|m| m.width == v.image.width && m.data[y * m.width + x])
}

/// The sparse points of `view` (index `i`, training resolution `1 / f`) that supervise:
/// inside the image, in front of the camera, and outside the mask (a point under the mask
/// lies on the object being removed).
fn sparse_samples(
    scene: &Scene,
    view: &View,
    v: &TrainView,
    i: usize,
    f: usize,
) -> Vec<SparseSample> {
    let Some(points) = scene.sparse_depth.get(&view.name) else {
        return Vec::new();
    };
    let s = 1.0 / f as f32;
    points
        .iter()
        .map(|p| SparseSample {
            view: i as u32,
            x: p.x * s,
            y: p.y * s,
            depth: p.depth,
        })
        .filter(|p| {
            let inside = p.x >= 0.0
                && p.y >= 0.0
                && (p.x as usize) < v.image.width
                && (p.y as usize) < v.image.height;
            inside && p.depth.is_finite() && p.depth > 0.0 && !masked(v, p.x as usize, p.y as usize)
        })
        .collect()
}

impl TrainData {
    /// The training split of `scene` at `1 / downscale` resolution, with the depth that
    /// `depth` selects. Mask pixels are never trained on. Errors when no trainable pixel
    /// remains.
    pub fn from_scene(
        scene: &Scene,
        downscale: usize,
        depth: DepthSupervision,
    ) -> Result<Self, super::NerfError> {
        let f = downscale.max(1);
        let train: Vec<&View> = scene.split(Split::Train).collect();
        let mut views: Vec<TrainView> = train.iter().map(|v| prepare_view(v, f)).collect();
        let mut sparse = Vec::new();
        if depth == DepthSupervision::Sparse {
            for (i, (view, v)) in train.iter().zip(&views).enumerate() {
                sparse.extend(sparse_samples(scene, view, v, i, f));
            }
        }
        if depth != DepthSupervision::Dense {
            views.iter_mut().for_each(|v| v.depth = None);
        }
        let mut pixels = Vec::new();
        for (i, v) in views.iter().enumerate() {
            for y in 0..v.image.height {
                for x in 0..v.image.width {
                    if !masked(v, x, y) {
                        pixels.push(PixelRef {
                            view: i as u32,
                            x: x as u32,
                            y: y as u32,
                        });
                    }
                }
            }
        }
        if pixels.is_empty() {
            return Err(super::NerfError::Scene {
                scene: scene.name.clone(),
                reason: "no training pixel outside the masks (no training views, or fully masked)"
                    .into(),
            });
        }
        Ok(Self {
            views,
            pixels,
            sparse,
        })
    }

    /// Withholds the pixels under `masks` (one per training view, at the training resolution;
    /// `None`: nothing withheld there) from every loss: they leave the pool of colour and
    /// depth rays, and the sparse points that project there are dropped. The views' own
    /// masks, and so the guidance, are unchanged. Errors when no trainable pixel remains.
    pub fn withhold(&mut self, masks: &[Option<Mask>]) -> Result<(), super::NerfError> {
        let under = |view: u32, x: usize, y: usize| {
            masks
                .get(view as usize)
                .and_then(Option::as_ref)
                .is_some_and(|m| x < m.width && y < m.height && m.data[y * m.width + x])
        };
        self.pixels
            .retain(|p| !under(p.view, p.x as usize, p.y as usize));
        self.sparse
            .retain(|p| !under(p.view, p.x as usize, p.y as usize));
        if self.pixels.is_empty() {
            return Err(super::NerfError::Scene {
                scene: "withheld".into(),
                reason: "no training pixel outside the masks and the withheld regions".into(),
            });
        }
        Ok(())
    }
}
