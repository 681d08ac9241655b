//! Parity with the plain-PyTorch references of `tools/nerf_parity/make_fixtures.py`
//! (fixture: `tests/fixtures/nerf_parity.json`): volume rendering, the hash encoding and the
//! depth-to-normal plane fit, forward and gradients, on every test backend.

use burn::module::Param;
use burn::tensor::{Tensor, TensorData};
use gb_nerf::field::{HashGrid, HashGridConfig};
use gb_nerf::render::{composite, depth_to_normals, Background, Intrinsics, PlaneFitConfig};
use serde_json::Value;

fn fixture() -> Value {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/nerf_parity.json"
    );
    serde_json::from_str(&std::fs::read_to_string(path).expect("fixture")).expect("json")
}

fn floats(v: &Value) -> Vec<f32> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number") as f32)
        .collect()
}

fn vec_of<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().unwrap()
}

fn assert_close(name: &str, got: &[f32], want: &[f32], rel: f32, abs: f32) {
    assert_eq!(got.len(), want.len(), "{name}: length");
    let scale = want.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let mut worst = 0.0f32;
    for (g, w) in got.iter().zip(want) {
        worst = worst.max((g - w).abs());
    }
    assert!(
        worst <= abs + rel * scale,
        "{name}: max abs error {worst} (scale {scale})"
    );
}

#[test]
fn volume_rendering_matches_pytorch() {
    let f = fixture();
    let v = &f["volume"];
    let (r, s) = (
        v["rays"].as_u64().unwrap() as usize,
        v["samples"].as_u64().unwrap() as usize,
    );
    for kind in gb_core::heavy_test_backends() {
        let dev = kind.autodiff_device();
        let t2 = |k: &str| Tensor::<2>::from_data(TensorData::new(floats(&v[k]), [r, s]), &dev);
        let sigma = t2("sigma").require_grad();
        let rgb = Tensor::<3>::from_data(TensorData::new(floats(&v["rgb"]), [r, s, 3]), &dev)
            .require_grad();
        let bg = floats(&v["background"]);
        let out = composite(
            sigma.clone(),
            rgb.clone(),
            t2("t"),
            t2("delta"),
            Background {
                color: [bg[0], bg[1], bg[2]],
                depth: v["background_depth"].as_f64().unwrap() as f32,
            },
        );
        let g1 = |k: &str| Tensor::<1>::from_data(TensorData::new(floats(&v[k]), [r]), &dev);
        let grgb = Tensor::<2>::from_data(TensorData::new(floats(&v["g_rgb"]), [r, 3]), &dev);
        let loss = (out.rgb.clone() * grgb).sum()
            + (out.depth.clone() * g1("g_depth")).sum()
            + (out.disparity.clone() * g1("g_disparity")).sum()
            + (out.opacity.clone() * g1("g_opacity")).sum();
        let grads = loss.backward();
        let tol = |n: &str| format!("{kind} {n}");
        assert_close(
            &tol("rgb"),
            &vec_of(out.rgb),
            &floats(&v["out_rgb"]),
            1e-5,
            1e-6,
        );
        assert_close(
            &tol("depth"),
            &vec_of(out.depth),
            &floats(&v["out_depth"]),
            1e-5,
            1e-6,
        );
        assert_close(
            &tol("disparity"),
            &vec_of(out.disparity),
            &floats(&v["out_disparity"]),
            1e-5,
            1e-6,
        );
        assert_close(
            &tol("opacity"),
            &vec_of(out.opacity),
            &floats(&v["out_opacity"]),
            1e-5,
            1e-6,
        );
        assert_close(
            &tol("weights"),
            &vec_of(out.weights),
            &floats(&v["out_weights"]),
            1e-5,
            1e-6,
        );
        assert_close(
            &tol("grad sigma"),
            &vec_of(sigma.grad(&grads).unwrap()),
            &floats(&v["grad_sigma"]),
            1e-4,
            1e-6,
        );
        assert_close(
            &tol("grad rgb"),
            &vec_of(rgb.grad(&grads).unwrap()),
            &floats(&v["grad_rgb"]),
            1e-4,
            1e-6,
        );
    }
}

#[test]
fn hash_encoding_matches_pytorch() {
    let f = fixture();
    let h = &f["hash"];
    let cfg = HashGridConfig {
        levels: h["levels"].as_u64().unwrap() as usize,
        features_per_level: h["features_per_level"].as_u64().unwrap() as usize,
        log2_table_size: h["log2_table_size"].as_u64().unwrap() as u32,
        base_resolution: h["base_resolution"].as_f64().unwrap() as f32,
        max_resolution: h["max_resolution"].as_f64().unwrap() as f32,
        lookups: Default::default(),
    };
    let pts: Vec<[f32; 3]> = floats(&h["points"])
        .chunks(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    let n = pts.len();
    let width = cfg.output_dim();
    for kind in gb_core::heavy_test_backends() {
        let dev = kind.autodiff_device();
        let rows = cfg.levels * cfg.table_size();
        let table = Tensor::<2>::from_data(
            TensorData::new(floats(&h["table"]), [rows, cfg.features_per_level]),
            &dev,
        );
        let grid = HashGrid {
            table: Param::from_tensor(table),
            config: cfg,
        };
        let out = grid.encode(&pts);
        let g = Tensor::<2>::from_data(TensorData::new(floats(&h["g"]), [n, width]), &dev);
        let grads = (out.clone() * g).sum().backward();
        assert_close(
            &format!("{kind} hash out"),
            &vec_of(out),
            &floats(&h["out"]),
            1e-5,
            1e-6,
        );
        let gt = grid.table.val().grad(&grads).unwrap();
        assert_close(
            &format!("{kind} hash grad"),
            &vec_of(gt),
            &floats(&h["grad_table"]),
            1e-5,
            1e-6,
        );
    }
}

#[test]
fn plane_fit_matches_pytorch() {
    let f = fixture();
    let p = &f["plane_fit"];
    let (h, w) = (
        p["height"].as_u64().unwrap() as usize,
        p["width"].as_u64().unwrap() as usize,
    );
    let k = Intrinsics {
        fx: p["fx"].as_f64().unwrap() as f32,
        fy: p["fy"].as_f64().unwrap() as f32,
        cx: p["cx"].as_f64().unwrap() as f32,
        cy: p["cy"].as_f64().unwrap() as f32,
    };
    for kind in gb_core::heavy_test_backends() {
        let dev = kind.autodiff_device();
        for case in p["cases"].as_array().unwrap() {
            let cfg = PlaneFitConfig {
                kernel: case["kernel"].as_u64().unwrap() as usize,
                downsample: case["downsample"].as_u64().unwrap() as usize,
            };
            let depth = Tensor::<2>::from_data(TensorData::new(floats(&p["depth"]), [h, w]), &dev)
                .require_grad();
            let n = depth_to_normals(depth.clone(), k, cfg);
            let g = Tensor::<3>::from_data(TensorData::new(floats(&case["g"]), [h, w, 3]), &dev);
            let grads = (n.clone() * g).sum().backward();
            let name = format!("{kind} {cfg:?}");
            assert_close(
                &format!("{name} normals"),
                &vec_of(n),
                &floats(&case["normals"]),
                0.0,
                1e-4,
            );
            let gd = vec_of(depth.grad(&grads).unwrap());
            assert_close(
                &format!("{name} grad"),
                &gd,
                &floats(&case["grad_depth"]),
                1e-3,
                1e-5,
            );
        }
    }
}
