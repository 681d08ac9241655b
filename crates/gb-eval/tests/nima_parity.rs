//! NIMA (pyiqa `nima`: timm inception_resnet_v2 + Linear(1536, 10) + softmax) against timm
//! 1.0.31 and torchvision 0.29.2, with deterministic pseudo-random weights that this test and
//! tools/eval_parity_nima/make_fixtures.py generate bit for bit (no weights are committed:
//! fixtures/nima/weights.json holds the tensor names, shapes and a checksum of each).
//!
//! Per image (a 61x50 one, upsampled, and a 232x174 one, downsampled), at a 96-px input:
//! - the input pipeline (antialiased bilinear resize, center crop, normalisation) against
//!   torchvision's;
//! - pooled features, logits and distribution of the network on torchvision's input;
//! - the end-to-end score from the PNG.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::tensor::{Tensor, TensorData};
use gb_core::{heavy_test_backends, read_rgb};
use gb_eval::fid::safetensors_f32::F32Tensors;
use gb_eval::nima::{mean_score, nima_score, preprocess, Nima, NimaError, NUM_BINS};
use safetensors::tensor::{Dtype, TensorView};

const INPUT_SIZE: usize = 96;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/nima")
}

/// The ordered tensor list of the pyiqa state dict, with the Python generator's checksums.
struct WeightsSpec {
    names: Vec<String>,
    shapes: Vec<Vec<usize>>,
    checksums: Vec<u64>,
    index: HashMap<String, usize>,
}

fn weights_spec() -> WeightsSpec {
    let text = std::fs::read_to_string(fixtures().join("weights.json")).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    let mut spec = WeightsSpec {
        names: Vec::new(),
        shapes: Vec::new(),
        checksums: Vec::new(),
        index: HashMap::new(),
    };
    for (k, entry) in json["tensors"].as_array().unwrap().iter().enumerate() {
        let name = entry[0].as_str().unwrap().to_string();
        let shape: Vec<usize> = entry[1]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as usize)
            .collect();
        let checksum = u64::from_str_radix(entry[2].as_str().unwrap(), 16).unwrap();
        spec.index.insert(name.clone(), k);
        spec.names.push(name);
        spec.shapes.push(shape);
        spec.checksums.push(checksum);
    }
    spec
}

/// `u(k, i)`: the splitmix64 finaliser of `(k << 32) | i`, top 24 bits mapped exactly to
/// [-1, 1) (see make_fixtures.py).
fn unit(k: u64, i: u64) -> f32 {
    let mut z = ((k << 32) | i).wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    ((z >> 40) as i64 - (1 << 23)) as f32 / (1u32 << 23) as f32
}

/// The values of tensor number `k` (the Python generator's rules, re-derived from the name).
fn generate(spec: &WeightsSpec, k: usize) -> Vec<f32> {
    let name = &spec.names[k];
    let shape = &spec.shapes[k];
    let n: usize = shape.iter().product();
    let u = (0..n as u64).map(|i| unit(k as u64, i));
    if name.ends_with(".running_mean") || name.ends_with(".bn.bias") {
        u.map(|u| 0.1f32 * u).collect()
    } else if name.ends_with(".running_var") {
        u.map(|u| 1.0f32 + 0.5f32 * u.abs()).collect()
    } else if name.ends_with(".bn.weight") {
        u.map(|u| 1.0f32 + 0.1f32 * u).collect()
    } else {
        let weight_shape = match name.strip_suffix("bias") {
            Some(stem) => &spec.shapes[spec.index[&format!("{stem}weight")]],
            None => shape,
        };
        let fan_in: usize = weight_shape[1..].iter().product();
        let scale = (6.0f64 / fan_in as f64).sqrt() as f32;
        u.map(|u| u * scale).collect()
    }
}

fn checksum(values: &[f32]) -> u64 {
    values.iter().enumerate().fold(0u64, |acc, (i, v)| {
        acc.wrapping_add(u64::from(v.to_bits()).wrapping_mul(i as u64 + 1))
    })
}

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

fn to_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().unwrap()
}

