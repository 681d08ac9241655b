//! CLIP text encoder and text-encoder LoRA parity with transformers / diffusers / peft on
//! every test backend (fixtures: tools/parity/make_text_fixtures.py). Tolerance 1e-4, f32.

use crate::sd_text_common;

use burn::module::Module;
use burn::tensor::Device;
use gb_core::test_backends;
use gb_diffusion::checkpoint::{keymap, DiffusersFolder, WeightVariant};
use gb_diffusion::clip::{load_text_encoder, ClipTextModel};
use gb_diffusion::lora::write::LoraExport;
use gb_diffusion::lora::{
    apply_lora, collect_lora, merge_lora, write_peft_lora, LoraComponent, LoraFile,
};
use sd_text_common::{fixtures, max_abs_err, read_f32, read_i64_rows};

const TOL: f32 = 1e-4;

fn load(name: &str, variant: WeightVariant, device: &Device) -> ClipTextModel {
    let folder = DiffusersFolder::open(fixtures().join(name)).unwrap();
    load_text_encoder(&folder, variant, device).unwrap().valid()
}

fn run(model: &ClipTextModel, device: &Device) -> burn::tensor::Tensor<3> {
    let ids = read_i64_rows("text_io.safetensors", "input_ids");
    model.forward(model.ids_tensor(&ids, device).unwrap())
}

#[test]
fn text_encoder_matches_transformers_on_every_backend() {
    for kind in test_backends() {
        let device = kind.device();
        for (folder, variant, expected) in [
            ("clip_quick", WeightVariant::Auto, "last_hidden_state_quick"),
            ("clip_gelu", WeightVariant::Full, "last_hidden_state_gelu"),
            ("clip_fp16", WeightVariant::Fp16, "last_hidden_state_fp16"),
        ] {
            let model = load(folder, variant, &device);
            let err = max_abs_err(
                run(&model, &device),
                &read_f32("text_io.safetensors", expected),
            );
            println!("{kind} {folder}: max abs err {err:.3e}");
            assert!(err < TOL, "{kind} {folder}: max abs err {err}");
        }
    }
}

fn lora_expected() -> (Vec<f32>, Vec<usize>) {
    read_f32("lora_io.safetensors", "last_hidden_state_lora")
}

fn with_lora(file: &std::path::Path, device: &Device) -> ClipTextModel {
    let base = load("clip_quick", WeightVariant::Auto, device);
    let lora = LoraFile::read(file).unwrap();
    let (model, n) = apply_lora(
        base,
        &lora,
        LoraComponent::TextEncoder,
        &keymap::TEXT_ENCODER,
    )
    .unwrap();
    assert_eq!(n, 8, "2 layers x q/k/v/out");
    model
}

#[test]
fn diffusers_and_kohya_lora_match_peft_on_every_backend() {
    let expected = lora_expected();
    for kind in test_backends() {
        let device = kind.device();
        for name in ["pytorch_lora_weights.safetensors", "kohya_lora.safetensors"] {
            let model = with_lora(&fixtures().join("lora").join(name), &device);
            let err = max_abs_err(run(&model, &device), &expected);
            println!("{kind} {name}: max abs err {err:.3e}");
            assert!(err < TOL, "{kind} {name}: {err}");
            let merged = merge_lora(model);
            let err = max_abs_err(run(&merged, &device), &expected);
            println!("{kind} {name} merged: max abs err {err:.3e}");
            assert!(err < TOL, "{kind} {name} merged: {err}");
        }
    }
}

