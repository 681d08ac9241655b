//! PSNR, SSIM and D-PSNR against scikit-image 0.26.0 on the fixtures of
//! `tools/eval_parity/make_fixtures.py` (photo crops and procedural patterns with noise, blur,
//! a 1-px shift and JPEG artefacts; constant and identical images).

use crate::common;

use common::{expected, fixture_dir, image, mask, number, Deviation};
use gb_eval::disparity::{d_psnr, read_disparity, DepthKind};
use gb_eval::image_metrics::{psnr, ssim, ssim_luminance, Region};

const TOL: f64 = 1e-5;

#[test]
fn psnr_and_ssim_match_scikit_image_on_every_region() {
    let doc = expected();
    let cases = doc["cases"].as_array().expect("cases");
    assert!(cases.len() >= 8);
    let mut dev_psnr = Deviation::new("PSNR", TOL);
    let mut dev_ssim = Deviation::new("SSIM", TOL);
    for c in cases {
        let name = c["name"].as_str().unwrap();
        let gt = image(c["gt"].as_str().unwrap());
        let pred = image(c["pred"].as_str().unwrap());
        let m = mask(c["mask"].as_str().unwrap());
        let b: Vec<usize> = c["bbox"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as usize)
            .collect();
        let bbox = Region::BBox {
            x0: b[0],
            y0: b[1],
            x1: b[2],
            y1: b[3],
        };
        assert_eq!(
            Region::bbox_of_mask(&m, gt.width),
            Some(bbox.clone()),
            "{name}: bbox"
        );
        let full = Region::Full;
        let masked = Region::Mask(m);
        dev_psnr.check(name, psnr(&pred, &gt, &full).unwrap(), number(&c["psnr"]));
        dev_psnr.check(
            name,
            psnr(&pred, &gt, &bbox).unwrap(),
            number(&c["psnr_bbox"]),
        );
        dev_psnr.check(
            name,
            psnr(&pred, &gt, &masked).unwrap(),
            number(&c["psnr_mask"]),
        );
        dev_ssim.check(name, ssim(&pred, &gt, &full).unwrap(), number(&c["ssim"]));
        dev_ssim.check(
            name,
            ssim(&pred, &gt, &bbox).unwrap(),
            number(&c["ssim_bbox"]),
        );
        dev_ssim.check(
            name,
            ssim(&pred, &gt, &masked).unwrap(),
            number(&c["ssim_mask"]),
        );
        dev_ssim.check(
            name,
            ssim_luminance(&pred, &gt, &full).unwrap(),
            number(&c["ssim_luminance"]),
        );
        dev_ssim.check(
            name,
            ssim_luminance(&pred, &gt, &masked).unwrap(),
            number(&c["ssim_luminance_mask"]),
        );
    }
    dev_psnr.report();
    dev_ssim.report();
}

#[test]
fn identical_images_give_infinite_psnr_and_unit_ssim() {
    let doc = expected();
    let c = doc["cases"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["name"] == "identical")
        .expect("identical case");
    assert_eq!(c["psnr"], "inf");
    let img = image(c["gt"].as_str().unwrap());
    assert_eq!(psnr(&img, &img, &Region::Full).unwrap(), f64::INFINITY);
    assert!((ssim(&img, &img, &Region::Full).unwrap() - 1.0).abs() < 1e-12);
}

#[test]
fn constant_images_follow_the_closed_form() {
    // Two constants a, b: variances vanish, so SSIM = (2ab + C1) / (a^2 + b^2 + C1).
    let doc = expected();
    let c = doc["cases"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["name"] == "constant_pair")
        .expect("constant case");
    let gt = image(c["gt"].as_str().unwrap());
    let pred = image(c["pred"].as_str().unwrap());
    let (a, b) = (f64::from(gt.data[0]), f64::from(pred.data[0]));
    let c1 = 1e-4;
    let closed = (2.0 * a * b + c1) / (a * a + b * b + c1);
    let got = ssim(&pred, &gt, &Region::Full).unwrap();
    assert!((got - closed).abs() < 1e-9, "{got} vs {closed}");
    let psnr_closed = -10.0 * ((a - b) * (a - b)).log10();
    assert!((psnr(&pred, &gt, &Region::Full).unwrap() - psnr_closed).abs() < 1e-9);
}

#[test]
fn an_empty_mask_is_a_clear_error() {
    let img = image("statue_noise_gt.png");
    let empty = Region::Mask(vec![false; img.width * img.height]);
    let err = psnr(&img, &img, &empty).unwrap_err().to_string();
    assert!(err.contains("mask selects no pixel"), "{err}");
    assert!(ssim(&img, &img, &empty).is_err());
}

#[test]
fn d_psnr_matches_the_reference_convention() {
    let doc = expected();
    let mut dev = Deviation::new("D-PSNR", TOL);
    for c in doc["depth_cases"].as_array().unwrap() {
        let dir = fixture_dir().join("depth");
        let p =
            read_disparity(&dir.join(c["pred"].as_str().unwrap()), DepthKind::Disparity).unwrap();
        let g = read_disparity(&dir.join(c["gt"].as_str().unwrap()), DepthKind::Disparity).unwrap();
        dev.check(
            c["name"].as_str().unwrap(),
            d_psnr(&p, &g, &Region::Full).unwrap(),
            number(&c["d_psnr"]),
        );
    }
    dev.report();
}
