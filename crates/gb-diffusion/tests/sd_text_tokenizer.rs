//! Token ids of the CLIP tokenizer against transformers' `CLIPTokenizer` (fixture written
//! by tools/parity/make_text_fixtures.py from the real CLIP vocabulary).

use crate::sd_text_common;

use gb_diffusion::tokenizer::ClipTokenizer;
use sd_text_common::{copy_dir, fixtures};

fn expected() -> serde_json::Value {
    let text = std::fs::read_to_string(fixtures().join("tokenizer_expected.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn check(tok: &ClipTokenizer, key: &str) {
    let exp = expected();
    let prompts = exp["prompts"].as_array().unwrap();
    let ids = exp[key].as_array().unwrap();
    assert!(prompts.iter().any(|p| p.as_str().unwrap().len() > 300));
    for (prompt, want) in prompts.iter().zip(ids) {
        let prompt = prompt.as_str().unwrap();
        let want: Vec<u32> = want
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as u32)
            .collect();
        let got = tok.encode(prompt).unwrap();
        assert_eq!(got, want, "prompt {prompt:?}");
    }
}

#[test]
fn ids_match_transformers_sd15_config() {
    let tok = ClipTokenizer::from_dir(&fixtures().join("tokenizer")).unwrap();
    let special = tok.special_tokens();
    assert_eq!(special.bos.1, 49406);
    assert_eq!(special.eos.1, 49407);
    assert_eq!(special.pad.1, 49407);
    assert_eq!(special.max_length, 77);
    check(&tok, "input_ids_sd15");
}

#[test]
fn ids_match_transformers_with_sd2_pad_token() {
    let dir = tempfile::tempdir().unwrap();
    copy_dir(&fixtures().join("tokenizer"), dir.path());
    let cfg_path = dir.path().join("tokenizer_config.json");
    let mut cfg: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&cfg_path).unwrap()).unwrap();
    cfg["pad_token"] = serde_json::json!("!");
    std::fs::write(&cfg_path, cfg.to_string()).unwrap();
    let tok = ClipTokenizer::from_dir(dir.path()).unwrap();
    assert_eq!(tok.special_tokens().pad, ("!".to_string(), 0));
    check(&tok, "input_ids_sd2_pad");
}

#[test]
fn missing_vocab_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let err = ClipTokenizer::from_dir(dir.path()).unwrap_err();
    assert!(err.to_string().contains("vocab.json"), "{err}");
}
