//! `--probe`: the geometry of the hidden region, for finding why a fill loses depth (issue
//! 49). For every test view with a mask and ground-truth depth it writes into `OUT/probe/`:
//!
//! - `NAME_probe.png`: the mask box and a margin around it, each panel enlarged 4x, left to
//!   right: the render, the truth, the rendered disparity, the true disparity (one colour
//!   scale, the truth's), the signed depth error (blue: in front of the truth, red: behind,
//!   white: within 1%, full colour at 20%), and the normals;
//! - `NAME_rays.svg`: the compositing weights along four hidden pixels, with the true and the
//!   rendered depth;
//! - `probe.json` ([`ProbeReport`]): per view, the depth error inside the mask and in the
//!   observed surroundings, and where the weight of the hidden rays lies (in front of the
//!   true surface, at it within [`TOLERANCE`], behind it), their spread in depth, and the four
//!   profiles.
//!
//! These separate the causes: floaters (weight in front of a surface that is still there),
//! a moved surface (weight concentrated, away from the truth), a smeared surface (a large
//! spread), or surroundings pulled along (the error outside the mask grows too).

use std::path::Path;

use gb_core::RgbImage;
use gb_nerf::render::{normals_to_image, ImageRender, RayProfile};
use gb_nerf::scene::{Scene, Split};
use gb_nerf::train::data::prepare_view;
use gb_nerf::train::output::turbo;
use serde::Serialize;

use crate::error::InpaintError;
use crate::trainer::GuidedTrainer;
use gb_report::svg::{tile, LineChart, Series};

/// Relative depth tolerance of "at the true surface" (3DGIC's depth test uses the same 5%).
pub const TOLERANCE: f32 = 0.05;
/// Hidden pixels whose weights are drawn, per view.
const PROFILE_PIXELS: usize = 4;
/// Enlargement of the picture's panels.
const SCALE: usize = 4;

/// Depth error over a set of pixels, relative to the true depth.
#[derive(Debug, Clone, Serialize)]
pub struct DepthError {
    /// Pixels with a true depth.
    pub pixels: usize,
    /// Mean of `(rendered - true) / true`: negative when the surface comes forward.
    pub mean_signed: f64,
    /// Mean of `|rendered - true| / true`.
    pub mean_abs: f64,
    /// Share of pixels within [`TOLERANCE`].
    pub within_tolerance: f64,
    /// Root mean square of `(rendered - true) / true` (what a PSNR weighs).
    pub rms: f64,
}

/// D-PSNR of the mask box taken apart: the metric divides each disparity map by its own
/// maximum over the whole image (SPIn-NeRF's convention, `gb_eval::disparity`), so a change
/// of the nearest rendered point anywhere in the view rescales the box.
#[derive(Debug, Clone, Serialize)]
pub struct DisparityScale {
    /// The largest rendered disparity of the view (`1 / depth`).
    pub rendered_max: f64,
    /// The pixel `[x, y]` that holds it (the nearest rendered point).
    pub rendered_max_at: [usize; 2],
    /// Whether that pixel lies in the mask box.
    pub rendered_max_in_box: bool,
    /// The largest true disparity of the view.
    pub true_max: f64,
    /// PSNR of the mask box with each map divided by its own maximum, as D-PSNR (without its
    /// 8-bit rounding).
    pub d_psnr_own_scale: f64,
    /// PSNR of the mask box with both maps divided by the true maximum: the local error
    /// alone.
    pub d_psnr_true_scale: f64,
}

/// Where the weight of the hidden rays lies, averaged over the rays.
#[derive(Debug, Clone, Serialize)]
pub struct WeightMass {
    /// Weight in front of the true surface (nearer than `1 - TOLERANCE` of its depth).
    pub in_front: f64,
    /// Weight at the true surface (within [`TOLERANCE`]).
    pub at_surface: f64,
    /// Weight behind it.
    pub behind: f64,
    /// What no sample holds (`1 - opacity`: the background).
    pub background: f64,
    /// Spread of the weights in depth (their standard deviation) over the true depth.
    pub spread: f64,
    /// Share of rays with at least 0.1 of their weight both in front and at the surface
    /// (floaters in front of a surface that is still there).
    pub two_surfaces: f64,
}

