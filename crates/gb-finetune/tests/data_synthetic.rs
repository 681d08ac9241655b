//! Procedural RGB / normal pairs, in memory and from a `write_pairs` folder.

use gb_finetune::normal_map::{decode_pixel, masked_angular_error_deg};
use gb_finetune::sample::PairSource;
use gb_finetune::synthetic::{SyntheticPairs, DEFAULT_VIEWS};
use gb_nerf::scene::procedural::{rgb_normal_pairs, write_pairs, ProceduralOptions, SceneName};

#[test]
fn generated_and_written_pairs_agree() {
    let mem = SyntheticPairs::generate(&["stairs"], &[3], 40, 30).unwrap();
    assert_eq!(mem.len(), DEFAULT_VIEWS);
    let s = mem.load(0).unwrap();
    assert_eq!((s.width, s.height), (40, 30));
    assert_eq!(s.rgb.len(), 40 * 30 * 3);
    assert!(s.name.starts_with("stairs_s3_view_"), "{}", s.name);
    assert!(!s.caption.is_empty());
    let nm = s.normal.as_ref().unwrap();
    // valid pixels decode to unit normals facing the camera (z > 0)
    let valid = s.normal_valid.iter().filter(|&&v| v == 1.0).count();
    assert!(valid > 40 * 30 / 2, "{valid}");
    for (i, &v) in s.normal_valid.iter().enumerate() {
        let px = [nm[3 * i], nm[3 * i + 1], nm[3 * i + 2]];
        match decode_pixel(px) {
            Some(n) => {
                assert_eq!(v, 1.0);
                assert!(n[2] > 0.0, "{n:?}");
            }
            None => {
                assert_eq!(v, 0.0);
                assert_eq!(px, [0.5; 3]);
            }
        }
    }

    // the same pairs written with write_pairs and read back (8-bit PNG)
    let opts = ProceduralOptions {
        name: SceneName::Stairs,
        seed: 3,
        width: 40,
        height: 30,
        views: DEFAULT_VIEWS,
        test_views: 2,
        dilate: 0,
    };
    let pairs = rgb_normal_pairs(&opts).unwrap();
    let dir = tempfile::tempdir().unwrap();
    write_pairs(dir.path(), &pairs).unwrap();
    let disk = SyntheticPairs::open(dir.path()).unwrap();
    assert_eq!(disk.len(), mem.len());
    for i in [0, DEFAULT_VIEWS - 1] {
        let (a, b) = (mem.load(i).unwrap(), disk.load(i).unwrap());
        assert_eq!(
            (a.name.as_str(), a.caption.as_str()),
            (b.name.as_str(), b.caption.as_str())
        );
        assert_eq!(a.normal_valid, b.normal_valid);
        let max_rgb = a
            .rgb
            .iter()
            .zip(&b.rgb)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max);
        assert!(max_rgb <= 0.5 / 255.0 + 1e-6, "{max_rgb}");
        let ones = vec![1.0; 40 * 30];
        let err = masked_angular_error_deg(
            a.normal.as_ref().unwrap(),
            b.normal.as_ref().unwrap(),
            &ones,
            40,
            30,
        )
        .unwrap();
        assert!(err < 0.5, "8-bit normal maps: {err} degrees");
    }
    // test views (without the object) and train views have different captions
    assert_ne!(
        mem.load(0).unwrap().caption,
        mem.load(DEFAULT_VIEWS - 1).unwrap().caption
    );
}

#[test]
fn bad_synthetic_inputs_are_clear_errors() {
    let e = SyntheticPairs::generate(&["castle"], &[0], 32, 32)
        .unwrap_err()
        .to_string();
    assert!(e.contains("castle"), "{e}");
    let e = SyntheticPairs::generate(&["fence"], &[], 32, 32)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no scene or no seed"), "{e}");
    let dir = tempfile::tempdir().unwrap();
    let e = SyntheticPairs::open(dir.path()).unwrap_err().to_string();
    assert!(e.contains("captions.jsonl"), "{e}");
    std::fs::write(
        dir.path().join("captions.jsonl"),
        "{\"name\": \"a\", \"rgb\": \"a_rgb.png\", \"normal\": \"a_normal.png\", \"caption\": \"x\"}\n",
    )
    .unwrap();
    let e = SyntheticPairs::open(dir.path()).unwrap_err().to_string();
    assert!(e.contains("a_rgb.png") && e.contains("line 1"), "{e}");
    std::fs::write(dir.path().join("captions.jsonl"), "{\"rgb\": 1}\n").unwrap();
    let e = SyntheticPairs::open(dir.path()).unwrap_err().to_string();
    assert!(e.contains("line 1") && e.contains("rgb"), "{e}");
}
