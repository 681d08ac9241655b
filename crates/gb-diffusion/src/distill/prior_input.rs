//! The image fed to the prior: the mask's bounding-box crop, resized to the prior's
//! resolution, of either the render alone or the render pasted inside the mask onto the
//! ground truth outside it (the reference).

use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};
use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};

use super::error::DistillError;

/// Which pixels surround the masked region in the prior's input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum PriorInputMode {
    /// The render everywhere.
    RenderOnly,
    /// The render inside the mask, the ground truth outside (the reference code).
    #[default]
    PasteOnGroundTruth,
}

/// An axis-aligned pixel box `[x0, x0 + width) x [y0, y0 + height)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct MaskBox {
    /// Left column.
    pub x0: usize,
    /// Top row.
    pub y0: usize,
    /// Width in pixels (>= 1).
    pub width: usize,
    /// Height in pixels (>= 1).
    pub height: usize,
}

/// The bounding box of the pixels `>= 0.5` of a row-major `width x height` mask; `name`
/// identifies the mask in the error when no pixel is set.
pub fn mask_bbox(
    mask: &[f32],
    width: usize,
    height: usize,
    name: &str,
) -> Result<MaskBox, DistillError> {
    if mask.len() != width * height {
        return Err(DistillError::Shape {
            tensor: "mask",
            actual: vec![mask.len()],
            expected: format!("{width} x {height} = {} values", width * height),
        });
    }
    let (mut x_lo, mut y_lo, mut x_hi, mut y_hi) = (usize::MAX, usize::MAX, 0, 0);
    for (i, _) in mask.iter().enumerate().filter(|(_, v)| **v >= 0.5) {
        let (x, y) = (i % width, i / width);
        x_lo = x_lo.min(x);
        y_lo = y_lo.min(y);
        x_hi = x_hi.max(x);
        y_hi = y_hi.max(y);
    }
    if x_lo == usize::MAX {
        return Err(DistillError::EmptyMask(name.to_string()));
    }
    Ok(MaskBox {
        x0: x_lo,
        y0: y_lo,
        width: x_hi - x_lo + 1,
        height: y_hi - y_lo + 1,
    })
}

/// Crops `image` (`[B, C, H, W]`) to `bbox` and resizes it to `resolution x resolution`
/// (bilinear with half-pixel centres, like `F.interpolate(align_corners=False)`, or nearest
/// for masks). Differentiable; an identity resize is skipped.
pub fn crop_resize(
    image: Tensor<4>,
    bbox: &MaskBox,
    resolution: usize,
    nearest: bool,
) -> Tensor<4> {
    let [b, c, _, _] = image.dims();
    let crop = image.slice([
        0..b,
        0..c,
        bbox.y0..bbox.y0 + bbox.height,
        bbox.x0..bbox.x0 + bbox.width,
    ]);
    if bbox.width == resolution && bbox.height == resolution {
        return crop;
    }
    if nearest {
        let mut options = InterpolateOptions::new(InterpolateMode::Nearest);
        options.align_corners = false;
        return interpolate(crop, options.with_output_size([resolution, resolution]));
    }
    bilinear_resize(crop, resolution, resolution)
}

/// Bilinear resize of `[B, C, H, W]` to `[B, C, out_h, out_w]` with half-pixel centres (the
/// semantics of `F.interpolate(mode="bilinear", align_corners=False, antialias=False)`),
/// written as two matrix products so that its gradient exists on every backend (ndarray has
/// no backward for `interpolate`'s bilinear mode).
pub fn bilinear_resize(image: Tensor<4>, out_h: usize, out_w: usize) -> Tensor<4> {
    let [b, c, h, w] = image.dims();
    let device = image.device();
    let rows = linear_resize_matrix(h, out_h, &device); // [out_h, h]
    let cols = linear_resize_matrix(w, out_w, &device).transpose(); // [w, out_w]
    let flat = image.reshape([b * c, h, w]);
    let rows = rows.unsqueeze::<3>().repeat_dim(0, b * c);
    let cols = cols.unsqueeze::<3>().repeat_dim(0, b * c);
    rows.matmul(flat).matmul(cols).reshape([b, c, out_h, out_w])
}

/// The `[output, input]` matrix of 1D linear interpolation with half-pixel centres.
fn linear_resize_matrix(input: usize, output: usize, device: &burn::tensor::Device) -> Tensor<2> {
    let m = gb_core::resample::bilinear_matrix(input, output);
    Tensor::from_data(burn::tensor::TensorData::new(m, [output, input]), device)
}

/// The full-resolution image whose crop the prior sees: `render` alone, or
/// `render * mask + ground_truth * (1 - mask)` with the binary `mask` (`[B, 1, H, W]`).
pub fn compose(
    render: Tensor<4>,
    ground_truth: Option<&Tensor<4>>,
    mask: &Tensor<4>,
    mode: PriorInputMode,
    view: usize,
) -> Result<Tensor<4>, DistillError> {
    match mode {
        PriorInputMode::RenderOnly => Ok(render),
        PriorInputMode::PasteOnGroundTruth => {
            let gt = ground_truth.ok_or(DistillError::MissingGroundTruth(view))?;
            if gt.dims() != render.dims() {
                return Err(DistillError::Shape {
                    tensor: "ground truth",
                    actual: gt.dims().to_vec(),
                    expected: format!("the render's shape {:?}", render.dims()),
                });
            }
            let c = render.dims()[1];
            let (mut m, mut gt) = (mask.clone().repeat_dim(1, c), gt.clone());
            if render.is_autodiff() {
                m = m.autodiff();
                gt = gt.autodiff();
            }
            let outside = gt * (m.ones_like() - m.clone());
            Ok(render * m + outside)
        }
    }
}

#[cfg(test)]
mod resize_tests {
    use super::*;

    #[test]
    fn matrix_bilinear_resize_equals_interpolate_forward() {
        let device = gb_core::BackendKind::Flex.device();
        let values: Vec<f32> = (0..2 * 3 * 7 * 5)
            .map(|i| ((i * 37) % 11) as f32 * 0.1)
            .collect();
        let x =
            Tensor::<4>::from_data(burn::tensor::TensorData::new(values, [2, 3, 7, 5]), &device);
        for (oh, ow) in [(4, 4), (12, 9), (7, 5), (3, 8)] {
            let mut options = InterpolateOptions::new(InterpolateMode::Bilinear);
            options.align_corners = false;
            let reference = interpolate(x.clone(), options.with_output_size([oh, ow]));
            let ours = bilinear_resize(x.clone(), oh, ow);
            let diff: f32 = (reference - ours).abs().max().into_scalar::<f32>();
            assert!(diff < 1e-5, "{oh}x{ow}: max diff {diff}");
        }
    }
}