#[test]
fn lora_changes_the_output_and_a_second_lora_is_refused() {
    let device = gb_core::BackendKind::Flex.device();
    let base = load("clip_quick", WeightVariant::Auto, &device);
    let plain = read_f32("text_io.safetensors", "last_hidden_state_quick");
    let expected = lora_expected();
    let diff = plain
        .0
        .iter()
        .zip(&expected.0)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(diff > 0.05, "the LoRA fixture must matter: {diff}");
    let file = LoraFile::read(&fixtures().join("lora/pytorch_lora_weights.safetensors")).unwrap();
    assert!(file.entries.iter().all(|e| (e.scale - 2.0).abs() < 1e-12));
    let (model, _) = apply_lora(
        base,
        &file,
        LoraComponent::TextEncoder,
        &keymap::TEXT_ENCODER,
    )
    .unwrap();
    let err = apply_lora(
        model,
        &file,
        LoraComponent::TextEncoder,
        &keymap::TEXT_ENCODER,
    )
    .unwrap_err();
    assert!(err.to_string().contains("already has a LoRA"), "{err}");
}

#[test]
fn written_peft_file_round_trips() {
    let device = gb_core::BackendKind::Flex.device();
    let model = with_lora(
        &fixtures().join("lora/pytorch_lora_weights.safetensors"),
        &device,
    );
    let factors = collect_lora(&model).unwrap();
    assert_eq!(factors.len(), 8);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("pytorch_lora_weights.safetensors");
    write_peft_lora(
        &out,
        &[LoraExport {
            component: LoraComponent::TextEncoder,
            section: &keymap::TEXT_ENCODER,
            factors,
            alpha: 8.0,
        }],
    )
    .unwrap();
    if let Some(dir) = std::env::var_os("GB_LORA_EXPORT_DIR") {
        std::fs::copy(
            &out,
            std::path::Path::new(&dir).join("rust_text_lora.safetensors"),
        )
        .unwrap();
    }
    let reread = LoraFile::read(&out).unwrap();
    let original =
        LoraFile::read(&fixtures().join("lora/pytorch_lora_weights.safetensors")).unwrap();
    assert_eq!(reread.entries.len(), original.entries.len());
    for e in &reread.entries {
        assert!(
            e.module.starts_with("text_model.encoder.layers."),
            "{}",
            e.module
        );
        assert!((e.scale - 2.0).abs() < 1e-12);
        let twin = original
            .entries
            .iter()
            .find(|o| format!("text_model.{}", o.module) == e.module)
            .unwrap();
        assert_eq!(twin.down_shape, e.down_shape);
        assert_eq!(twin.down, e.down);
        assert_eq!(twin.up, e.up);
    }
    let fresh = with_lora(&out, &device);
    let err = max_abs_err(run(&fresh, &device), &lora_expected());
    assert!(err < TOL, "round trip: {err}");
}

#[test]
fn legacy_lora_down_up_keys_with_alpha_load() {
    use gb_diffusion::lora::tensor_io::f32_bytes;
    use safetensors::tensor::TensorView;
    let device = gb_core::BackendKind::Flex.device();
    let src = std::fs::read(fixtures().join("lora/pytorch_lora_weights.safetensors")).unwrap();
    let st = safetensors::SafeTensors::deserialize(&src).unwrap();
    let mut owned: Vec<(String, Vec<u8>, Vec<usize>)> = Vec::new();
    for (key, view) in st.tensors() {
        let key = key
            .replace("text_encoder.", "text_encoder.text_model.")
            .replace(".lora_A.weight", ".lora.down.weight")
            .replace(".lora_B.weight", ".lora.up.weight");
        owned.push((key, view.data().to_vec(), view.shape().to_vec()));
        if owned.last().unwrap().0.ends_with(".lora.down.weight") {
            let alpha_key = owned
                .last()
                .unwrap()
                .0
                .replace(".lora.down.weight", ".alpha");
            owned.push((alpha_key, f32_bytes(&[8.0]), vec![]));
        }
    }
    let views: Vec<(String, TensorView<'_>)> = owned
        .iter()
        .map(|(k, b, s)| {
            (
                k.clone(),
                TensorView::new(safetensors::Dtype::F32, s.clone(), b).unwrap(),
            )
        })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("legacy.safetensors");
    std::fs::write(&path, safetensors::serialize(views, None).unwrap()).unwrap();
    let model = with_lora(&path, &device);
    let err = max_abs_err(run(&model, &device), &lora_expected());
    assert!(err < TOL, "legacy keys: {err}");
}