#[test]
fn nima_matches_timm_and_torchvision_with_generated_weights() {
    let spec = weights_spec();
    let expected = F32Tensors::read(&fixtures().join("expected.safetensors")).unwrap();
    assert!(spec.names.len() > 1000, "{} tensors", spec.names.len());
    let mut worst = [0.0f32; 6];
    for backend in heavy_test_backends() {
        let device = backend.device();
        let start = Instant::now();
        let mut requested = Vec::new();
        let model = Nima::from_fn(
            |name, shape| {
                let k = *spec.index.get(name)?;
                assert_eq!(shape, spec.shapes[k].as_slice(), "{name}");
                let values = generate(&spec, k);
                assert_eq!(
                    checksum(&values),
                    spec.checksums[k],
                    "{name}: generated weights differ from the Python generator's"
                );
                requested.push(k);
                Some(values)
            },
            "generated weights",
            &device,
        )
        .unwrap()
        .with_input_size(INPUT_SIZE)
        .unwrap();
        // Every tensor of the pyiqa state dict is used once, in timm's order.
        assert_eq!(requested, (0..spec.names.len()).collect::<Vec<_>>());
        let loaded = start.elapsed();

        for n in 0..2 {
            let get = |key: &str| expected.get_any(&format!("image_{n}.{key}")).unwrap().1;
            let s = INPUT_SIZE;
            // Input pipeline.
            let image = read_rgb(&fixtures().join(format!("image_{n}.png")), None).unwrap();
            let input = preprocess(&image, s).unwrap();
            let want_input = get("input");
            let d_input = max_abs_diff(&input, &want_input);

            // Network on torchvision's input.
            let x = Tensor::<4>::from_data(TensorData::new(want_input, [1, 3, s, s]), &device);
            let out = model.forward(x);
            let features = to_vec(out.features);
            let want_features = get("features");
            let scale = want_features.iter().fold(1.0f32, |m, v| m.max(v.abs()));
            let d_features = max_abs_diff(&features, &want_features) / scale;
            let d_logits = max_abs_diff(&to_vec(out.logits), &get("logits"));
            let dist = to_vec(out.distribution);
            let d_dist = max_abs_diff(&dist, &get("dist"));

            // End to end from the PNG.
            let prediction = model.predict(&image).unwrap();
            let want_mos = f64::from(get("mos")[0]);
            let d_e2e_dist = max_abs_diff(&prediction.distribution, &get("dist"));
            let d_mos = (prediction.mean - want_mos).abs();
            eprintln!(
                "{backend} image_{n}: input {d_input:.2e}, features {d_features:.2e} (relative \
                 to max |f| {scale:.3}), logits {d_logits:.2e}, dist {d_dist:.2e}, end-to-end \
                 dist {d_e2e_dist:.2e}, mos {:.6} vs {want_mos:.6} ({d_mos:.2e})",
                prediction.mean
            );
            for (w, d) in worst.iter_mut().zip([
                d_input,
                d_features,
                d_logits,
                d_dist,
                d_e2e_dist,
                d_mos as f32,
            ]) {
                *w = w.max(d);
            }
            assert!(d_input <= 1e-5, "{backend} image_{n}: input {d_input}");
            assert!(
                d_features <= 1e-4,
                "{backend} image_{n}: features {d_features}"
            );
            assert!(d_logits <= 1e-4, "{backend} image_{n}: logits {d_logits}");
            assert!(d_dist <= 1e-4, "{backend} image_{n}: dist {d_dist}");
            assert!(d_e2e_dist <= 1e-4, "{backend} image_{n}: e2e {d_e2e_dist}");
            assert!(d_mos <= 1e-3, "{backend} image_{n}: mos {d_mos}");
            assert_eq!(nima_score(&model, &image).unwrap(), prediction.mean);
            assert!((mean_score(&dist) - want_mos).abs() < 1e-4);
        }
        eprintln!(
            "{backend}: weights generated and loaded in {:.1} s, total {:.1} s",
            loaded.as_secs_f64(),
            start.elapsed().as_secs_f64()
        );
    }
    eprintln!(
        "worst: input {:.2e}, features (rel) {:.2e}, logits {:.2e}, dist {:.2e}, e2e dist {:.2e}, mos {:.2e}",
        worst[0], worst[1], worst[2], worst[3], worst[4], worst[5]
    );
}

