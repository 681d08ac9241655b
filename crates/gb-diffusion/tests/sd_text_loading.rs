//! Checkpoint loading errors: a missing or misshaped tensor names the tensor, the
//! expected shape and the file.

use crate::sd_text_common;

use gb_diffusion::checkpoint::{DiffusersFolder, WeightVariant};
use gb_diffusion::clip::load_text_encoder;
use sd_text_common::{copy_dir, fixtures};

fn altered(field: &str, value: serde_json::Value) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    copy_dir(&fixtures().join("clip_quick"), dir.path());
    let cfg = dir.path().join("text_encoder/config.json");
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&cfg).unwrap()).unwrap();
    json[field] = value;
    std::fs::write(&cfg, json.to_string()).unwrap();
    dir
}

#[test]
fn misshaped_tensor_names_tensor_shape_and_file() {
    let dir = altered("intermediate_size", serde_json::json!(48));
    let folder = DiffusersFolder::open(dir.path()).unwrap();
    let device = gb_core::BackendKind::Flex.device();
    let err = load_text_encoder(&folder, WeightVariant::Auto, &device)
        .unwrap_err()
        .to_string();
    assert!(err.contains("mlp.fc"), "{err}");
    assert!(err.contains("model.safetensors"), "{err}");
    assert!(err.contains("48"), "{err}");
}

#[test]
fn missing_tensor_names_tensor_shape_and_file() {
    let dir = altered("num_hidden_layers", serde_json::json!(3));
    let folder = DiffusersFolder::open(dir.path()).unwrap();
    let device = gb_core::BackendKind::Flex.device();
    let err = load_text_encoder(&folder, WeightVariant::Auto, &device)
        .unwrap_err()
        .to_string();
    assert!(err.contains("text_model.encoder.layers.2."), "{err}");
    assert!(err.contains("model.safetensors"), "{err}");
    assert!(err.contains("[32"), "{err}");
}

#[test]
fn folder_reads_model_index_and_rejects_absent_components() {
    let folder = DiffusersFolder::open(fixtures().join("clip_quick")).unwrap();
    let index = folder.index.as_ref().unwrap();
    assert_eq!(
        index.component("text_encoder").unwrap().class_name(),
        Some("CLIPTextModel")
    );
    let device = gb_core::BackendKind::Flex.device();
    let err = load_text_encoder(&folder, WeightVariant::Fp16, &device)
        .unwrap_err()
        .to_string();
    assert!(err.contains("text_encoder"), "{err}");
}