/// One ray's weights, for the figure and the record.
#[derive(Debug, Clone, Serialize)]
pub struct ProfileRecord {
    /// Pixel centre.
    pub pixel: [f32; 2],
    /// True z-depth.
    pub true_depth: f32,
    /// Rendered z-depth.
    pub depth: f32,
    /// Sample z-depths.
    pub t: Vec<f32>,
    /// Their weights.
    pub weights: Vec<f32>,
}

/// The probe of one test view.
#[derive(Debug, Clone, Serialize)]
pub struct ViewProbe {
    /// The view's name.
    pub view: String,
    /// The mask's box `(x0, y0, x1, y1)`, ends exclusive.
    pub mask_box: [usize; 4],
    /// The depth error of the hidden pixels (inside the mask).
    pub hidden: DepthError,
    /// The depth error of the observed pixels around the mask (the box grown by a quarter
    /// of its size on each side, outside the mask).
    pub surroundings: DepthError,
    /// Where the hidden rays' weight lies.
    pub hidden_weights: WeightMass,
    /// The mask box's D-PSNR, split into the maps' scales and the local error.
    pub disparity_scale: DisparityScale,
    /// A few hidden rays' weights.
    pub profiles: Vec<ProfileRecord>,
}

/// `probe.json`: the probe of every test view with a mask and true depth.
#[derive(Debug, Clone, Serialize)]
pub struct ProbeReport {
    /// [`TOLERANCE`].
    pub tolerance: f32,
    /// The views.
    pub views: Vec<ViewProbe>,
}

/// Probes the test views of `scene` rendered by `trainer` (their renders `renders`, in the
/// scene's test order) and writes `dir` (module docs).
pub fn write_probe(
    dir: &Path,
    scene: &Scene,
    trainer: &GuidedTrainer,
    renders: &[ImageRender],
) -> Result<ProbeReport, InpaintError> {
    std::fs::create_dir_all(dir).map_err(|e| InpaintError::io(dir, e))?;
    let mut views = Vec::new();
    for (view, render) in scene.split(Split::Test).zip(renders) {
        let v = prepare_view(view, trainer.config.train.image_downscale);
        let (Some(mask), Some(truth)) = (v.mask.as_ref(), v.depth.as_ref()) else {
            continue;
        };
        let Some(bbox) = mask.bbox() else { continue };
        let (w, h) = (v.image.width, v.image.height);
        let valid = |i: usize| truth[i].is_finite() && truth[i] > 0.0;
        let hidden: Vec<usize> = (0..w * h).filter(|&i| mask.data[i] && valid(i)).collect();
        let around = grown_box(bbox, w, h);
        let ring: Vec<usize> = box_pixels(around, w)
            .filter(|&i| !mask.data[i] && valid(i))
            .collect();
        let centre = |i: usize| [(i % w) as f32 + 0.5, (i / w) as f32 + 0.5];
        let pixels: Vec<[f32; 2]> = hidden.iter().map(|&i| centre(i)).collect();
        let profiles = trainer.ray_profiles(&v.camera, &pixels)?;
        let truths: Vec<f32> = hidden.iter().map(|&i| truth[i]).collect();
        let picked: Vec<usize> = (1..=PROFILE_PIXELS)
            .map(|k| k * hidden.len() / (PROFILE_PIXELS + 1))
            .filter(|&k| k < hidden.len())
            .collect();
        let records: Vec<ProfileRecord> = picked
            .iter()
            .map(|&k| ProfileRecord {
                pixel: profiles[k].pixel,
                true_depth: truths[k],
                depth: profiles[k].depth,
                t: profiles[k].t.clone(),
                weights: profiles[k].weights.clone(),
            })
            .collect();
        let stem = Path::new(&view.name)
            .file_stem()
            .map_or_else(|| view.name.clone(), |s| s.to_string_lossy().into_owned());
        let picture = probe_picture(&v.image, render, truth, around);
        let png = dir.join(format!("{stem}_probe.png"));
        gb_core::write_rgb_png(&png, &picture)
            .map_err(|e| InpaintError::io(&png, std::io::Error::other(e.to_string())))?;
        let svg = dir.join(format!("{stem}_rays.svg"));
        std::fs::write(&svg, rays_figure(&records)).map_err(|e| InpaintError::io(&svg, e))?;
        views.push(ViewProbe {
            view: view.name.clone(),
            mask_box: [bbox.0, bbox.1, bbox.2, bbox.3],
            hidden: depth_error(&hidden, &render.depth, truth),
            surroundings: depth_error(&ring, &render.depth, truth),
            hidden_weights: weight_mass(&profiles, &truths),
            disparity_scale: disparity_scale(&render.depth, truth, w, box_pixels(bbox, w)),
            profiles: records,
        });
    }
    let report = ProbeReport {
        tolerance: TOLERANCE,
        views,
    };
    let path = dir.join("probe.json");
    let text = serde_json::to_string_pretty(&report)
        .map_err(|e| InpaintError::io(&path, std::io::Error::other(e)))?;
    gb_core::write_atomic(&path, text.as_bytes()).map_err(|e| InpaintError::io(&path, e))?;
    Ok(report)
}

