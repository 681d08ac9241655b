//! Normals from a rendered depth map (local plane fit) and their image encoding.
//!
//! **Convention** (shared with the fine-tuning data): normals are unit vectors in CAMERA
//! space with OpenGL axes — x right, y up, z backwards (towards the viewer). A surface that
//! faces the camera has `n ~ (0, 0, 1)`. The normal-map image stores `(n + 1) / 2` per
//! channel (R = x, G = y, B = z), so a fronto-parallel surface is `(0.5, 0.5, 1.0)`.
//! Rays that hit nothing (depth = background depth) and patches too degenerate to define a
//! plane get the background normal `(0, 0, 1)`.
//!
//! The plane fit (MVIP-NeRF / GB-NeRF: `k = 31` at one seventh of the resolution):
//! 1. average-pool the depth by `downsample` (intrinsics scaled to match);
//! 2. back-project every pixel to a camera-space point `p = z * ((u - cx)/fx, -(v - cy)/fy, -1)`;
//! 3. shift and scale all points by the (detached) image mean and spread, so that the
//!    moments below are well conditioned in f32;
//! 4. box-filter (`k x k`, borders averaged over valid pixels only) the first and second
//!    moments and form the local covariance `C`;
//! 5. the plane normal is the eigenvector of `C` with the smallest eigenvalue, computed
//!    stably as the largest of the three cross products of the rows of `C` (the columns of
//!    `adj(C)`; Eberly's / Ernerfeldt's robust fit), oriented towards the camera;
//! 6. a patch whose covariance is (near) rank <= 1 gets the background normal;
//! 7. bilinear upsampling (half-pixel centres, `align_corners = false`) back to the input
//!    size and renormalisation.
//!
//! Every step is a differentiable tensor operation, so a loss on the normal map reaches the
//! depth (and through it the field).

use burn::tensor::module::avg_pool2d;
use burn::tensor::ops::AvgPoolOptions;
use burn::tensor::{Tensor, TensorData};
use serde::{Deserialize, Serialize};

/// Settings of the depth-to-normal plane fit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PlaneFitConfig {
    /// Side of the fitting window at the reduced resolution (GB-NeRF: 31).
    pub kernel: usize,
    /// Integer reduction of the resolution before fitting (GB-NeRF: 7).
    pub downsample: usize,
}

impl Default for PlaneFitConfig {
    fn default() -> Self {
        Self {
            kernel: 31,
            downsample: 7,
        }
    }
}

/// Pinhole intrinsics in pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    /// Focal length x.
    pub fx: f32,
    /// Focal length y.
    pub fy: f32,
    /// Principal point x.
    pub cx: f32,
    /// Principal point y.
    pub cy: f32,
}

impl Intrinsics {
    /// The intrinsics of a camera.
    pub fn of(camera: &crate::scene::Camera) -> Self {
        Self {
            fx: camera.fx,
            fy: camera.fy,
            cx: camera.cx,
            cy: camera.cy,
        }
    }
}

fn box_mean(x: Tensor<4>, k: usize) -> Tensor<4> {
    let (a, b) = (k / 2, k - 1 - k / 2);
    let opts = AvgPoolOptions::new([k, k])
        .with_stride([1, 1])
        .with_padding_pairs([(a, b), (a, b)])
        .with_count_include_pad(false);
    avg_pool2d(x, opts)
}

fn cross(a: [Tensor<2>; 3], b: [Tensor<2>; 3]) -> [Tensor<2>; 3] {
    [
        a[1].clone() * b[2].clone() - a[2].clone() * b[1].clone(),
        a[2].clone() * b[0].clone() - a[0].clone() * b[2].clone(),
        a[0].clone() * b[1].clone() - a[1].clone() * b[0].clone(),
    ]
}

fn sq_norm(v: &[Tensor<2>; 3]) -> Tensor<2> {
    v[0].clone().square() + v[1].clone().square() + v[2].clone().square()
}

/// Bilinear upsampling of `[C, hs, ws]` to `[C, h, w]` as two matrix products (a linear map,
/// so it is differentiable on every backend; burn-ndarray has no bilinear backward).
fn upsample_bilinear(x: Tensor<3>, h: usize, w: usize) -> Tensor<3> {
    let [c, hs, ws] = x.dims();
    let device = x.device();
    let my = Tensor::<2>::from_data(
        TensorData::new(gb_core::resample::bilinear_matrix(hs, h), [h, hs]),
        &device,
    );
    let mx = Tensor::<2>::from_data(
        TensorData::new(gb_core::resample::bilinear_matrix(ws, w), [w, ws]),
        &device,
    );
    let my = my.unsqueeze_dim::<3>(0).repeat_dim(0, c);
    let mxt = mx.transpose().unsqueeze_dim::<3>(0).repeat_dim(0, c);
    my.matmul(x).matmul(mxt)
}

