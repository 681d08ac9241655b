//! The field and the renderer give the same outputs and parameter gradients on every
//! backend (ndarray, flex, wgpu/lavapipe) to a relative 1e-4, from identical parameters.

use crate::nerf_common;
use nerf_common as common;

use burn::module::Module;
use burn::store::ModuleRecord;
use burn::tensor::Tensor;
use gb_core::BackendKind;
use gb_nerf::field::{FieldConfig, NerfField};
use gb_nerf::render::{depth_to_normals, render_samples, Background, Intrinsics, PlaneFitConfig};
use gb_nerf::sampler::{sample_rays, RayBatch, SceneSpace};

fn vec_of<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().unwrap()
}

/// Everything compared between backends.
fn run(field: &NerfField) -> Vec<(String, Vec<f32>)> {
    let space = SceneSpace::Aabb {
        min: [-1.0; 3],
        max: [1.0; 3],
    };
    let mut rays = RayBatch::default();
    for i in 0..6 {
        let x = -0.6 + 0.2 * i as f32;
        rays.origins.push([x, 0.1 * i as f32 - 0.3, 3.0]);
        rays.dirs.push([0.05 * i as f32, -0.03, -1.0]);
        let (a, b) = space.ray_bounds(rays.origins[i], rays.dirs[i], 0.5, 6.0);
        rays.near.push(a);
        rays.far.push(b);
    }
    let samples = sample_rays::<rand_chacha::ChaCha8Rng>(&rays, &space, 12, None, None);
    let out = render_samples(
        field,
        &samples,
        Background {
            color: [0.1, 0.2, 0.3],
            depth: 6.0,
        },
    );
    let k = Intrinsics {
        fx: 3.0,
        fy: 3.0,
        cx: 1.5,
        cy: 1.0,
    };
    let normals = depth_to_normals(
        out.depth.clone().reshape([2, 3]),
        k,
        PlaneFitConfig {
            kernel: 3,
            downsample: 1,
        },
    );
    let weights: Vec<f32> = (0..18).map(|i| ((i * 7) % 5) as f32 * 0.1 - 0.2).collect();
    let nw = Tensor::<3>::from_data(
        burn::tensor::TensorData::new(weights, [2, 3, 3]),
        &field.device(),
    );
    let loss = out.rgb.clone().sum()
        + out.depth.clone().mul_scalar(0.3).sum()
        + out.opacity.clone().sum()
        + (normals.clone() * nw).sum();
    let grads = loss.backward();
    let mut v = vec![
        ("rgb".to_string(), vec_of(out.rgb)),
        ("depth".to_string(), vec_of(out.depth)),
        ("disparity".to_string(), vec_of(out.disparity)),
        ("opacity".to_string(), vec_of(out.opacity)),
        ("normals".to_string(), vec_of(normals)),
    ];
    if let Some(g) = &field.grid {
        v.push((
            "grad table".into(),
            vec_of(g.table.val().grad(&grads).unwrap()),
        ));
    }
    for (name, mlp) in [("density", &field.density_net), ("color", &field.color_net)] {
        for (i, l) in mlp.layers.iter().enumerate() {
            v.push((
                format!("grad {name}.{i}.w"),
                vec_of(l.weight.val().grad(&grads).unwrap()),
            ));
            let b = l.bias.as_ref().unwrap().val();
            v.push((
                format!("grad {name}.{i}.b"),
                vec_of(b.grad(&grads).unwrap()),
            ));
        }
    }
    v
}

fn assert_close(kind: BackendKind, a: &[(String, Vec<f32>)], b: &[(String, Vec<f32>)]) {
    for ((name, x), (_, y)) in a.iter().zip(b) {
        assert_eq!(x.len(), y.len(), "{kind} {name}");
        let scale = x.iter().fold(0.0f32, |m, v| m.max(v.abs())).max(1e-6);
        for (p, q) in x.iter().zip(y) {
            assert!(
                (p - q).abs() <= 1e-4 * scale,
                "{kind} {name}: {p} vs {q} (scale {scale})"
            );
        }
    }
}

fn check(config: FieldConfig) {
    // draws from Burn's process-global device RNG (crate::DEVICE_RNG)
    let _rng = crate::DEVICE_RNG.lock().unwrap_or_else(|e| e.into_inner());
    let reference_device = BackendKind::Flex.autodiff_device();
    reference_device.seed(7);
    let reference = config.init(&reference_device);
    let bytes = reference.clone().into_record().into_bytes().unwrap();
    let expected = run(&reference);
    for kind in gb_core::heavy_test_backends() {
        let device = kind.autodiff_device();
        let record = ModuleRecord::from_bytes(bytes.clone()).unwrap();
        let field = config.init(&device).load_record(record);
        assert_close(kind, &expected, &run(&field));
    }
}

#[test]
fn hash_field_and_renderer_agree_across_backends() {
    check(common::tiny_hash());
}

#[test]
fn vanilla_field_and_renderer_agree_across_backends() {
    check(FieldConfig::Vanilla {
        pos_freqs: 3,
        dir_freqs: 1,
        width: 16,
        depth: 3,
    });
}
