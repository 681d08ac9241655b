//! Standard LPIPS (AlexNet and VGG16 backbones) against the PyPI package `lpips` 0.1.4, on
//! "formula weights" (no LPIPS backbone weights exist here): both sides fill every tensor with
//! the same closed-form values, see tools/eval_parity/make_fixtures.py.

use crate::common;

use std::collections::HashMap;
use std::path::Path;

use common::{expected, image, number, Deviation};
use gb_core::BackendKind;
use gb_eval::lpips::{Backbone, Lpips, PerceptualDistance};
use safetensors::tensor::{Dtype, TensorView};

const TOL: f64 = 1e-4;

/// `(key prefix, out, in, kernel)` of each convolution, as the fixture script lists them.
fn convs(backbone: Backbone) -> Vec<(&'static str, usize, usize, usize)> {
    match backbone {
        Backbone::Alex => vec![
            ("net.slice1.0", 64, 3, 11),
            ("net.slice2.3", 192, 64, 5),
            ("net.slice3.6", 384, 192, 3),
            ("net.slice4.8", 256, 384, 3),
            ("net.slice5.10", 256, 256, 3),
        ],
        Backbone::Vgg => vec![
            ("net.slice1.0", 64, 3, 3),
            ("net.slice1.2", 64, 64, 3),
            ("net.slice2.5", 128, 64, 3),
            ("net.slice2.7", 128, 128, 3),
            ("net.slice3.10", 256, 128, 3),
            ("net.slice3.12", 256, 256, 3),
            ("net.slice3.14", 256, 256, 3),
            ("net.slice4.17", 512, 256, 3),
            ("net.slice4.19", 512, 512, 3),
            ("net.slice4.21", 512, 512, 3),
            ("net.slice5.24", 512, 512, 3),
            ("net.slice5.26", 512, 512, 3),
            ("net.slice5.28", 512, 512, 3),
        ],
    }
}

fn formula(t: usize, shape: &[usize], key: &str) -> Vec<f32> {
    let n: usize = shape.iter().product();
    let fan_in: usize = shape[1..].iter().product();
    (0..n)
        .map(|i| {
            let wave = (0.731 * i as f64 + 1.37 * t as f64 + 0.5).sin();
            let v = if key.starts_with("lin") {
                0.05 * (1.0 + wave)
            } else if key.ends_with(".bias") {
                0.01 * wave
            } else {
                2.0 / (fan_in as f64).sqrt() * wave
            };
            v as f32
        })
        .collect()
}

/// Writes the formula-weights state dict of `backbone` to `path`.
fn write_formula_weights(backbone: Backbone, path: &Path) {
    let mut tensors: Vec<(String, Vec<usize>)> = Vec::new();
    for (prefix, cout, cin, k) in convs(backbone) {
        tensors.push((format!("{prefix}.weight"), vec![cout, cin, k, k]));
        tensors.push((format!("{prefix}.bias"), vec![cout]));
    }
    let heads: Vec<usize> = match backbone {
        Backbone::Alex => vec![64, 192, 384, 256, 256],
        Backbone::Vgg => vec![64, 128, 256, 512, 512],
    };
    for (k, c) in heads.into_iter().enumerate() {
        tensors.push((format!("lin{k}.model.1.weight"), vec![1, c, 1, 1]));
    }
    let bytes: Vec<(String, Vec<usize>, Vec<u8>)> = tensors
        .into_iter()
        .enumerate()
        .map(|(t, (key, shape))| {
            let vals = formula(t, &shape, &key);
            (
                key,
                shape,
                vals.iter().flat_map(|v| v.to_le_bytes()).collect(),
            )
        })
        .collect();
    let views: HashMap<String, TensorView<'_>> = bytes
        .iter()
        .map(|(k, s, b)| {
            (
                k.clone(),
                TensorView::new(Dtype::F32, s.clone(), b).unwrap(),
            )
        })
        .collect();
    safetensors::serialize_to_file(views, None, path).unwrap();
}

fn check_backbone(backbone: Backbone, key: &'static str) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lpips.safetensors");
    write_formula_weights(backbone, &path);
    let model = Lpips::load(&path, backbone, &BackendKind::Flex.device()).unwrap();
    let doc = expected();
    let mut dev = Deviation::new(key, TOL);
    let mut seen = 0;
    for c in doc["cases"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| c.get(key).is_some())
    {
        let gt = image(c["gt"].as_str().unwrap());
        let pred = image(c["pred"].as_str().unwrap());
        dev.check(
            c["name"].as_str().unwrap(),
            model.distance(&pred, &gt).unwrap(),
            number(&c[key]),
        );
        seen += 1;
    }
    assert!(seen >= 3, "{key}: only {seen} cases");
    dev.report();
}

#[test]
fn lpips_alex_matches_the_package() {
    check_backbone(Backbone::Alex, "lpips_alex_formula");
}

#[test]
fn lpips_vgg_matches_the_package() {
    check_backbone(Backbone::Vgg, "lpips_vgg_formula");
}

#[test]
fn a_file_without_the_backbone_is_rejected_with_its_name() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("heads_only.safetensors");
    let b = vec![0u8; 64 * 4];
    let views = HashMap::from([(
        "lin0.model.1.weight".to_string(),
        TensorView::new(Dtype::F32, vec![1, 64, 1, 1], &b).unwrap(),
    )]);
    safetensors::serialize_to_file(views, None, &path).unwrap();
    let err = Lpips::load(&path, Backbone::Alex, &BackendKind::Flex.device())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("heads_only.safetensors") && err.contains("missing"),
        "{err}"
    );
}
