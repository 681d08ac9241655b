//! `cargo xtask parity` for the tokenizer and the text encoder (with and without LoRA)
//! against the transformers / diffusers outputs committed in
//! crates/gb-diffusion/tests/fixtures/sd_text (tools/parity/make_text_fixtures.py).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use gb_tests::{workspace_root, xtask};

fn fixtures() -> PathBuf {
    workspace_root().join("crates/gb-diffusion/tests/fixtures/sd_text")
}

/// Minimal safetensors reader: name -> (dtype, shape, raw bytes).
fn read_safetensors(path: &Path) -> BTreeMap<String, (String, Vec<usize>, Vec<u8>)> {
    let bytes = std::fs::read(path).unwrap();
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + n]).unwrap();
    let data = &bytes[8 + n..];
    let mut out = BTreeMap::new();
    for (name, info) in header.as_object().unwrap() {
        if name == "__metadata__" {
            continue;
        }
        let dtype = info["dtype"].as_str().unwrap().to_string();
        let shape = info["shape"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as usize)
            .collect();
        let off = info["data_offsets"].as_array().unwrap();
        let (a, b) = (
            off[0].as_u64().unwrap() as usize,
            off[1].as_u64().unwrap() as usize,
        );
        out.insert(name.clone(), (dtype, shape, data[a..b].to_vec()));
    }
    out
}

fn f32s(raw: &[u8]) -> Vec<f32> {
    raw.chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

fn max_abs(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn parity_tokenizer_writes_transformers_ids() {
    let dir = tempfile::tempdir().unwrap();
    let expected: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(fixtures().join("tokenizer_expected.json")).unwrap(),
    )
    .unwrap();
    let prompts = dir.path().join("prompts.json");
    std::fs::write(&prompts, expected["prompts"].to_string()).unwrap();
    let out = dir.path().join("ids.safetensors");
    let run = xtask(&[
        "parity",
        "--component",
        "tokenizer",
        "--model",
        fixtures().to_str().unwrap(),
        "--inputs",
        prompts.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let tensors = read_safetensors(&out);
    let (dtype, shape, raw) = &tensors["input_ids"];
    assert_eq!(dtype, "I64");
    let want: Vec<i64> = expected["input_ids_sd15"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|r| r.as_array().unwrap().iter().map(|v| v.as_i64().unwrap()))
        .collect();
    assert_eq!(shape, &vec![want.len() / 77, 77]);
    let got: Vec<i64> = raw
        .chunks_exact(8)
        .map(|c| i64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    assert_eq!(got, want);
}

fn text_encoder(lora: Option<&str>) -> Vec<f32> {
    text_encoder_with(lora, &["--device", "flex"])
}

fn text_encoder_with(lora: Option<&str>, extra: &[&str]) -> Vec<f32> {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.safetensors");
    let model = fixtures().join("clip_quick");
    let inputs = fixtures().join("text_io.safetensors");
    let lora_path = lora.map(|l| fixtures().join("lora").join(l));
    let mut args = vec![
        "parity",
        "--component",
        "text-encoder",
        "--model",
        model.to_str().unwrap(),
        "--inputs",
        inputs.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend(extra);
    if let Some(l) = &lora_path {
        args.extend(["--lora", l.to_str().unwrap()]);
    }
    let run = xtask(&args);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let tensors = read_safetensors(&out);
    assert_eq!(tensors["last_hidden_state"].1, vec![2, 16, 32]);
    f32s(&tensors["last_hidden_state"].2)
}

#[test]
fn parity_text_encoder_matches_transformers_with_and_without_lora() {
    let io = read_safetensors(&fixtures().join("text_io.safetensors"));
    let err = max_abs(&text_encoder(None), &f32s(&io["last_hidden_state_quick"].2));
    assert!(err < 1e-4, "text encoder: {err}");
    let lora_io = read_safetensors(&fixtures().join("lora_io.safetensors"));
    let err = max_abs(
        &text_encoder(Some("pytorch_lora_weights.safetensors")),
        &f32s(&lora_io["last_hidden_state_lora"].2),
    );
    assert!(err < 1e-4, "text encoder + LoRA: {err}");
}

#[test]
fn parity_with_a_missing_model_exits_2_with_one_line() {
    let run = xtask(&[
        "parity",
        "--component",
        "text-encoder",
        "--model",
        "/nonexistent/model/dir",
        "--inputs",
        "x.safetensors",
        "--out",
        "y.safetensors",
    ]);
    assert_eq!(run.status.code(), Some(2));
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("/nonexistent/model/dir"), "{err}");
}

/// `--precision f16`: the text encoder in half precision against transformers in fp16
/// (crates/gb-diffusion/tests/fixtures/fp16, tools/parity/make_fp16_fixtures.py), within
/// 1e-2 of the output's largest magnitude; ndarray, which has no f16 tensors, is refused with
/// a line naming the flag.
#[test]
fn parity_text_encoder_in_f16_matches_transformers_fp16() {
    let fp16 = workspace_root().join("crates/gb-diffusion/tests/fixtures/fp16/fp16_io.safetensors");
    let want = f32s(&read_safetensors(&fp16)["clip_last_hidden_state"].2);
    let got = text_encoder_with(None, &["--device", "flex", "--precision", "f16"]);
    let scale = want.iter().fold(0f32, |m, v| m.max(v.abs()));
    let err = max_abs(&got, &want) / scale;
    assert!(err < 1e-2, "f16 text encoder: {err} of the largest value");
    let f32_out = text_encoder(None);
    assert!(
        max_abs(&got, &f32_out) > 1e-5,
        "--precision f16 computed in f32"
    );

    let dir = tempfile::tempdir().unwrap();
    let run = xtask(&[
        "parity",
        "--component",
        "text-encoder",
        "--model",
        fixtures().join("clip_quick").to_str().unwrap(),
        "--inputs",
        fixtures().join("text_io.safetensors").to_str().unwrap(),
        "--out",
        dir.path().join("o.safetensors").to_str().unwrap(),
        "--device",
        "ndarray",
        "--precision",
        "f16",
    ]);
    assert!(!run.status.success());
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("--precision"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}