/// The depth error over `pixels` (indices into the maps).
pub fn depth_error(pixels: &[usize], rendered: &[f32], truth: &[f32]) -> DepthError {
    let n = pixels.len().max(1) as f64;
    let rel: Vec<f64> = pixels
        .iter()
        .map(|&i| ((rendered[i] - truth[i]) / truth[i]) as f64)
        .collect();
    DepthError {
        pixels: pixels.len(),
        mean_signed: rel.iter().sum::<f64>() / n,
        mean_abs: rel.iter().map(|e| e.abs()).sum::<f64>() / n,
        within_tolerance: rel.iter().filter(|e| e.abs() <= TOLERANCE as f64).count() as f64 / n,
        rms: (rel.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
    }
}

/// [`DisparityScale`] of the rendered and true depth maps (row-major, `width` wide) over the
/// pixels `region`.
pub fn disparity_scale(
    rendered: &[f32],
    truth: &[f32],
    width: usize,
    region: impl Iterator<Item = usize>,
) -> DisparityScale {
    let disparity = |d: f32| {
        if d.is_finite() && d > 0.0 {
            1.0 / f64::from(d)
        } else {
            0.0
        }
    };
    let at = (0..rendered.len())
        .max_by(|&a, &b| disparity(rendered[a]).total_cmp(&disparity(rendered[b])))
        .unwrap_or(0);
    let rmax = rendered.get(at).map_or(0.0, |&d| disparity(d)).max(1e-12);
    let tmax = truth
        .iter()
        .map(|&d| disparity(d))
        .fold(0.0, f64::max)
        .max(1e-12);
    let region: Vec<usize> = region.collect();
    let psnr = |scale: f64| {
        let sum: f64 = region
            .iter()
            .map(|&i| {
                let p = (disparity(rendered[i]) / scale).clamp(0.0, 1.0);
                let t = (disparity(truth[i]) / tmax).clamp(0.0, 1.0);
                (p - t) * (p - t)
            })
            .sum();
        -10.0 * (sum / region.len().max(1) as f64).max(1e-12).log10()
    };
    DisparityScale {
        rendered_max: rmax,
        rendered_max_at: [at % width.max(1), at / width.max(1)],
        rendered_max_in_box: region.contains(&at),
        true_max: tmax,
        d_psnr_own_scale: psnr(rmax),
        d_psnr_true_scale: psnr(tmax),
    }
}

/// Where the weight of `profiles` lies against their true depths `truths`.
pub fn weight_mass(profiles: &[RayProfile], truths: &[f32]) -> WeightMass {
    let n = profiles.len().max(1) as f64;
    let mut m = WeightMass {
        in_front: 0.0,
        at_surface: 0.0,
        behind: 0.0,
        background: 0.0,
        spread: 0.0,
        two_surfaces: 0.0,
    };
    for (p, &z) in profiles.iter().zip(truths) {
        let [f, a, b] = p.mass_around(z, TOLERANCE);
        m.in_front += f as f64 / n;
        m.at_surface += a as f64 / n;
        m.behind += b as f64 / n;
        m.background += (1.0 - p.opacity) as f64 / n;
        m.spread += (p.spread() / z) as f64 / n;
        if f >= 0.1 && a >= 0.1 {
            m.two_surfaces += 1.0 / n;
        }
    }
    m
}

/// The mask box grown by a quarter of its size on each side (at least 2 pixels), clipped.
fn grown_box(
    (x0, y0, x1, y1): (usize, usize, usize, usize),
    w: usize,
    h: usize,
) -> (usize, usize, usize, usize) {
    let mx = ((x1 - x0) / 4).max(2);
    let my = ((y1 - y0) / 4).max(2);
    (
        x0.saturating_sub(mx),
        y0.saturating_sub(my),
        (x1 + mx).min(w),
        (y1 + my).min(h),
    )
}

fn box_pixels(
    (x0, y0, x1, y1): (usize, usize, usize, usize),
    w: usize,
) -> impl Iterator<Item = usize> {
    (y0..y1).flat_map(move |y| (x0..x1).map(move |x| y * w + x))
}

/// The colour of a signed relative depth error: blue in front, red behind, white within
/// 1%, full colour at 20%.
fn error_colour(e: f32) -> [f32; 3] {
    let s = ((e.abs() - 0.01) / 0.19).clamp(0.0, 1.0);
    if e < 0.0 {
        [1.0 - s, 1.0 - s, 1.0]
    } else {
        [1.0, 1.0 - s, 1.0 - s]
    }
}

/// The picture of the module docs: six panels of the box `around`, side by side.
fn probe_picture(
    truth_rgb: &RgbImage,
    render: &ImageRender,
    truth: &[f32],
    around: (usize, usize, usize, usize),
) -> RgbImage {
    let (x0, y0, x1, y1) = around;
    let w = truth_rgb.width;
    let disp = |d: f32| {
        if d.is_finite() && d > 0.0 {
            1.0 / d
        } else {
            0.0
        }
    };
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for i in box_pixels(around, w) {
        let d = disp(truth[i]);
        if d > 0.0 {
            lo = lo.min(d);
            hi = hi.max(d);
        }
    }
    let span = (hi - lo).max(1e-6);
    let normals = normals_to_image(&render.normals, w, truth_rgb.height);
    type Panel<'a> = Box<dyn Fn(usize, usize) -> [f32; 3] + 'a>;
    let panels: Vec<Panel> = vec![
        Box::new(|x, y| render.rgb.get(x, y)),
        Box::new(|x, y| truth_rgb.get(x, y)),
        Box::new(|x, y| turbo((disp(render.depth[y * w + x]) - lo) / span)),
        Box::new(|x, y| turbo((disp(truth[y * w + x]) - lo) / span)),
        Box::new(|x, y| {
            let (d, z) = (render.depth[y * w + x], truth[y * w + x]);
            if z.is_finite() && z > 0.0 {
                error_colour((d - z) / z)
            } else {
                [0.5; 3]
            }
        }),
        Box::new(|x, y| normals.get(x, y)),
    ];
    let (pw, ph) = ((x1 - x0) * SCALE, (y1 - y0) * SCALE);
    let gap = 2;
    let mut out = RgbImage::filled(panels.len() * (pw + gap) - gap, ph, [1.0; 3]);
    for (k, panel) in panels.iter().enumerate() {
        for py in 0..ph {
            for px in 0..pw {
                let c = panel(x0 + px / SCALE, y0 + py / SCALE);
                out.set(k * (pw + gap) + px, py, c);
            }
        }
    }
    out
}

/// The weights of `records` as one SVG of small charts.
fn rays_figure(records: &[ProfileRecord]) -> String {
    let charts: Vec<LineChart> = records
        .iter()
        .map(|r| {
            let top = r.weights.iter().cloned().fold(0.0f32, f32::max).max(1e-3) as f64;
            let mut c = LineChart::new(
                format!("pixel ({:.1}, {:.1})", r.pixel[0], r.pixel[1]),
                "z-depth",
                "weight",
            );
            c.width = 420;
            c.height = 240;
            let pts = r.t.iter().zip(&r.weights);
            c.push(Series::new(
                "weights",
                pts.map(|(t, w)| (*t as f64, *w as f64)).collect(),
            ));
            let z = r.true_depth as f64;
            c.push(Series::new("true depth", vec![(z, 0.0), (z, top)]));
            let d = r.depth as f64;
            c.push(Series::new("rendered depth", vec![(d, 0.0), (d, top)]));
            c
        })
        .collect();
    tile(&charts, 2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_error_signs_a_surface_in_front_negative() {
        let truth = [2.0, 2.0, 4.0];
        let rendered = [1.0, 2.05, 4.0];
        let e = depth_error(&[0, 1, 2], &rendered, &truth);
        assert_eq!(e.pixels, 3);
        assert!((e.mean_signed - (-0.5 + 0.025) / 3.0).abs() < 1e-6, "{e:?}");
        assert!((e.mean_abs - (0.5 + 0.025) / 3.0).abs() < 1e-6, "{e:?}");
        assert!((e.within_tolerance - 2.0 / 3.0).abs() < 1e-9);
        let rms = ((0.25 + 0.025 * 0.025) / 3.0_f64).sqrt();
        assert!((e.rms - rms).abs() < 1e-6, "{e:?}");
    }

    #[test]
    fn a_near_point_outside_the_box_rescales_its_d_psnr() {
        // truth: disparity 1 everywhere but 0.5 in the box (pixels 2, 3)
        let truth = [1.0, 1.0, 2.0, 2.0];
        // the box rendered exactly, and a point outside it twice as near
        let rendered = [0.5, 1.0, 2.0, 2.0];
        let s = disparity_scale(&rendered, &truth, 2, [2, 3].into_iter());
        assert!((s.rendered_max - 2.0).abs() < 1e-9 && (s.true_max - 1.0).abs() < 1e-9);
        assert_eq!(s.rendered_max_at, [0, 0]);
        assert!(!s.rendered_max_in_box);
        // against its own maximum the box reads 0.25 instead of 0.5: PSNR 20 log10(4)
        assert!(
            (s.d_psnr_own_scale - 20.0 * 4.0_f64.log10()).abs() < 1e-6,
            "{s:?}"
        );
        // on the true scale the box is exact
        assert!(s.d_psnr_true_scale > 100.0, "{s:?}");
    }

    #[test]
    fn weight_mass_finds_a_floater_in_front_of_the_surface() {
        let floater = RayProfile {
            pixel: [0.5, 0.5],
            t: vec![1.0, 2.0, 3.0],
            weights: vec![0.3, 0.6, 0.0],
            depth: 1.7,
            opacity: 0.9,
        };
        let clean = RayProfile {
            weights: vec![0.0, 0.9, 0.0],
            depth: 2.0,
            opacity: 0.9,
            ..floater.clone()
        };
        let m = weight_mass(&[floater, clean], &[2.0, 2.0]);
        assert!((m.in_front - 0.15).abs() < 1e-6, "{m:?}");
        assert!((m.at_surface - 0.75).abs() < 1e-6, "{m:?}");
        assert_eq!(m.behind, 0.0);
        assert!((m.background - 0.1).abs() < 1e-6, "{m:?}");
        assert!((m.two_surfaces - 0.5).abs() < 1e-9);
        // the floater ray's spread is sqrt(0.3 * 0.6 * 1) / 0.9 = 0.471 of its depth 2,
        // averaged with 0
        assert!((m.spread - 0.4714 / 2.0 / 2.0).abs() < 1e-3, "{m:?}");
    }

    #[test]
    fn error_colour_is_white_near_zero_blue_in_front_red_behind() {
        assert_eq!(error_colour(0.005), [1.0, 1.0, 1.0]);
        assert_eq!(error_colour(-0.3), [0.0, 0.0, 1.0]);
        assert_eq!(error_colour(0.3), [1.0, 0.0, 0.0]);
    }
}
