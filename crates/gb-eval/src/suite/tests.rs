use std::path::Path;

use gb_core::{BackendKind, RgbImage};

use super::*;
use crate::disparity::{DepthKind, ScalarMap};
use crate::eval_inputs::EvalInputs;
use crate::report::Outcome;

// fails when the shared data appeared after this crate was built without it
gb_core::shared_data_guard!();

fn img(w: usize, h: usize, f: impl Fn(usize, usize) -> f32) -> RgbImage {
    let mut im = RgbImage::filled(w, h, [0.0; 3]);
    for y in 0..h {
        for x in 0..w {
            let v = f(x, y);
            im.set(x, y, [v, v * 0.5, 1.0 - v]);
        }
    }
    im
}

fn value(r: &EvalReport, k: &str) -> f64 {
    match r.values.get(k) {
        Some(Outcome::Value(v)) => *v,
        other => panic!("{k}: {other:?}"),
    }
}

fn reason<'a>(r: &'a EvalReport, k: &str) -> &'a str {
    match r.values.get(k) {
        Some(Outcome::Unavailable(why)) => why,
        other => panic!("{k}: {other:?}"),
    }
}

fn no_weights() -> SuiteOptions {
    SuiteOptions {
        weights: None,
        ..SuiteOptions::new(None, BackendKind::Ndarray)
    }
}

/// A view whose render is wrong only inside a triangle mask, so that its bounding box also
/// holds correct pixels.
fn triangle_view(name: &str, shift: usize) -> EvalPair {
    let (w, h) = (32, 24);
    let gt = img(w, h, |x, y| ((x * 7 + y * 3 + shift) % 17) as f32 / 17.0);
    let mut pred = gt.clone();
    let mut mask = vec![false; w * h];
    for y in 4..20 {
        for x in 8..24 {
            if x - 8 <= y - 4 {
                mask[y * w + x] = true;
                pred.set(x, y, [0.5; 3]);
            }
        }
    }
    EvalPair {
        name: name.into(),
        pred,
        gt: Some(gt),
        mask: Some(mask),
        disparity: None,
    }
}

#[test]
fn psnr_ssim_regions_and_unavailable_reasons() {
    let views = [triangle_view("v", 0)];
    let set = PairSet {
        noun: "test view",
        no_depth: "the scene has no ground-truth depth",
        ..PairSet::new(&views)
    };
    let r = evaluate(&set, &no_weights()).unwrap();
    // the error is only inside the mask: full > bbox > mask PSNR
    assert!(value(&r, "psnr") > value(&r, "psnr_bbox"));
    assert!(value(&r, "psnr_bbox") > value(&r, "psnr_mask"));
    assert!(value(&r, "ssim") > value(&r, "ssim_bbox"));
    assert_eq!(r.per_image[0].1["psnr"], value(&r, "psnr"));
    assert!(reason(&r, "fid").contains("1 test view(s): FID needs at least 8"));
    assert_eq!(reason(&r, "d_psnr"), "the scene has no ground-truth depth");
    for k in ["lpips", "lpips_bbox", "nima", "brisque", "brisque_bbox"] {
        assert!(reason(&r, k).contains("no weights folder"), "{k}");
    }
    // without a mask there are no region keys
    let mut plain = triangle_view("v", 0);
    plain.mask = None;
    let r = evaluate(&PairSet::new(&[plain]), &no_weights()).unwrap();
    assert!(r.values.contains_key("psnr") && !r.values.contains_key("psnr_bbox"));
}

#[test]
fn a_pair_that_fails_makes_the_key_unavailable_and_keeps_the_others_values() {
    let good = triangle_view("good", 0);
    let mut tiny_box = triangle_view("tiny", 3);
    // a one-pixel mask: its box is under SSIM's 7-pixel window
    let mask = tiny_box.mask.as_mut().unwrap();
    mask.iter_mut().for_each(|m| *m = false);
    mask[5 * 32 + 5] = true;
    let pairs = [good, tiny_box];
    let r = evaluate(&PairSet::new(&pairs), &no_weights()).unwrap();
    assert!(reason(&r, "ssim_bbox").starts_with("tiny: "), "{r:?}");
    assert!(r.per_image[0].1.contains_key("ssim_bbox"));
    assert!(!r.per_image[1].1.contains_key("ssim_bbox"));
    // PSNR over one pixel is defined: that pixel is right, so it is infinite, and so the mean
    assert_eq!(r.per_image[1].1["psnr_bbox"], f64::INFINITY);
    assert_eq!(value(&r, "psnr_bbox"), f64::INFINITY);
}

