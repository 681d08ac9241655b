//! The run report of `cargo xtask inpaint` in a real browser: a tiny run (procedural stairs,
//! 40x30, 3 steps, `--method none`), then Debian's `chromium` in headless mode loads
//! `report.html`. Every `<img>` of the page sets `data-loaded="ok"` from its `onload`
//! attribute (or `"error"` from `onerror`); `--dump-dom` after a virtual-time budget shows
//! which loaded. A negative control (a page with a missing image) proves the check can fail,
//! and a screenshot proves the page renders. Every referenced file is also checked to exist
//! and to decode (PNG / GIF with the image crate through gb_core, SVG as a well-formed
//! document).
//!
//! Chromium is required: without it the test FAILS, saying how to install it
//! (`apt-get install chromium`; `.ci/run` installs it).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use gb_tests::{assert_success as check, path_str as s, small_preset, small_stairs, xtask};

/// The chromium binary, or a failure that says how to install it.
fn chromium() -> PathBuf {
    for name in ["chromium", "chromium-browser"] {
        let ok = Command::new(name)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success());
        if ok {
            return PathBuf::from(name);
        }
    }
    panic!(
        "chromium is not installed: this test loads report.html in a real headless browser. \
         Install it with `apt-get update && apt-get install -y chromium` (Debian; .ci/run \
         installs it)"
    );
}

