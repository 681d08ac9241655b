//! Volume rendering and normals at the numerical extremes: finite outputs and gradients,
//! opacity in [0, 1], weights summing to at most 1 + 1e-6, documented empty-ray outputs.

use crate::nerf_common;
use nerf_common as common;

use burn::tensor::{Tensor, TensorData};
use gb_core::BackendKind;
use gb_nerf::render::{composite, depth_to_normals, Background, Intrinsics, PlaneFitConfig};

const DENSITIES: [f32; 6] = [0.0, 1e-30, 1e-6, 1e6, 1e30, f32::MAX];
const DELTAS: [f32; 3] = [0.0, 1e-12, 1e10];
const FAR: f32 = 1e10;

fn finite(v: &[f32]) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn vec_of<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().unwrap()
}

/// Every density at every position of a ray for every delta, with consistent distances.
fn extreme_rays(samples: usize) -> (Vec<f32>, Vec<f32>, Vec<f32>, usize) {
    let (mut sigma, mut t, mut delta) = (vec![], vec![], vec![]);
    let mut rays = 0;
    for &d in &DELTAS {
        for start in 0..DENSITIES.len() {
            let mut acc = 0.0f32;
            for i in 0..samples {
                sigma.push(DENSITIES[(start + i) % DENSITIES.len()]);
                delta.push(d);
                t.push((acc + 0.5 * d).min(FAR));
                acc = (acc + d).min(FAR);
            }
            rays += 1;
        }
    }
    (sigma, t, delta, rays)
}

fn check_extremes(kind: BackendKind, samples: usize) {
    let device = kind.autodiff_device();
    let (sigma, t, delta, r) = extreme_rays(samples);
    let s = samples;
    let sigma = Tensor::<2>::from_data(TensorData::new(sigma, [r, s]), &device).require_grad();
    let colors: Vec<f32> = (0..r * s * 3).map(|i| (i % 7) as f32 / 7.0).collect();
    let rgb = Tensor::<3>::from_data(TensorData::new(colors, [r, s, 3]), &device).require_grad();
    let t = Tensor::<2>::from_data(TensorData::new(t, [r, s]), &device);
    let delta = Tensor::<2>::from_data(TensorData::new(delta, [r, s]), &device);
    let out = composite(
        sigma.clone(),
        rgb.clone(),
        t,
        delta,
        Background {
            color: [0.2, 0.4, 0.6],
            depth: FAR,
        },
    );
    let loss = out.rgb.clone().sum()
        + out.depth.clone().mul_scalar(1e-10).sum()
        + out.disparity.clone().sum()
        + out.opacity.clone().sum();
    let grads = loss.backward();
    let (c, d, disp, a, w) = (
        vec_of(out.rgb),
        vec_of(out.depth),
        vec_of(out.disparity),
        vec_of(out.opacity),
        vec_of(out.weights),
    );
    assert!(
        finite(&c) && finite(&d) && finite(&disp) && finite(&a) && finite(&w),
        "{kind}: non-finite output"
    );
    assert!(
        a.iter().all(|v| (0.0..=1.0).contains(v)),
        "{kind}: opacity {a:?}"
    );
    for ray in w.chunks(s) {
        let sum: f32 = ray.iter().sum();
        assert!(
            sum <= 1.0 + 1e-6 && ray.iter().all(|x| *x >= 0.0),
            "{kind}: weights {ray:?}"
        );
    }
    // delta = 0 rays are empty: background colour and depth, no NaN
    for ray in 0..DENSITIES.len() {
        assert_eq!(a[ray], 0.0);
        assert_eq!(d[ray], FAR);
        assert!((c[ray * 3] - 0.2).abs() < 1e-6 && (c[ray * 3 + 2] - 0.6).abs() < 1e-6);
    }
    let gs = vec_of(sigma.grad(&grads).expect("sigma grad"));
    let gc = vec_of(rgb.grad(&grads).expect("rgb grad"));
    assert!(finite(&gs), "{kind}: sigma grad {gs:?}");
    assert!(finite(&gc), "{kind}: rgb grad");
}

#[test]
fn extreme_densities_and_deltas_stay_finite_on_every_backend() {
    for kind in gb_core::test_backends() {
        check_extremes(kind, 8);
    }
}

#[test]
fn one_sample_per_ray_stays_finite() {
    check_extremes(BackendKind::Flex, 1);
}

