//! Caption files and the paper's three prompt modes.

use gb_finetune::captions::{prompts_for, CaptionFile, CaptionMode, Modality};
use std::path::Path;

#[test]
fn the_three_modes_and_the_shared_caption() {
    let c = "a wooden staircase";
    assert_eq!(
        prompts_for(CaptionMode::Captions, c),
        vec![
            (Modality::Rgb, "RGB image, a wooden staircase".to_string()),
            (
                Modality::Normal,
                "normal map, a wooden staircase".to_string()
            ),
        ]
    );
    assert_eq!(
        prompts_for(CaptionMode::Identifiers, c),
        vec![
            (Modality::Rgb, "RGB image".to_string()),
            (Modality::Normal, "normal map".to_string()),
        ]
    );
    assert_eq!(
        prompts_for(CaptionMode::NormalOnly, c),
        vec![(Modality::Normal, "normal map".to_string())]
    );
    // an empty caption falls back to the bare identifiers
    assert_eq!(
        prompts_for(CaptionMode::Captions, "  "),
        prompts_for(CaptionMode::Identifiers, "")
    );
    assert_eq!(CaptionMode::default(), CaptionMode::Captions);
    for m in CaptionMode::ALL {
        assert_eq!(m.as_str().parse::<CaptionMode>().unwrap(), m);
    }
    let e = "both".parse::<CaptionMode>().unwrap_err().to_string();
    assert!(e.contains("mode") && e.contains("normal-only"), "{e}");
}

#[test]
fn caption_file_keys_shared_caption_and_bad_lines() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("blip.jsonl");
    std::fs::write(
        &p,
        concat!(
            "{\"image\": \"val/indoors/scene_1/scan_2/x.png\", \"caption\": \"a desk\"}\n",
            "\n",
            "{\"rgb\": \"y_rgb.png\", \"normal\": \"y_normal.png\", \"caption\": \"a fence\"}\n",
            "{\"file\": \"z.jpg\", \"text\": \"a door\"}\n",
            "{\"name\": \"w\", \"caption\": \"\"}\n",
        ),
    )
    .unwrap();
    let f = CaptionFile::load(&p).unwrap();
    assert_eq!(f.len(), 4);
    assert_eq!(f.get("val/indoors/scene_1/scan_2/x.png"), Some("a desk"));
    assert_eq!(f.get("indoors/scene_1/scan_2/x.png"), Some("a desk"));
    assert_eq!(f.get("x"), Some("a desk"));
    assert_eq!(f.get("y_rgb.png"), Some("a fence"));
    assert_eq!(f.get("z"), Some("a door"));
    assert_eq!(f.get("w.png"), Some(""));
    assert_eq!(f.get("q.png"), None);
    // one caption, both modalities: only the prefix differs
    let prompts = prompts_for(CaptionMode::Captions, f.get("x.png").unwrap());
    assert_eq!(prompts.len(), 2);
    let strip = |s: &str, m: Modality| s.strip_prefix(m.identifier()).unwrap().to_string();
    assert_eq!(strip(&prompts[0].1, Modality::Rgb), ", a desk");
    assert_eq!(strip(&prompts[1].1, Modality::Normal), ", a desk");

    for (text, needle) in [
        (
            "{\"image\": \"a.png\", \"caption\": \"ok\"}\n{not json}\n",
            "line 2",
        ),
        ("\n\n{\"caption\": \"no image\"}\n", "line 3"),
        ("{\"image\": \"a.png\"}\n", "line 1"),
        ("{\"image\": \"a.png\", \"caption\": 3}\n", "line 1"),
        ("[1, 2]\n", "line 1"),
    ] {
        std::fs::write(&p, text).unwrap();
        let e = CaptionFile::load(&p).unwrap_err().to_string();
        assert!(
            e.contains("blip.jsonl") && e.contains(needle),
            "{text:?}: {e}"
        );
    }
    let e = CaptionFile::load(Path::new("/nonexistent/c.jsonl"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("/nonexistent/c.jsonl"), "{e}");
}