fn write_pair_folders(root: &Path, pairs: &[EvalPair]) {
    for dir in ["pred", "gt", "masks", "pd", "gd"] {
        std::fs::create_dir_all(root.join(dir)).unwrap();
    }
    for p in pairs {
        let file = format!("{}.png", p.name);
        gb_core::write_rgb_png(&root.join("pred").join(&file), &p.pred).unwrap();
        gb_core::write_rgb_png(&root.join("gt").join(&file), p.gt.as_ref().unwrap()).unwrap();
        let mask: Vec<f32> = p
            .mask
            .as_ref()
            .unwrap()
            .iter()
            .map(|&m| m as u8 as f32)
            .collect();
        let (w, h) = (p.pred.width, p.pred.height);
        gb_core::write_gray_png(&root.join("masks").join(&file), w, h, &mask).unwrap();
        let (pd, gd) = p.disparity.as_ref().unwrap();
        gb_core::write_gray_png(&root.join("pd").join(&file), w, h, &pd.data).unwrap();
        gb_core::write_gray_png(&root.join("gd").join(&file), w, h, &gd.data).unwrap();
    }
}

#[test]
fn folders_and_pairs_in_memory_get_the_same_report() {
    let tmp = tempfile::tempdir().unwrap();
    let mut pairs: Vec<EvalPair> = (0..3)
        .map(|i| triangle_view(&format!("p{i}"), i * 5))
        .collect();
    for (i, p) in pairs.iter_mut().enumerate() {
        let disp = |k: usize| ScalarMap {
            width: 32,
            height: 24,
            data: (0..32 * 24)
                .map(|j| ((j * (k + 1)) % 29) as f32 / 28.0)
                .collect(),
        };
        p.disparity = Some((disp(i), disp(i + 1)));
    }
    write_pair_folders(tmp.path(), &pairs);
    let d = |s: &str| tmp.path().join(s);
    let (pd, gd) = (d("pd"), d("gd"));
    let folders = EvalInputs::from_dirs(
        &d("pred"),
        &d("gt"),
        Some(&d("masks")),
        Some((&pd, &gd)),
        DepthKind::Disparity,
    )
    .unwrap();
    // the same pairs as the files hold them (8-bit)
    let loaded: Vec<EvalPair> = (0..3)
        .map(|i| {
            let (pred, gt) = folders.load_pair(i).unwrap();
            EvalPair {
                name: folders.names[i].clone(),
                pred,
                gt: Some(gt),
                mask: folders.load_mask(i).unwrap(),
                disparity: folders.load_disparity_pair(i).unwrap(),
            }
        })
        .collect();
    let opts = no_weights();
    let from_files = evaluate(&folders, &opts).unwrap();
    let from_memory = evaluate(&PairSet::new(&loaded), &opts).unwrap();
    let keys = [
        "psnr",
        "psnr_bbox",
        "psnr_mask",
        "ssim_mask",
        "d_psnr",
        "d_psnr_bbox",
    ];
    for k in keys {
        assert_eq!(value(&from_files, k), value(&from_memory, k), "{k}");
    }
    assert_eq!(from_files.per_image, from_memory.per_image);
    assert_eq!(from_files.per_image[2].0, "p2.png");
    assert!(value(&from_files, "d_psnr") > 0.0 && value(&from_files, "d_psnr").is_finite());

    // without depth folders: `Available` skips the depth metrics, `All` says why
    let no_depth =
        EvalInputs::from_dirs(&d("pred"), &d("gt"), None, None, DepthKind::Disparity).unwrap();
    let available = SuiteOptions {
        metrics: Selection::Available,
        ..no_weights()
    };
    let r = evaluate(&no_depth, &available).unwrap();
    assert!(!r.values.contains_key("d_psnr") && !r.values.contains_key("d_fid"));
    assert!(!r.values.contains_key("psnr_bbox"), "no masks, no regions");
    let r = evaluate(&no_depth, &no_weights()).unwrap();
    assert!(reason(&r, "d_psnr").contains("--pred-depth"));
    // a chosen list runs those only, in its order
    let only = SuiteOptions {
        metrics: Selection::parse(&["SSIM".into(), "psnr".into(), "ssim".into()]).unwrap(),
        ..no_weights()
    };
    let r = evaluate(&no_depth, &only).unwrap();
    assert_eq!(r.values.keys().collect::<Vec<_>>(), ["psnr", "ssim"]);
    let err = Selection::parse(&["psnr".into(), "sharpness".into()]).unwrap_err();
    assert!(err
        .to_string()
        .starts_with("unknown metric 'sharpness': expected some of psnr"));
}

