//! BRISQUE against `cv2.quality.QualityBRISQUE` (opencv-contrib-python-headless 4.14.0.94):
//! features and scores on fixture images from tools/eval_parity_fid_brisque/make_fixtures.py.

use std::path::{Path, PathBuf};

use gb_eval::brisque::{
    brisque_features, gray_from_rgb8, libsvm, quantize_rgb, Brisque, BrisqueError, RbfSvr,
    FEATURE_COUNT,
};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/brisque")
}

fn expected() -> serde_json::Value {
    let text = std::fs::read_to_string(fixtures().join("expected.json")).expect("expected.json");
    serde_json::from_str(&text).expect("expected.json is JSON")
}

fn load_opencv_model() -> Brisque {
    Brisque::load_opencv_dir(&gb_core::test_data_dir().join("weights"))
        .expect("BRISQUE model in shared/weights")
}

// fails when the shared data appeared after this crate was built without it
gb_core::shared_data_guard!();

#[test]
#[cfg_attr(
    gb_no_shared_data,
    ignore = "needs the shared test data (../shared or GB_TEST_DATA): weights/brisque_*_live.yml"
)]
fn features_and_scores_match_opencv_within_1e_3() {
    let model = load_opencv_model();
    let exp = expected();
    let mut worst_feature = (0.0f64, String::new());
    let mut worst_score = (0.0f64, String::new());
    let mut checked = 0;
    for (name, entry) in exp.as_object().unwrap() {
        if name.starts_with('_') {
            continue;
        }
        let img = gb_core::read_rgb(&fixtures().join(format!("{name}.png")), None).unwrap();
        let gray = gray_from_rgb8(&quantize_rgb(&img), img.width, img.height).unwrap();
        let feats = brisque_features(&gray).unwrap();
        let want: Vec<f64> = entry["features"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(want.len(), FEATURE_COUNT);
        for (i, (got, want)) in feats.iter().zip(&want).enumerate() {
            let d = (*got as f64 - want).abs();
            if d > worst_feature.0 {
                worst_feature = (d, format!("{name}[{i}]: {got} vs {want}"));
            }
        }
        let score = model.score(&img).unwrap();
        let want_score = entry["score"].as_f64().unwrap();
        let d = (score - want_score).abs();
        if d > worst_score.0 {
            worst_score = (d, format!("{name}: {score} vs {want_score}"));
        }
        checked += 1;
    }
    eprintln!(
        "BRISQUE worst feature deviation {:.3e} ({})",
        worst_feature.0, worst_feature.1
    );
    eprintln!(
        "BRISQUE worst score deviation {:.3e} ({})",
        worst_score.0, worst_score.1
    );
    assert!(checked >= 6, "only {checked} fixture images");
    assert!(
        worst_feature.0 <= 1e-3,
        "feature deviation {:?}",
        worst_feature
    );
    assert!(worst_score.0 <= 1e-3, "score deviation {:?}", worst_score);
}

#[test]
#[cfg_attr(
    gb_no_shared_data,
    ignore = "needs the shared test data (../shared or GB_TEST_DATA): weights/brisque_*_live.yml"
)]
fn opencv_model_file_is_read_completely() {
    let model = load_opencv_model();
    assert_eq!(model.svr.dim, 36);
    assert_eq!(model.svr.coefs.len(), 774);
    assert_eq!(model.svr.support_vectors.len(), 774 * 36);
    assert!((model.svr.gamma - 0.05).abs() < 1e-15);
    assert!((model.svr.rho - -149.63506109127357).abs() < 1e-9);
    assert_eq!(model.range.min.len(), 36);
    assert_eq!(model.range.min[0], 0.344_f32);
    assert_eq!(model.range.max[35], 0.538_609_2_f32);
}

#[test]
fn libsvm_text_model_predicts_like_the_libsvm_formula() {
    let svr =
        libsvm::load_libsvm_model(&fixtures().join("tiny_libsvm.model"), FEATURE_COUNT).unwrap();
    assert_eq!(svr.coefs.len(), 5);
    let exp = expected();
    let tiny = &exp["_tiny_libsvm"];
    let mut worst = 0.0f64;
    for (x, want) in tiny["inputs"]
        .as_array()
        .unwrap()
        .iter()
        .zip(tiny["predictions"].as_array().unwrap())
    {
        let x: Vec<f32> = x
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap() as f32)
            .collect();
        // The reference used the f64 inputs; feed the f32-rounded ones to both sides' formula.
        let got = svr.predict(&x);
        worst = worst.max((got - want.as_f64().unwrap()).abs());
    }
    eprintln!("libsvm tiny model worst deviation {worst:.3e}");
    // Inputs were rounded to f32 (|dx| < 6e-8); with |coef| <= 50 and 5 vectors the effect is < 1e-4.
    assert!(worst < 1e-4, "{worst}");
}

