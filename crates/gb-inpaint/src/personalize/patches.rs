//! The scene's own training data for personalisation: square patches of the training views
//! that no object mask touches, at the size of the guidance crops. A view with an
//! object-free image (a reference view, or a clean plate) gives every square of that image,
//! its masked region included: there the prior is shown what the hole holds.

use gb_core::RgbImage;
use gb_finetune::sample::{PairSample, PairSource};
use gb_finetune::FinetuneError;
use gb_nerf::train::data::TrainView;

use crate::crop::CropGeometry;

/// One patch: a training view and the square's corner and side, training-resolution pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PatchRect {
    /// Index into the views.
    pub view: usize,
    /// Left column.
    pub x0: usize,
    /// Top row.
    pub y0: usize,
    /// Side.
    pub side: usize,
}

/// Square patches of the training views outside every object mask, as a
/// [`PairSource`] of RGB samples captioned with the guidance's appearance prompt.
#[derive(Debug, Clone)]
pub struct ScenePatches {
    images: Vec<RgbImage>,
    /// The patches, in view-major, row-major order.
    pub rects: Vec<PatchRect>,
    /// Views whose object-free image the patches come from.
    pub object_free_views: usize,
    caption: String,
}

/// The side of the guidance crops of `views` (median over the masked views of the crop
/// box's longer side, with the method's `margin`), clamped to the smallest image side;
/// `None` when no view has a mask.
pub fn crop_side(views: &[TrainView], margin: f32) -> Option<usize> {
    let mut sides: Vec<usize> = views
        .iter()
        .filter_map(|v| CropGeometry::new(v, margin, 8))
        .map(|g| {
            let (x0, y0, x1, y1) = g.bbox;
            (x1 - x0).max(y1 - y0)
        })
        .collect();
    if sides.is_empty() {
        return None;
    }
    sides.sort_unstable();
    let smallest = views
        .iter()
        .map(|v| v.image.width.min(v.image.height))
        .min()
        .unwrap_or(1);
    Some(sides[sides.len() / 2].clamp(1, smallest.max(1)))
}

/// Whether the square `(x0, y0, side)` of `view` touches its mask.
fn touches_mask(view: &TrainView, x0: usize, y0: usize, side: usize) -> bool {
    let Some(m) = view.mask.as_ref() else {
        return false;
    };
    (y0..y0 + side).any(|y| (x0..x0 + side).any(|x| m.data[y * m.width + x]))
}

impl ScenePatches {
    /// Every square of `side` on a grid of stride `side / 4` over each view that touches no
    /// mask pixel. `caption` is the prompt each sample is trained with.
    pub fn new(views: &[TrainView], side: usize, caption: &str) -> Self {
        Self::with_object_free(views, &[], side, caption)
    }

    /// As [`ScenePatches::new`], but a view `i` with `object_free[i]` (the view without the
    /// object, at the training resolution) gives the squares of that image, masked or not.
    pub fn with_object_free(
        views: &[TrainView],
        object_free: &[Option<RgbImage>],
        side: usize,
        caption: &str,
    ) -> Self {
        let stride = (side / 4).max(1);
        let clean = |i: usize| object_free.get(i).and_then(Option::as_ref);
        let mut rects = Vec::new();
        for (i, v) in views.iter().enumerate() {
            let (w, h) = (v.image.width, v.image.height);
            if side > w || side > h {
                continue;
            }
            for y0 in (0..=h - side).step_by(stride) {
                for x0 in (0..=w - side).step_by(stride) {
                    if clean(i).is_some() || !touches_mask(v, x0, y0, side) {
                        rects.push(PatchRect {
                            view: i,
                            x0,
                            y0,
                            side,
                        });
                    }
                }
            }
        }
        Self {
            images: views
                .iter()
                .enumerate()
                .map(|(i, v)| clean(i).unwrap_or(&v.image).clone())
                .collect(),
            object_free_views: (0..views.len()).filter(|&i| clean(i).is_some()).count(),
            rects,
            caption: caption.to_string(),
        }
    }

    /// A fingerprint of the patches' pixels and caption (FNV-1a), for the cache.
    pub fn fingerprint(&self) -> u64 {
        let mut h = gb_core::fingerprint::Fnv64::default();
        for r in &self.rects {
            [r.view, r.x0, r.y0, r.side]
                .iter()
                .for_each(|v| h.word(*v as u64));
        }
        for img in &self.images {
            img.data.iter().for_each(|f| h.word(f.to_bits() as u64));
        }
        h.bytes(self.caption.as_bytes());
        h.finish()
    }
}

impl PairSource for ScenePatches {
    fn len(&self) -> usize {
        self.rects.len()
    }

    fn load(&self, index: usize) -> Result<PairSample, FinetuneError> {
        let r = self.rects[index];
        let img = &self.images[r.view];
        let mut rgb = Vec::with_capacity(r.side * r.side * 3);
        for y in r.y0..r.y0 + r.side {
            for x in r.x0..r.x0 + r.side {
                rgb.extend_from_slice(&img.get(x, y));
            }
        }
        Ok(PairSample {
            name: format!("view {} patch ({}, {})", r.view, r.x0, r.y0),
            width: r.side,
            height: r.side,
            rgb,
            normal: None,
            normal_valid: vec![0.0; r.side * r.side],
            caption: self.caption.clone(),
        })
    }
}
