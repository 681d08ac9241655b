//! `cargo xtask distill-image` end to end on the committed tiny SD-inpainting fixture
//! (crates/gb-diffusion/tests/fixtures/sd_image/pipeline, prior resolution 32): for SDS, CSD
//! and BSD a few Adam steps on a small image, then the files it writes, the pixels it may
//! and may not touch, and its log; and the one-line error of a bad mask.

use std::path::{Path, PathBuf};

use gb_core::{read_rgb, write_gray_png, write_rgb_png, RgbImage};
use gb_tests::xtask;

const PRIOR: &str = "crates/gb-diffusion/tests/fixtures/sd_image/pipeline";
const W: usize = 24;
const H: usize = 20;
const STEPS: usize = 3;
const SAVE_EVERY: usize = 2;

/// The hole: a 9x7 rectangle, off-centre.
fn in_mask(x: usize, y: usize) -> bool {
    (9..18).contains(&x) && (5..12).contains(&y)
}

/// A mid-range pattern whose values are exact multiples of 1/255, so that the PNG round
/// trip (read /255, write *255) is exact and clamping to [0, 1] never bites.
fn input_image() -> RgbImage {
    let mut img = RgbImage::filled(W, H, [0.0; 3]);
    for y in 0..H {
        for x in 0..W {
            let v = |k: usize| (60 + (k % 130)) as f32 / 255.0;
            img.set(
                x,
                y,
                [v(7 * x + 3 * y), v(5 * x + 11 * y + 40), v(x * y + 90)],
            );
        }
    }
    img
}

/// Writes the image and mask into `dir`; returns their paths.
fn write_inputs(dir: &Path) -> (PathBuf, PathBuf) {
    let image = dir.join("image.png");
    let mask = dir.join("mask.png");
    write_rgb_png(&image, &input_image()).unwrap();
    let values: Vec<f32> = (0..H)
        .flat_map(|y| (0..W).map(move |x| if in_mask(x, y) { 1.0 } else { 0.0 }))
        .collect();
    write_gray_png(&mask, W, H, &values).unwrap();
    (image, mask)
}

fn to_u8(img: &RgbImage) -> Vec<u8> {
    img.data
        .iter()
        .map(|&v| (v * 255.0).round() as u8)
        .collect()
}

fn run_method(method: &str, expected_batch: u64) {
    run_method_with(PRIOR, method, expected_batch);
}

fn run_method_with(prior: &str, method: &str, expected_batch: u64) {
    let dir = tempfile::tempdir().unwrap();
    let (image, mask) = write_inputs(dir.path());
    let out = dir.path().join("out");
    let steps = STEPS.to_string();
    let save_every = SAVE_EVERY.to_string();
    let args = [
        "distill-image",
        "--prior",
        prior,
        "--image",
        image.to_str().unwrap(),
        "--mask",
        mask.to_str().unwrap(),
        "--prompt",
        "a plain brick wall",
        "--negative-prompt",
        "blurry",
        "--method",
        method,
        "--steps",
        &steps,
        "--save-every",
        &save_every,
        "--lr",
        "0.05",
        "--seed",
        "3",
        "--device",
        "flex",
        "--out",
        out.to_str().unwrap(),
    ];
    let result = xtask(&args);
    assert!(
        result.status.success(),
        "{method}: exit {:?}\n{}",
        result.status.code(),
        String::from_utf8_lossy(&result.stderr)
    );

    // Snapshots at every SAVE_EVERY-th step and at the last one, all at the input size.
    let snaps: Vec<usize> = (1..=STEPS)
        .filter(|s| s % SAVE_EVERY == 0 || *s == STEPS)
        .collect();
    let input = to_u8(&input_image());
    let mut last = None;
    for s in &snaps {
        let path = out.join(format!("step_{s:05}.png"));
        let img = read_rgb(&path, None).unwrap_or_else(|e| panic!("{method}: {e}"));
        assert_eq!((img.width, img.height), (W, H), "{}", path.display());
        last = Some(img);
    }
    let grid = read_rgb(&out.join("grid.png"), None).unwrap();
    assert_eq!((grid.width, grid.height), (W * (1 + snaps.len()), H));

    // Outside the mask: bit for bit the input. Inside: changed.
    let result = to_u8(&last.unwrap());
    let (mut changed_inside, mut inside) = (0, 0);
    for y in 0..H {
        for x in 0..W {
            let i = (y * W + x) * 3;
            let (a, b) = (&input[i..i + 3], &result[i..i + 3]);
            if in_mask(x, y) {
                inside += 1;
                changed_inside += usize::from(a != b);
            } else {
                assert_eq!(a, b, "{method}: pixel ({x}, {y}) outside the mask changed");
            }
        }
    }
    assert!(
        changed_inside * 2 > inside,
        "{method}: only {changed_inside} of {inside} pixels inside the mask changed"
    );
    // The grid's first tile is the input.
    let grid = to_u8(&grid);
    for y in 0..H {
        let row = (y * W * (1 + snaps.len())) * 3;
        assert_eq!(&grid[row..row + W * 3], &input[y * W * 3..(y + 1) * W * 3]);
    }

    // One JSON line per step: finite positive loss scale and gradient norm, t in the
    // default [0.02, 0.98] range, one batched U-Net call of the method's size.
    let log = std::fs::read_to_string(out.join("log.jsonl")).unwrap();
    let lines: Vec<serde_json::Value> = log
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), STEPS, "{log}");
    for (i, l) in lines.iter().enumerate() {
        assert_eq!(l["step"].as_u64(), Some(i as u64 + 1), "{l}");
        let loss = l["loss"].as_f64().unwrap_or(f64::NAN);
        let grad = l["grad_norm"].as_f64().unwrap_or(f64::NAN);
        assert!(loss.is_finite() && loss > 0.0, "{method}: loss {l}");
        assert!(grad.is_finite() && grad > 0.0, "{method}: grad_norm {l}");
        let t = l["t"].as_f64().unwrap();
        assert!((20.0..=980.0).contains(&t), "{method}: t {l}");
        assert_eq!(l["unet_calls"].as_u64(), Some(1), "{l}");
        assert_eq!(l["unet_batch"].as_u64(), Some(expected_batch), "{l}");
    }
}

#[test]
fn sds_changes_only_the_masked_pixels() {
    run_method("sds", 2);
}

#[test]
fn csd_changes_only_the_masked_pixels() {
    run_method("csd", 3);
}

#[test]
fn bsd_changes_only_the_masked_pixels() {
    run_method("bsd", 2);
}

#[test]
fn bsd_runs_with_the_builtin_tiny_prior() {
    run_method_with("tiny", "bsd", 2);
}

#[test]
fn a_bad_mask_is_a_one_line_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let (image, _) = write_inputs(dir.path());
    let garbage = dir.path().join("garbage.png");
    std::fs::write(&garbage, b"not a png").unwrap();
    for mask in [dir.path().join("no_such_mask.png"), garbage] {
        let out = dir.path().join("out");
        let result = xtask(&[
            "distill-image",
            "--prior",
            PRIOR,
            "--image",
            image.to_str().unwrap(),
            "--mask",
            mask.to_str().unwrap(),
            "--prompt",
            "x",
            "--out",
            out.to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&result.stderr);
        assert_eq!(result.status.code(), Some(2), "{err}");
        let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
        assert_eq!(lines.len(), 1, "{err}");
        assert!(lines[0].contains(mask.to_str().unwrap()), "{err}");
    }
}