/// Box blur of radius `r` inside `[x0, x1) x [y0, y1)`, repeated `times`.
fn blur_box(
    img: &RgbImage,
    (x0, y0, x1, y1): (usize, usize, usize, usize),
    r: usize,
    times: usize,
) -> RgbImage {
    let mut out = img.clone();
    for _ in 0..times {
        let src = out.clone();
        for y in y0..y1 {
            for x in x0..x1 {
                let mut acc = [0.0f32; 3];
                let mut n = 0.0;
                for yy in y.saturating_sub(r)..(y + r + 1).min(img.height) {
                    for xx in x.saturating_sub(r)..(x + r + 1).min(img.width) {
                        let p = src.get(xx, yy);
                        (0..3).for_each(|c| acc[c] += p[c]);
                        n += 1.0;
                    }
                }
                out.set(x, y, acc.map(|v| v / n));
            }
        }
    }
    out
}

#[test]
#[cfg_attr(
    gb_no_shared_data,
    ignore = "needs the shared test data (../shared or GB_TEST_DATA): weights/ and data/rgb_normal_sample"
)]
fn renders_without_reference_get_brisque_whole_and_in_the_mask_box() {
    let data = gb_core::test_data_dir();
    let weights = data.join("weights");
    let photo = data.join("data/rgb_normal_sample/000000_img.png");
    let photo = gb_core::read_rgb(&photo, None).unwrap();
    let (w, h) = (photo.width, photo.height);
    let (x0, y0, x1, y1) = (w / 3, h / 3, w / 3 + 160, h / 3 + 120);
    let mut mask = vec![false; w * h];
    for y in y0..y1 {
        for x in x0..x1 {
            mask[y * w + x] = true;
        }
    }
    // the "filled" box of a render: the photo, blurred inside the mask box as a weak fill is
    let pred = blur_box(&photo, (x0, y0, x1, y1), 3, 3);
    let mut tiny = vec![false; w * h];
    tiny[10 * w + 10] = true;
    let opts = SuiteOptions::new(Some(weights.clone()), BackendKind::Flex);
    let view = |name: &str, mask: Vec<bool>| EvalPair {
        name: name.into(),
        pred: pred.clone(),
        gt: None,
        mask: Some(mask),
        disparity: None,
    };
    let no_reference = "the scene has no test view with ground truth";
    fn set(pairs: &[EvalPair]) -> PairSet<'_> {
        PairSet {
            no_reference: "the scene has no test view with ground truth",
            ..PairSet::new(pairs)
        }
    }
    let r = evaluate(&set(&[view("a", mask.clone())]), &opts).unwrap();
    use crate::brisque::{Brisque, OPENCV_MODEL_FILE, OPENCV_RANGE_FILE};
    let model = Brisque::load_opencv(
        &weights.join(OPENCV_MODEL_FILE),
        &weights.join(OPENCV_RANGE_FILE),
    )
    .unwrap();
    let crop = bbox_crop(&pred, Some(&mask)).unwrap();
    assert_eq!((crop.width, crop.height), (160, 120));
    assert_eq!(crop.get(0, 0), pred.get(x0, y0));
    assert_eq!(crop.get(159, 119), pred.get(x1 - 1, y1 - 1));
    assert_eq!(value(&r, "brisque"), model.score(&pred).unwrap());
    assert_eq!(value(&r, "brisque_bbox"), model.score(&crop).unwrap());
    // the blurred fill scores worse (higher) in the box than the photo's own crop
    let sharp = model
        .score(&bbox_crop(&photo, Some(&mask)).unwrap())
        .unwrap();
    assert!(value(&r, "brisque_bbox") > sharp + 10.0);
    for k in ["psnr", "ssim", "lpips", "d_psnr", "fid", "psnr_mask"] {
        assert_eq!(reason(&r, k), no_reference, "{k}");
    }
    // a 1-pixel mask box is too small to score, and says so with the view's name
    let r = evaluate(&set(&[view("a", mask), view("b", tiny)]), &opts).unwrap();
    assert!(value(&r, "brisque").is_finite());
    assert!(reason(&r, "brisque_bbox").starts_with("b: the mask box is 1x1"));
    let none = evaluate(&set(&[]), &opts).unwrap();
    assert!(reason(&none, "brisque").contains("no pair has the inputs"));
}
