//! Parity of `gb_fill::fsr` with OpenCV's frequency-selective reconstruction
//! (`cv2.xphoto.inpaint`, `INPAINT_FSR_FAST`, whose settings are our defaults), on the four
//! pictures of `tools/fill_parity/make_fixtures.py` (stripes, bricks, smooth noise, a
//! gradient; 96x96, holes of 400 to 784 pixels). The two implementations differ (our blocks
//! are never split, our window is 48 pixels against OpenCV's 32), so the check is the fill's
//! quality, not its bits: on every picture our masked PSNR against the truth is within
//! [`MARGIN_DB`] of OpenCV's FSR_FAST or above it, and our fill is closer to OpenCV's than
//! the hole's own mean colour is.

use std::path::{Path, PathBuf};

use gb_core::RgbImage;
use gb_fill::fsr::{fill, FsrSettings};

/// How far below OpenCV's FSR_FAST our masked PSNR may fall, dB. Measured at the fixtures'
/// making: stripes 45.47 against 26.75, bricks 23.90 against 16.49, gradient 37.83 against
/// 37.86, smooth noise 22.82 against 23.88 (our wider window helps periodic texture and costs
/// a little on noise).
const MARGIN_DB: f64 = 1.5;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/fsr")
}

fn rgb(name: &str) -> RgbImage {
    gb_core::read_rgb(&fixtures().join(name), None).unwrap()
}

/// The hole (true: fill) of `<case>_mask.png`.
fn hole(case: &str) -> Vec<bool> {
    let (_, _, values) = gb_core::read_gray(&fixtures().join(format!("{case}_mask.png"))).unwrap();
    values.iter().map(|v| *v > 0.5).collect()
}

/// `img` as the 8-bit values a PNG holds, back in [0, 1] (OpenCV's fills are 8-bit).
fn quantised(img: &RgbImage) -> RgbImage {
    let mut out = img.clone();
    for v in &mut out.data {
        *v = (*v * 255.0).round().clamp(0.0, 255.0) / 255.0;
    }
    out
}

fn masked_psnr(a: &RgbImage, b: &RgbImage, hole: &[bool]) -> f64 {
    let (mut se, mut n) = (0.0f64, 0usize);
    for (i, _) in hole.iter().enumerate().filter(|(_, h)| **h) {
        for c in 0..3 {
            let d = f64::from(a.data[3 * i + c]) - f64::from(b.data[3 * i + c]);
            se += d * d;
            n += 1;
        }
    }
    gb_core::psnr_from_mse(se / n as f64)
}

/// `img` with every hole pixel set to the mean colour of the hole's truth (a fill that knows
/// the answer's mean and nothing else).
fn mean_fill(img: &RgbImage, hole: &[bool]) -> RgbImage {
    let mut sum = [0.0f64; 3];
    let count = hole.iter().filter(|h| **h).count() as f64;
    for (i, _) in hole.iter().enumerate().filter(|(_, h)| **h) {
        for (c, s) in sum.iter_mut().enumerate() {
            *s += f64::from(img.data[3 * i + c]);
        }
    }
    let mut out = img.clone();
    for (i, _) in hole.iter().enumerate().filter(|(_, h)| **h) {
        for (c, s) in sum.iter().enumerate() {
            out.data[3 * i + c] = (s / count) as f32;
        }
    }
    out
}

#[test]
fn fsr_is_as_good_as_opencvs_fsr_fast_on_every_picture() {
    let expected: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fixtures().join("expected.json")).unwrap())
            .unwrap();
    let cases = expected["cases"].as_object().unwrap();
    assert_eq!(cases.len(), 4);
    for (case, numbers) in cases {
        let truth = rgb(&format!("{case}_truth.png"));
        let hole = hole(case);
        assert_eq!(
            hole.iter().filter(|h| **h).count() as u64,
            numbers["hole_pixels"].as_u64().unwrap(),
            "{case}"
        );
        let opencv = rgb(&format!("{case}_opencv_fast.png"));
        let opencv_psnr = numbers["opencv_fast_psnr"].as_f64().unwrap();
        // the fixture's number is what this test measures of OpenCV's file
        assert!(
            (masked_psnr(&opencv, &truth, &hole) - opencv_psnr).abs() < 1e-3,
            "{case}"
        );
        let mut input = truth.clone();
        for (i, _) in hole.iter().enumerate().filter(|(_, h)| **h) {
            input.data[3 * i..3 * i + 3].copy_from_slice(&[0.0; 3]);
        }
        let ours = quantised(
            &fill(
                &input,
                &hole,
                (truth.width, truth.height),
                &FsrSettings::default(),
            )
            .unwrap(),
        );
        let ours_psnr = masked_psnr(&ours, &truth, &hole);
        println!("{case}: ours {ours_psnr:.2} dB, OpenCV FSR_FAST {opencv_psnr:.2} dB");
        assert!(
            ours_psnr >= opencv_psnr - MARGIN_DB,
            "{case}: {ours_psnr:.2} dB against OpenCV's {opencv_psnr:.2} dB"
        );
        let to_opencv = masked_psnr(&ours, &opencv, &hole);
        let mean_to_opencv = masked_psnr(&mean_fill(&truth, &hole), &opencv, &hole);
        assert!(
            to_opencv > mean_to_opencv,
            "{case}: ours is {to_opencv:.2} dB from OpenCV's fill, the mean colour {mean_to_opencv:.2} dB"
        );
    }
}