#[test]
fn field_parameter_gradients_are_finite_at_extremes() {
    // draws from Burn's process-global device RNG (crate::DEVICE_RNG)
    let _rng = crate::DEVICE_RNG.lock().unwrap_or_else(|e| e.into_inner());
    use burn::module::Module;
    use gb_nerf::render::render_samples;
    use gb_nerf::sampler::{sample_rays, RayBatch, SceneSpace};

    let device = BackendKind::Flex.autodiff_device();
    let field = common::tiny_hash().init(&device);
    let space = SceneSpace::Aabb {
        min: [-1.0; 3],
        max: [1.0; 3],
    };
    // a normal ray, a grazing ray along the box face, an empty ray and a far-bound ray
    let rays = RayBatch {
        origins: vec![
            [0.0, 0.0, 3.0],
            [-3.0, 0.999_999, 0.0],
            [5.0, 5.0, 5.0],
            [0.0, 0.0, 3.0],
        ],
        dirs: vec![
            [0.0, 0.0, -1.0],
            [1.0, 1e-7, 0.0],
            [0.0, 0.0, -1.0],
            [0.0, 0.0, -1.0],
        ],
        near: vec![0.0; 4],
        far: vec![10.0, 10.0, 10.0, FAR],
    };
    let mut rays = rays;
    for i in 0..rays.len() {
        let (a, b) = space.ray_bounds(rays.origins[i], rays.dirs[i], rays.near[i], rays.far[i]);
        rays.near[i] = a;
        rays.far[i] = b;
    }
    let samples = sample_rays::<rand_chacha::ChaCha8Rng>(&rays, &space, 16, None, None);
    let out = render_samples(
        &field,
        &samples,
        Background {
            color: [1.0; 3],
            depth: FAR,
        },
    );
    let loss = out.rgb.sum() + out.disparity.sum() + out.opacity.sum();
    let grads = loss.backward();
    let mut checked = 0;
    let table = field.grid.as_ref().unwrap().table.val();
    assert!(finite(&vec_of(table.grad(&grads).unwrap())));
    for mlp in [&field.density_net, &field.color_net] {
        for layer in &mlp.layers {
            assert!(finite(&vec_of(layer.weight.val().grad(&grads).unwrap())));
            let b = layer.bias.as_ref().unwrap().val();
            assert!(finite(&vec_of(b.grad(&grads).unwrap())));
            checked += 2;
        }
    }
    assert_eq!(checked, 10);
    assert!(field.num_params() > 0);
    // the empty ray (index 2) renders the documented background
    let d = vec_of(out.depth);
    assert_eq!(d[2], FAR);
}

#[test]
fn plane_fit_is_finite_on_flat_constant_and_degenerate_patches() {
    let device = BackendKind::Flex.autodiff_device();
    let k = Intrinsics {
        fx: 20.0,
        fy: 20.0,
        cx: 8.0,
        cy: 6.0,
    };
    let (w, h) = (16, 12);
    let mut grazing = vec![0.0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            grazing[y * w + x] = 1.0 + 1e4 * x as f32; // nearly edge-on plane
        }
    }
    let patches: Vec<(&str, Vec<f32>)> = vec![
        ("constant", vec![2.0; w * h]),
        ("zero", vec![0.0; w * h]),
        ("far", vec![FAR; w * h]),
        ("grazing", grazing),
        (
            "step",
            (0..w * h)
                .map(|i| if i % w < w / 2 { 1.0 } else { 1e6 })
                .collect(),
        ),
    ];
    for (name, depth) in patches {
        for cfg in [
            PlaneFitConfig {
                kernel: 5,
                downsample: 1,
            },
            PlaneFitConfig {
                kernel: 1,
                downsample: 1,
            },
            PlaneFitConfig {
                kernel: 31,
                downsample: 7,
            },
        ] {
            let d = Tensor::<2>::from_data(TensorData::new(depth.clone(), [h, w]), &device)
                .require_grad();
            let n = depth_to_normals(d.clone(), k, cfg);
            let grads = n.clone().sum().backward();
            let nv = vec_of(n);
            assert!(finite(&nv), "{name} {cfg:?}: {nv:?}");
            for px in nv.chunks(3) {
                let len = (px[0] * px[0] + px[1] * px[1] + px[2] * px[2]).sqrt();
                assert!((len - 1.0).abs() < 1e-3, "{name} {cfg:?}: |n| = {len}");
            }
            assert!(
                finite(&vec_of(d.grad(&grads).unwrap())),
                "{name} {cfg:?}: grad"
            );
            if name == "constant" || name == "zero" {
                // fronto-parallel / degenerate patches face the camera
                assert!(nv.chunks(3).all(|p| p[2] > 0.999), "{name} {cfg:?}");
            }
        }
    }
}