#[test]
fn the_two_fixture_images_get_different_scores() {
    // Guards the fixture itself: the random network must not be blind to its input.
    let expected = F32Tensors::read(&fixtures().join("expected.safetensors")).unwrap();
    let f0 = expected.get_any("image_0.features").unwrap().1;
    let f1 = expected.get_any("image_1.features").unwrap().1;
    let norm = |v: &[f32]| v.iter().map(|x| x * x).sum::<f32>().sqrt();
    let diff: Vec<f32> = f0.iter().zip(&f1).map(|(a, b)| a - b).collect();
    assert!(norm(&diff) > 0.2 * norm(&f0));
    let m0 = expected.get_any("image_0.mos").unwrap().1[0];
    let m1 = expected.get_any("image_1.mos").unwrap().1[0];
    assert!((m0 - m1).abs() > 0.05, "{m0} {m1}");
    let d = expected.get_any("image_0.dist").unwrap();
    assert_eq!(d.0, vec![1, NUM_BINS]);
}

fn write_safetensors(path: &Path, tensors: &[(&str, Vec<usize>)]) {
    let bytes: Vec<(String, Vec<usize>, Vec<u8>)> = tensors
        .iter()
        .map(|(n, s)| {
            let len: usize = s.iter().product();
            (n.to_string(), s.clone(), vec![0u8; 4 * len])
        })
        .collect();
    let views: HashMap<String, TensorView<'_>> = bytes
        .iter()
        .map(|(n, s, b)| {
            (
                n.clone(),
                TensorView::new(Dtype::F32, s.clone(), b).unwrap(),
            )
        })
        .collect();
    safetensors::serialize_to_file(views, None, path).unwrap();
}

#[test]
fn bad_weights_files_name_the_tensor_and_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let device = gb_core::BackendKind::Flex.device();

    // pyiqa prefix, first tensor present, the next one missing.
    let path = dir.path().join("partial.safetensors");
    write_safetensors(
        &path,
        &[("base_model.conv2d_1a.conv.weight", vec![32, 3, 3, 3])],
    );
    let err = Nima::load(&path, &device).unwrap_err();
    match &err {
        NimaError::MissingTensor { path: p, tensor } => {
            assert_eq!(p, &path);
            assert_eq!(tensor, "base_model.conv2d_1a.bn.weight");
        }
        other => panic!("unexpected {other}"),
    }
    let msg = err.to_string();
    assert!(msg.contains("partial.safetensors") && msg.contains("conv2d_1a.bn.weight"));

    // Another prefix in front of pyiqa's keys is followed.
    let path = dir.path().join("prefixed.safetensors");
    write_safetensors(
        &path,
        &[("net.base_model.conv2d_1a.conv.weight", vec![32, 3, 3, 3])],
    );
    match Nima::load(&path, &device).unwrap_err() {
        NimaError::MissingTensor { tensor, .. } => {
            assert_eq!(tensor, "net.base_model.conv2d_1a.bn.weight")
        }
        other => panic!("unexpected {other}"),
    }

    // A bare timm state dict with a wrong shape.
    let path = dir.path().join("wrong_shape.safetensors");
    write_safetensors(&path, &[("conv2d_1a.conv.weight", vec![32, 3, 5, 5])]);
    let err = Nima::load(&path, &device).unwrap_err();
    match &err {
        NimaError::BadTensor {
            path: p,
            tensor,
            got,
            expected,
            ..
        } => {
            assert_eq!(p, &path);
            assert_eq!(tensor, "conv2d_1a.conv.weight");
            assert_eq!(got, &vec![32, 3, 5, 5]);
            assert_eq!(expected, &vec![32, 3, 3, 3]);
        }
        other => panic!("unexpected {other}"),
    }
    assert!(err.to_string().contains("wrong_shape.safetensors"));

    // Not a safetensors file; no file at all.
    let path = dir.path().join("garbage.safetensors");
    std::fs::write(&path, b"not a safetensors file").unwrap();
    assert!(matches!(
        Nima::load(&path, &device),
        Err(NimaError::Format { .. })
    ));
    let missing = dir.path().join("absent.safetensors");
    let err = Nima::load(&missing, &device).unwrap_err();
    assert!(matches!(err, NimaError::Io { .. }));
    assert!(err.to_string().contains("absent.safetensors"));

    // A generator that lacks a tensor.
    let err = Nima::from_fn(|_, _| None, "empty source", &device).unwrap_err();
    assert!(err.to_string().contains("empty source"));
    assert!(err.to_string().contains("base_model.conv2d_1a.conv.weight"));
}

#[test]
fn the_mean_score_is_pyiqas_dist_to_mos() {
    let mut uniform = [0.1f32; NUM_BINS];
    assert!((mean_score(&uniform) - 5.5).abs() < 1e-6);
    uniform = [0.0; NUM_BINS];
    uniform[9] = 1.0;
    assert_eq!(mean_score(&uniform), 10.0);
}
