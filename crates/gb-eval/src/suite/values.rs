//! The per-pair values of one metric over its regions, and how they enter the report.

use gb_core::RgbImage;

use crate::error::MetricError;
use crate::image_metrics::Region;
use crate::report::{EvalReport, RegionKind};

/// Smallest side of a mask-box crop scored by BRISQUE / NIMA: below it the local statistics
/// (7x7 windows at two scales) describe the crop's border more than its content.
pub const NO_REFERENCE_MIN_CROP: usize = 32;

/// One key's value per pair (`None` where the pair lacks the input or the metric failed),
/// with the first failure.
pub struct KeyValues {
    key: String,
    values: Vec<Option<f64>>,
    error: Option<String>,
}

impl KeyValues {
    /// No value yet for `key`.
    pub fn new(key: String) -> Self {
        Self {
            key,
            values: Vec::new(),
            error: None,
        }
    }

    /// The next pair's value: a number, a failure (kept when it is the first), or nothing
    /// (the pair lacks the input, which is no failure).
    pub fn push(&mut self, name: &str, value: Option<Result<f64, String>>) {
        let v = match value {
            Some(Ok(v)) => Some(v),
            Some(Err(e)) => {
                if self.error.is_none() {
                    tracing::warn!("{}: {name}: {e}", self.key);
                    self.error = Some(format!("{name}: {e}"));
                }
                None
            }
            None => None,
        };
        self.values.push(v);
    }

    /// Writes the per-pair values, and the mean as the set-level value; the set-level value
    /// is unavailable after a failure, or when no pair had the input.
    pub fn store(self, report: &mut EvalReport) {
        report.set_per_image_partial(&self.key, &self.values);
        let present: Vec<f64> = self.values.iter().flatten().copied().collect();
        match self.error {
            Some(e) => report.set_unavailable(self.key, e),
            None if present.is_empty() => {
                report.set_unavailable(self.key, "no pair has the inputs this metric needs")
            }
            None => report.set(self.key, crate::report::mean(&present)),
        }
    }
}

/// The values of one metric over the three regions.
pub struct RegionValues {
    by_region: [KeyValues; 3],
}

impl RegionValues {
    /// Keys `base`, `base_bbox`, `base_mask`.
    pub fn new(base: &str) -> Self {
        Self {
            by_region: RegionKind::ALL.map(|r| KeyValues::new(r.key(base))),
        }
    }

    /// The next pair's value in each region (`regions` as [`regions_of`] returns them; a
    /// region absent from it has no value for this pair).
    pub fn push(
        &mut self,
        name: &str,
        regions: &[(RegionKind, Result<Region, MetricError>)],
        f: impl Fn(&Region) -> Result<f64, MetricError>,
    ) {
        for kind in RegionKind::ALL {
            let value = regions
                .iter()
                .find(|(k, _)| *k == kind)
                .map(|(_, r)| match r {
                    Ok(r) => f(r).map_err(|e| e.to_string()),
                    Err(e) => Err(e.to_string()),
                });
            self.by_region[kind as usize].push(name, value);
        }
    }

    /// The next pair has no value in any region (it lacks the input).
    pub fn push_none(&mut self, name: &str) {
        for values in &mut self.by_region {
            values.push(name, None);
        }
    }

    /// Writes the keys of the regions in `kinds`.
    pub fn store(self, report: &mut EvalReport, kinds: &[RegionKind]) {
        for (kind, values) in RegionKind::ALL.into_iter().zip(self.by_region) {
            if kinds.contains(&kind) {
                values.store(report);
            }
        }
    }
}

/// The regions of one `width x height` pair: the whole image, and with a mask its bounding
/// box and its pixels (a mask of another size makes those fail, naming the sizes).
pub fn regions_of(
    mask: Option<&[bool]>,
    width: usize,
    height: usize,
) -> Vec<(RegionKind, Result<Region, MetricError>)> {
    let mut out = vec![(RegionKind::Full, Ok(Region::Full))];
    if let Some(mask) = mask {
        if mask.len() != width * height {
            let err = || MetricError::MaskSize {
                got: mask.len(),
                expected: width * height,
                width,
                height,
            };
            out.push((RegionKind::BBox, Err(err())));
            out.push((RegionKind::Mask, Err(err())));
        } else {
            let bbox = Region::bbox_of_mask(mask, width).ok_or(MetricError::EmptyMask);
            out.push((RegionKind::BBox, bbox));
            out.push((RegionKind::Mask, Ok(Region::Mask(mask.to_vec()))));
        }
    }
    out
}

/// The crop of `img` to its mask's bounding box, or why there is none.
pub fn bbox_crop(img: &RgbImage, mask: Option<&[bool]>) -> Result<RgbImage, String> {
    let mask = mask.ok_or("no mask")?;
    if mask.len() != img.width * img.height {
        return Err(MetricError::MaskSize {
            got: mask.len(),
            expected: img.width * img.height,
            width: img.width,
            height: img.height,
        }
        .to_string());
    }
    let Some(Region::BBox { x0, y0, x1, y1 }) = Region::bbox_of_mask(mask, img.width) else {
        return Err(MetricError::EmptyMask.to_string());
    };
    let (w, h) = (x1 - x0, y1 - y0);
    if w < NO_REFERENCE_MIN_CROP || h < NO_REFERENCE_MIN_CROP {
        return Err(format!(
            "the mask box is {w}x{h}, under the {NO_REFERENCE_MIN_CROP}-pixel minimum"
        ));
    }
    let mut out = RgbImage::filled(w, h, [0.0; 3]);
    for y in 0..h {
        for x in 0..w {
            out.set(x, y, img.get(x0 + x, y0 + y));
        }
    }
    Ok(out)
}