/// Camera-space unit normals `[H, W, 3]` of a z-depth map `[H, W]` by the local plane fit
/// described in the module docs.
pub fn depth_to_normals(depth: Tensor<2>, k: Intrinsics, cfg: PlaneFitConfig) -> Tensor<3> {
    let [h, w] = depth.dims();
    let device = depth.device();
    let ds = cfg.downsample.max(1).min(h).min(w);
    let (hs, ws) = (h / ds, w / ds);
    let small = if ds > 1 {
        avg_pool2d(depth.reshape([1, 1, h, w]), AvgPoolOptions::new([ds, ds])).reshape([hs, ws])
    } else {
        depth
    };
    let kk = cfg.kernel.max(1);
    // camera-space back-projection coefficients at the reduced resolution
    let (fx, fy, cx, cy) = (
        k.fx / ds as f32,
        k.fy / ds as f32,
        k.cx / ds as f32,
        k.cy / ds as f32,
    );
    let mut ax = Vec::with_capacity(hs * ws);
    let mut ay = Vec::with_capacity(hs * ws);
    for v in 0..hs {
        for u in 0..ws {
            ax.push((u as f32 + 0.5 - cx) / fx);
            ay.push(-(v as f32 + 0.5 - cy) / fy);
        }
    }
    let ax = Tensor::<2>::from_data(TensorData::new(ax, [hs, ws]), &device);
    let ay = Tensor::<2>::from_data(TensorData::new(ay, [hs, ws]), &device);
    let z = small;
    let pts = [ax * z.clone(), ay * z.clone(), z.neg()];
    // conditioning: detached global shift and scale (a plane's normal is invariant to both)
    let mean: Vec<f32> = pts
        .iter()
        .map(|p| p.clone().detach().mean().into_scalar::<f32>())
        .collect();
    let spread: f32 = pts
        .iter()
        .zip(&mean)
        .map(|(p, m)| {
            p.clone()
                .detach()
                .sub_scalar(*m)
                .square()
                .mean()
                .into_scalar::<f32>()
        })
        .sum::<f32>()
        .sqrt();
    let scale = if spread.is_finite() && spread > 1e-20 {
        1.0 / spread
    } else {
        1.0
    };
    let p: Vec<Tensor<2>> = pts
        .into_iter()
        .zip(&mean)
        .map(|(p, m)| {
            let m = if m.is_finite() { *m } else { 0.0 };
            p.sub_scalar(m).mul_scalar(scale)
        })
        .collect();
    let moments = vec![
        p[0].clone(),
        p[1].clone(),
        p[2].clone(),
        p[0].clone() * p[0].clone(),
        p[0].clone() * p[1].clone(),
        p[0].clone() * p[2].clone(),
        p[1].clone() * p[1].clone(),
        p[1].clone() * p[2].clone(),
        p[2].clone() * p[2].clone(),
    ];
    let stacked = Tensor::stack::<3>(moments, 0).reshape([1, 9, hs, ws]);
    let m = box_mean(stacked, kk).reshape([9, hs, ws]);
    let g = |i: usize| m.clone().narrow(0, i, 1).reshape([hs, ws]);
    let (mx, my, mz) = (g(0), g(1), g(2));
    let cxx = g(3) - mx.clone() * mx.clone();
    let cxy = g(4) - mx.clone() * my.clone();
    let cxz = g(5) - mx.clone() * mz.clone();
    let cyy = g(6) - my.clone() * my.clone();
    let cyz = g(7) - my.clone() * mz.clone();
    let czz = g(8) - mz.clone() * mz.clone();
    let r0 = [cxx.clone(), cxy.clone(), cxz.clone()];
    let r1 = [cxy, cyy.clone(), cyz.clone()];
    let r2 = [cxz, cyz, czz.clone()];
    let n0 = cross(r1.clone(), r2.clone());
    let n1 = cross(r0.clone(), r2);
    let n2 = cross(r0, r1);
    let (l0, l1, l2) = (sq_norm(&n0), sq_norm(&n1), sq_norm(&n2));
    let pick1 = l1.clone().greater(l0.clone());
    let best01: [Tensor<2>; 3] =
        [0, 1, 2].map(|i| n0[i].clone().mask_where(pick1.clone(), n1[i].clone()));
    let l01 = l0.mask_where(pick1, l1);
    let pick2 = l2.clone().greater(l01.clone());
    let n: [Tensor<2>; 3] =
        [0, 1, 2].map(|i| best01[i].clone().mask_where(pick2.clone(), n2[i].clone()));
    let len2 = l01.mask_where(pick2, l2);
    // orientation: towards the camera at the origin, i.e. n . centroid < 0 in camera space
    // (the centroid in un-normalised coordinates is mean_window * spread + mean).
    let cen = [
        mx.mul_scalar(1.0 / scale).add_scalar(mean[0]),
        my.mul_scalar(1.0 / scale).add_scalar(mean[1]),
        mz.mul_scalar(1.0 / scale).add_scalar(mean[2]),
    ];
    let facing = n[0].clone() * cen[0].clone()
        + n[1].clone() * cen[1].clone()
        + n[2].clone() * cen[2].clone();
    let flip = facing.greater_elem(0.0);
    let n: [Tensor<2>; 3] =
        [0, 1, 2].map(|i| n[i].clone().mask_where(flip.clone(), n[i].clone().neg()));
    // degenerate patches: |adj(C)| negligible against trace(C)^2
    let trace = cxx + cyy + czz;
    let degenerate = len2
        .clone()
        .lower_equal(trace.square().square().mul_scalar(1e-10).add_scalar(1e-30));
    let inv = len2.add_scalar(1e-30).sqrt().recip();
    let fallback = [0.0f32, 0.0, 1.0];
    let n: Vec<Tensor<2>> = (0..3)
        .map(|i| (n[i].clone() * inv.clone()).mask_fill(degenerate.clone(), fallback[i]))
        .collect();
    let n = Tensor::stack::<3>(n, 0); // [3, hs, ws]
    let n = if ds > 1 {
        upsample_bilinear(n, h, w)
    } else {
        n
    };
    let len = n.clone().square().sum_dim(0).add_scalar(1e-12).sqrt(); // [1, h, w]
    (n / len).permute([1, 2, 0])
}

