//! Small synthetic scenes built in code for the gb-nerf tests.
#![allow(dead_code)]

use gb_core::RgbImage;
use gb_nerf::field::{FieldConfig, HashGridConfig};
use gb_nerf::scene::{Camera, Mask, Scene, SceneKind, Split, View};

/// Texture of the ground plane z = 0.
pub fn albedo(x: f32, y: f32) -> [f32; 3] {
    [
        0.5 + 0.35 * (3.0 * x).sin(),
        0.5 + 0.35 * (2.0 * y).cos(),
        0.3 + 0.2 * (x + y).sin(),
    ]
}

/// A camera at `(ox, oy, 2)` looking straight down -z.
pub fn camera(ox: f32, oy: f32, w: usize, h: usize) -> Camera {
    Camera {
        width: w,
        height: h,
        fx: w as f32,
        fy: w as f32,
        cx: w as f32 / 2.0,
        cy: h as f32 / 2.0,
        c2w: [
            [1.0, 0.0, 0.0, ox],
            [0.0, 1.0, 0.0, oy],
            [0.0, 0.0, 1.0, 2.0],
        ],
    }
}

/// Renders the textured plane (z-depth 2 everywhere).
pub fn render_plane(cam: &Camera) -> (RgbImage, Vec<f32>) {
    let mut img = RgbImage::filled(cam.width, cam.height, [0.0; 3]);
    let o = cam.origin();
    for y in 0..cam.height {
        for x in 0..cam.width {
            let d = cam.ray_direction(x as f32 + 0.5, y as f32 + 0.5);
            let t = -o[2] / d[2];
            img.set(x, y, albedo(o[0] + t * d[0], o[1] + t * d[1]));
        }
    }
    (img, vec![2.0; cam.width * cam.height])
}

/// A bounded scene of a textured plane seen by `n_train` + 2 test cameras; train views
/// carry a square mask in their centre and ground-truth depth.
pub fn plane_scene(n_train: usize, w: usize, h: usize) -> Scene {
    let mut views = Vec::new();
    for i in 0..n_train + 2 {
        let a = i as f32 / (n_train + 2) as f32 * std::f32::consts::TAU;
        let cam = camera(0.3 * a.cos(), 0.3 * a.sin(), w, h);
        let (image, depth) = render_plane(&cam);
        let test = i >= n_train;
        let mut mask = Mask {
            width: w,
            height: h,
            data: vec![false; w * h],
        };
        for y in h / 3..h / 2 {
            for x in w / 3..w / 2 {
                mask.data[y * w + x] = true;
            }
        }
        views.push(View {
            name: format!("v{i:02}"),
            camera: cam,
            image,
            mask: (!test).then_some(mask),
            depth: Some(depth),
            normal: None,
            split: if test { Split::Test } else { Split::Train },
        });
    }
    Scene {
        name: "plane".into(),
        kind: SceneKind::Bounded {
            aabb_min: [-2.0, -2.0, -0.5],
            aabb_max: [2.0, 2.0, 0.5],
        },
        views,
        near: 1.0,
        far: 3.0,
        background: [0.0, 0.0, 0.0],
        warnings: vec![],
        sparse_depth: Default::default(),
    }
}

/// A tiny hash field: 4 levels, table 2^10.
pub fn tiny_hash() -> FieldConfig {
    FieldConfig::Hash {
        grid: HashGridConfig {
            levels: 4,
            features_per_level: 2,
            log2_table_size: 10,
            base_resolution: 4.0,
            max_resolution: 32.0,
            lookups: Default::default(),
        },
        hidden: 16,
        geo_features: 3,
        dir_freqs: 1,
        density_bias: 0.0,
    }
}
