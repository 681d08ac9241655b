//! ST-LPIPS against stlpips-pytorch 0.0.2 (torch 2.15.0) on the same weights and fixtures,
//! on every test backend.

use crate::common;

use common::{expected, image, number, Deviation};
use gb_core::{heavy_test_backends, test_data_dir};
use gb_eval::stlpips::StLpips;
use gb_eval::MetricError;
use gb_eval::PerceptualDistance;

const TOL: f64 = 1e-4;

fn weights() -> std::path::PathBuf {
    test_data_dir().join("weights").join(StLpips::WEIGHTS_FILE)
}

#[test]
#[cfg_attr(
    gb_no_shared_data,
    ignore = "needs the shared test data (../shared or GB_TEST_DATA): weights/stlpips_alex_shift_tolerant.safetensors"
)]
fn stlpips_matches_the_package_on_every_backend() {
    let doc = expected();
    let cases = doc["cases"].as_array().unwrap();
    for kind in heavy_test_backends() {
        let model = StLpips::load(&weights(), &kind.device()).expect("weights load");
        let mut dev = Deviation::new("ST-LPIPS", TOL);
        // wgpu runs on a software rasteriser here: keep it to a few small cases.
        let take = if kind == gb_core::BackendKind::Wgpu {
            3
        } else {
            cases.len()
        };
        for c in cases.iter().take(take) {
            let name = c["name"].as_str().unwrap();
            let gt = image(c["gt"].as_str().unwrap());
            let pred = image(c["pred"].as_str().unwrap());
            dev.check(
                name,
                model.distance(&pred, &gt).unwrap(),
                number(&c["stlpips"]),
            );
        }
        println!("backend {kind}:");
        dev.report();
    }
}

#[test]
#[cfg_attr(
    gb_no_shared_data,
    ignore = "needs the shared test data (../shared or GB_TEST_DATA): weights/stlpips_alex_shift_tolerant.safetensors"
)]
fn identical_images_are_at_distance_zero_and_tiny_images_are_rejected() {
    let model = StLpips::load(&weights(), &gb_core::BackendKind::Flex.device()).unwrap();
    let img = image("fern_blur_gt.png");
    assert_eq!(model.distance(&img, &img).unwrap(), 0.0);
    let tiny = gb_core::RgbImage::filled(20, 40, [0.5; 3]);
    assert!(matches!(
        model.distance(&tiny, &tiny),
        Err(MetricError::TooSmall { min: 21, .. })
    ));
}

#[test]
fn missing_weights_name_the_file() {
    let err = StLpips::load(
        std::path::Path::new("/nonexistent/stlpips.safetensors"),
        &gb_core::BackendKind::Flex.device(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("/nonexistent/stlpips.safetensors"), "{err}");
}