/// The normal-map image `(n + 1) / 2` of unit normals `[.., 3]`, as an [`gb_core::RgbImage`].
pub fn normals_to_image(normals: &[[f32; 3]], width: usize, height: usize) -> gb_core::RgbImage {
    let data = normals
        .iter()
        .flat_map(|n| n.map(|v| ((v + 1.0) * 0.5).clamp(0.0, 1.0)))
        .collect();
    gb_core::RgbImage {
        width,
        height,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane_depth(w: usize, h: usize, k: Intrinsics, n: [f32; 3], d: f32) -> Vec<f32> {
        // plane n . p = -d (camera space); p = z * (ax, ay, -1)
        let mut out = Vec::new();
        for v in 0..h {
            for u in 0..w {
                let ax = (u as f32 + 0.5 - k.cx) / k.fx;
                let ay = -(v as f32 + 0.5 - k.cy) / k.fy;
                let denom = n[0] * ax + n[1] * ay - n[2];
                out.push(-d / denom);
            }
        }
        out
    }

    #[test]
    fn tilted_plane_normal_is_recovered() {
        let device = gb_core::BackendKind::Flex.device();
        let (w, h) = (40, 32);
        let k = Intrinsics {
            fx: 40.0,
            fy: 40.0,
            cx: 20.0,
            cy: 16.0,
        };
        let nrm = {
            let v = [0.3f32, 0.4, 0.866];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            v.map(|x| x / l)
        };
        let depth = plane_depth(w, h, k, nrm, 3.0);
        let t = Tensor::<2>::from_data(TensorData::new(depth, [h, w]), &device);
        for cfg in [
            PlaneFitConfig {
                kernel: 5,
                downsample: 1,
            },
            PlaneFitConfig {
                kernel: 3,
                downsample: 4,
            },
        ] {
            let out: Vec<f32> = depth_to_normals(t.clone(), k, cfg)
                .into_data()
                .try_to_vec::<f32>()
                .unwrap();
            for px in out.chunks(3) {
                let dot = px[0] * nrm[0] + px[1] * nrm[1] + px[2] * nrm[2];
                assert!(dot > 0.999, "{px:?} vs {nrm:?} ({cfg:?})");
            }
        }
    }
}