#[test]
#[cfg_attr(
    gb_no_shared_data,
    ignore = "needs the shared test data (../shared or GB_TEST_DATA): weights/brisque_*_live.yml"
)]
fn libsvm_model_with_svm_scale_range_scores_an_image() {
    // The OpenCV model converted to libsvm text and an svm-scale range file must give the
    // same score as the YAML pair (up to the f32 kernel arithmetic OpenCV uses).
    let opencv = load_opencv_model();
    let dir = tempfile::tempdir().unwrap();
    let model_path = dir.path().join("brisque.model");
    let range_path = dir.path().join("brisque.range");
    let mut text = format!(
        "svm_type epsilon_svr\nkernel_type rbf\ngamma {}\nnr_class 2\ntotal_sv {}\nrho {}\nSV\n",
        opencv.svr.gamma,
        opencv.svr.coefs.len(),
        opencv.svr.rho
    );
    for (c, sv) in opencv
        .svr
        .coefs
        .iter()
        .zip(opencv.svr.support_vectors.chunks_exact(36))
    {
        text.push_str(&format!("{c}"));
        for (i, v) in sv.iter().enumerate() {
            text.push_str(&format!(" {}:{v}", i + 1));
        }
        text.push('\n');
    }
    std::fs::write(&model_path, text).unwrap();
    let mut range = String::from("x\n-1 1\n");
    for i in 0..36 {
        range.push_str(&format!(
            "{} {} {}\n",
            i + 1,
            opencv.range.min[i],
            opencv.range.max[i]
        ));
    }
    std::fs::write(&range_path, range).unwrap();
    let lib = Brisque::load_libsvm(&model_path, &range_path).unwrap();
    let img = gb_core::read_rgb(&fixtures().join("photo.png"), None).unwrap();
    let (a, b) = (opencv.score(&img).unwrap(), lib.score(&img).unwrap());
    // The libsvm path keeps the kernel sum in f64; OpenCV rounds kernel values to f32, which
    // moves the score by a few 1e-4 (|alpha| = 1024 sums cancel).
    assert!((a - b).abs() < 2e-3, "{a} vs {b}");
}

#[test]
#[cfg_attr(
    gb_no_shared_data,
    ignore = "needs the shared test data (../shared or GB_TEST_DATA): weights/brisque_*_live.yml"
)]
fn bad_files_and_images_are_clear_errors() {
    let missing = Path::new("/nonexistent/brisque_model_live.yml");
    let err = RbfSvr::load_opencv_yaml(missing).unwrap_err();
    assert!(
        matches!(err, BrisqueError::Io { .. })
            && err.to_string().contains("brisque_model_live.yml"),
        "{err}"
    );

    let dir = tempfile::tempdir().unwrap();
    let linear = dir.path().join("linear.yml");
    std::fs::write(
        &linear,
        "%YAML:1.0\n---\nopencv_ml_svm:\n   format: 3\n   svmType: EPS_SVR\n   kernel:\n      type: LINEAR\n",
    )
    .unwrap();
    let err = RbfSvr::load_opencv_yaml(&linear).unwrap_err();
    assert!(
        err.to_string().contains("kernel.type") && err.to_string().contains("LINEAR"),
        "{err}"
    );

    let model = load_opencv_model();
    let err = model.score_rgb8(&[0u8; 10], 4, 4).unwrap_err();
    assert!(matches!(err, BrisqueError::BadBuffer { .. }), "{err}");
    let flat = vec![128u8; 32 * 32 * 3];
    let err = model.score_rgb8(&flat, 32, 32).unwrap_err();
    assert!(matches!(err, BrisqueError::Degenerate(_)), "{err}");
    let err = model.score_rgb8(&[0u8; 5 * 5 * 3], 5, 5).unwrap_err();
    assert!(matches!(err, BrisqueError::TooSmall { .. }), "{err}");
}