/// `chromium --headless ... ARGS file://PAGE` with a private profile under `profile`.
fn browse(profile: &Path, page: &Path, args: &[&str]) -> Output {
    let url = format!("file://{}", page.canonicalize().unwrap().display());
    let out = Command::new(chromium())
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--no-first-run",
            "--hide-scrollbars",
            &format!("--user-data-dir={}", profile.display()),
            "--run-all-compositor-stages-before-draw",
            "--virtual-time-budget=5000",
        ])
        .args(args)
        .arg(url)
        .output()
        .expect("cannot start chromium");
    assert!(
        out.status.success(),
        "chromium failed ({:?}): {}",
        out.status.code(),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The `<img ...>` tags of an HTML text.
fn img_tags(html: &str) -> Vec<String> {
    html.match_indices("<img ")
        .map(|(i, _)| {
            let end = html[i..].find('>').expect("unterminated <img");
            html[i..i + end + 1].to_string()
        })
        .collect()
}

fn attr(tag: &str, name: &str) -> Option<String> {
    let key = format!(" {name}=\"");
    let i = tag.find(&key)? + key.len();
    let j = tag[i..].find('"')?;
    Some(tag[i..i + j].to_string())
}

/// Every image of the page loads in chromium; returns the `src` of each.
fn assert_all_images_load(profile: &Path, page: &Path) -> Vec<String> {
    let source = std::fs::read_to_string(page).unwrap();
    let want = img_tags(&source);
    let dom = String::from_utf8(browse(profile, page, &["--dump-dom"]).stdout).unwrap();
    assert!(
        dom.contains("<h2>Metrics</h2>"),
        "the page did not load: {dom}"
    );
    let got = img_tags(&dom);
    assert_eq!(got.len(), want.len(), "images in the DOM: {got:?}");
    for tag in &got {
        assert_eq!(
            attr(tag, "data-loaded").as_deref(),
            Some("ok"),
            "image did not load in chromium: {tag}"
        );
    }
    got.iter().map(|t| attr(t, "src").unwrap()).collect()
}

/// The file behind `src` exists and decodes.
fn assert_decodes(dir: &Path, src: &str) {
    let path = dir.join(src);
    assert!(path.is_file(), "{} does not exist", path.display());
    if src.ends_with(".svg") {
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(
            text.starts_with("<svg xmlns=\"http://www.w3.org/2000/svg\"")
                && text.trim_end().ends_with("</svg>")
                && text.contains("<polyline"),
            "{} is not a drawn SVG chart",
            path.display()
        );
    } else {
        let img = gb_core::read_rgb(&path, None)
            .unwrap_or_else(|e| panic!("{} does not decode: {e}", path.display()));
        assert!(img.width > 0 && img.height > 0);
    }
}

/// A tiny stairs scene (40x30, mask grown by 1 pixel) and a small preset in `dir`.
fn setup(dir: &Path) -> (PathBuf, PathBuf) {
    (small_stairs(dir, 40, 30, 1), small_preset(dir, None))
}

fn inpaint(scene: &Path, preset: &Path, out: &Path, extra: &[&str]) {
    let mut args = vec![
        "inpaint",
        "--scene",
        s(scene),
        "--preset",
        s(preset),
        "--out",
        s(out),
        "--device",
        "flex",
        "--method",
        "none",
        "--orbit-frames",
        "6",
    ];
    args.extend_from_slice(extra);
    check(&xtask(&args), "inpaint");
}

#[test]
fn the_report_loads_in_headless_chromium_with_every_image() {
    // fail early, before training, when the browser is missing
    chromium();
    let dir = tempfile::tempdir().unwrap();
    let (scene, preset) = setup(dir.path());
    let profile = dir.path().join("chromium-profile");

    // a run without a baseline: the masked input stands in, and the page says so
    let a = dir.path().join("a");
    inpaint(&scene, &preset, &a, &["--steps", "3"]);
    let page = a.join("report.html");
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(html.contains("No baseline was given"), "{html}");
    assert!(!html.contains("<script") && !html.contains("https://"));
    let srcs = assert_all_images_load(&profile, &page);
    for want in [
        "report/view_000_gt.png",
        "renders/view_000_rgb.png",
        "report/view_000_masked_input.png",
        "report/view_000_diff.png",
        "orbit.gif",
        "report/loss.svg",
        "report/psnr.svg",
    ] {
        assert!(
            srcs.iter().any(|s| s == want),
            "{want} not on the page: {srcs:?}"
        );
    }
    for src in &srcs {
        assert_decodes(&a, src);
    }
    // the orbit: 6 frames at half the training size (40x30 -> 20x15)
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(a.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(m["orbit"]["frames"], 6);
    assert_eq!(
        (m["orbit"]["width"].as_u64(), m["orbit"]["height"].as_u64()),
        (Some(20), Some(15))
    );
    let gif = image_frames(&a.join("orbit.gif"));
    assert_eq!(gif, 6, "GIF frames");
    // metrics.json: the eval block with every gb-eval key, reasons for the unavailable ones
    let e = &m["eval"];
    assert!(e["psnr"].as_f64().unwrap() > 5.0, "{e}");
    assert!(
        e["psnr_mask"].as_f64().is_some() && e["d_psnr"].as_f64().is_some(),
        "{e}"
    );
    assert!(
        e["unavailable"]["fid"]
            .as_str()
            .unwrap()
            .contains("test view"),
        "{e}"
    );
    assert_eq!(m["mean"]["psnr"], e["psnr"], "the old keys stay");
    // the metric table shows the same PSNR
    assert!(
        html.contains(&format!("<td>{:.4}</td>", e["psnr"].as_f64().unwrap())),
        "metric table"
    );

    // a run with a baseline: the other run's renders
    let b = dir.path().join("b");
    inpaint(&scene, &preset, &b, &["--steps", "2", "--baseline", s(&a)]);
    let page_b = b.join("report.html");
    let srcs = assert_all_images_load(&profile, &page_b);
    assert!(
        srcs.iter().any(|s| s == "report/view_000_baseline.png"),
        "{srcs:?}"
    );
    let base = gb_core::read_rgb(&b.join("report/view_000_baseline.png"), None).unwrap();
    let a_render = gb_core::read_rgb(&a.join("renders/view_000_rgb.png"), None).unwrap();
    assert_eq!(base, a_render, "the baseline column is run a's render");

    // the browser really renders the page: a screenshot of the given size with content
    let shot = dir.path().join("shot.png");
    browse(
        &profile,
        &page,
        &[
            "--window-size=1200,1600",
            &format!("--screenshot={}", shot.display()),
        ],
    );
    let img = gb_core::read_rgb(&shot, None).expect("chromium wrote no screenshot");
    assert_eq!((img.width, img.height), (1200, 1600));
    let mean = img.data.iter().sum::<f32>() / img.data.len() as f32;
    let var = img.data.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / img.data.len() as f32;
    assert!(var > 1e-3, "blank screenshot (variance {var})");

    // negative control: a missing image is reported as not loaded
    let broken = a.join("broken.html");
    std::fs::write(
        &broken,
        html.replacen("report/view_000_gt.png", "report/does_not_exist.png", 1),
    )
    .unwrap();
    let dom = String::from_utf8(browse(&profile, &broken, &["--dump-dom"]).stdout).unwrap();
    let bad: Vec<String> = img_tags(&dom)
        .into_iter()
        .filter(|t| attr(t, "data-loaded").as_deref() != Some("ok"))
        .collect();
    assert_eq!(bad.len(), 1, "{bad:?}");
    assert_eq!(attr(&bad[0], "data-loaded").as_deref(), Some("error"));
}

/// Number of frames of a GIF (counts image descriptors after the header; the encoder writes
/// no extension that contains the 0x2C byte at block starts, so walk the blocks properly).
fn image_frames(path: &Path) -> usize {
    let b = std::fs::read(path).unwrap();
    assert_eq!(&b[..6], b"GIF89a");
    let packed = b[10];
    let mut i = 13;
    if packed & 0x80 != 0 {
        i += 3 * (1 << ((packed & 7) + 1));
    }
    let skip_blocks = |mut i: usize| {
        while b[i] != 0 {
            i += b[i] as usize + 1;
        }
        i + 1
    };
    let mut frames = 0;
    loop {
        match b[i] {
            0x3B => return frames,
            0x21 => i = skip_blocks(i + 2),
            0x2C => {
                frames += 1;
                let p = b[i + 9];
                i += 10;
                if p & 0x80 != 0 {
                    i += 3 * (1 << ((p & 7) + 1));
                }
                i = skip_blocks(i + 1);
            }
            x => panic!("bad GIF block 0x{x:02x} at {i}"),
        }
    }
}
