//! PNG outputs of a rendered view: RGB, depth in a colour map, normal map.

use std::path::Path;

use gb_core::RgbImage;

use super::NerfError;
use crate::render::image::ImageRender;
use crate::render::normals::normals_to_image;

/// Google's Turbo colour map (polynomial approximation by Ruofei Du), `x` in `[0, 1]`.
pub fn turbo(x: f32) -> [f32; 3] {
    let x = x.clamp(0.0, 1.0) as f64;
    let r = 0.13572138
        + x * (4.61539260
            + x * (-42.66032258 + x * (132.13108234 + x * (-152.94239396 + x * 59.28637943))));
    let g = 0.09140261
        + x * (2.19418839
            + x * (4.84296658 + x * (-14.18503333 + x * (4.27729857 + x * 2.82956604))));
    let b = 0.10667330
        + x * (12.64194608
            + x * (-60.58204836 + x * (110.36276771 + x * (-89.90310912 + x * 27.34824973))));
    [r, g, b].map(|v| v.clamp(0.0, 1.0) as f32)
}

/// A depth map as a Turbo-coloured image of its disparity, normalised between the 1st and
/// 99th percentiles of the finite positive depths (near = red end, far = blue end).
pub fn depth_colormap(depth: &[f32], width: usize, height: usize) -> RgbImage {
    let mut disp: Vec<f32> = depth
        .iter()
        .filter(|d| d.is_finite() && **d > 0.0)
        .map(|d| 1.0 / d)
        .collect();
    disp.sort_by(|a, b| a.total_cmp(b));
    let (lo, hi) = if disp.is_empty() {
        (0.0, 1.0)
    } else {
        (
            disp[disp.len() / 100],
            disp[(disp.len() * 99 / 100).min(disp.len() - 1)],
        )
    };
    let span = (hi - lo).max(1e-12);
    let data = depth
        .iter()
        .flat_map(|d| {
            let v = if d.is_finite() && *d > 0.0 {
                (1.0 / d - lo) / span
            } else {
                0.0
            };
            turbo(v)
        })
        .collect();
    RgbImage {
        width,
        height,
        data,
    }
}

/// Writes `<stem>_rgb.png`, `<stem>_depth.png` and `<stem>_normal.png` into `dir`.
pub fn write_render_pngs(dir: &Path, stem: &str, render: &ImageRender) -> Result<(), NerfError> {
    let (w, h) = (render.rgb.width, render.rgb.height);
    let io = |path: &Path, e: gb_core::ImageIoError| NerfError::Io {
        path: path.to_path_buf(),
        source: std::io::Error::other(e.to_string()),
    };
    std::fs::create_dir_all(dir).map_err(|e| NerfError::Io {
        path: dir.to_path_buf(),
        source: e,
    })?;
    let p = dir.join(format!("{stem}_rgb.png"));
    gb_core::write_rgb_png(&p, &render.rgb).map_err(|e| io(&p, e))?;
    let p = dir.join(format!("{stem}_depth.png"));
    gb_core::write_rgb_png(&p, &depth_colormap(&render.depth, w, h)).map_err(|e| io(&p, e))?;
    if render.normals.len() == w * h {
        let p = dir.join(format!("{stem}_normal.png"));
        gb_core::write_rgb_png(&p, &normals_to_image(&render.normals, w, h))
            .map_err(|e| io(&p, e))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn turbo_ends() {
        let a = turbo(0.15);
        let b = turbo(0.9);
        assert!(a[2] > a[0], "low end is blue-ish: {a:?}");
        assert!(b[0] > b[2], "high end is red-ish: {b:?}");
    }
}
