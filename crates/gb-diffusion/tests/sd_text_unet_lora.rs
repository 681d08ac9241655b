//! LoRA on the U-Net: a PEFT file written by diffusers (linear attention projections and
//! 3x3 conv LoRA on `conv1` / `conv_in`) applied to the sd-image fixture U-Net matches
//! diffusers' output, unmerged and merged, on every test backend; and the file we write
//! back reloads to the same output.

use crate::sd_text_common;

use burn::tensor::{Tensor, TensorData};
use gb_core::heavy_test_backends;
use gb_diffusion::checkpoint::keymap;
use gb_diffusion::lora::write::LoraExport;
use gb_diffusion::lora::{
    apply_lora, collect_lora, merge_lora, write_peft_lora, LoraComponent, LoraFile,
};
use gb_diffusion::models::load_unet;
use gb_diffusion::tensor_file::read_f32;
use sd_text_common::{fixtures, max_abs_err};

const TOL: f32 = 1e-4;

fn image_fixtures() -> std::path::PathBuf {
    fixtures().join("../sd_image")
}

fn run(
    unet: &gb_diffusion::models::UNet2DConditionModel,
    device: &burn::tensor::Device,
) -> Tensor<4> {
    let io = image_fixtures().join("unet_sd15_io.safetensors");
    let (s, ss) = read_f32(&io, "sample").unwrap();
    let (t, _) = read_f32(&io, "timestep").unwrap();
    let (e, es) = read_f32(&io, "encoder_hidden_states").unwrap();
    let sample = Tensor::<4>::from_data(TensorData::new(s, ss), device);
    let ehs = Tensor::<3>::from_data(TensorData::new(e, es), device);
    unet.forward(sample, &t, ehs)
}

fn expected() -> (Vec<f32>, Vec<usize>) {
    read_f32(&fixtures().join("unet_lora_io.safetensors"), "out_lora").unwrap()
}

#[test]
fn diffusers_unet_lora_with_conv_matches_on_every_backend() {
    let file = LoraFile::read(&fixtures().join("lora/unet_lora.safetensors")).unwrap();
    assert!(file.entries.iter().any(|e| e.down_shape.len() == 4));
    let want = expected();
    for kind in heavy_test_backends() {
        let device = kind.device();
        let (unet, _) = load_unet(&image_fixtures().join("pipeline"), &device).unwrap();
        let (unet, n) = apply_lora(unet, &file, LoraComponent::Unet, &keymap::UNET).unwrap();
        assert_eq!(n, file.entries.len());
        let err = max_abs_err(run(&unet, &device), &want);
        println!("{kind} unet LoRA: max abs err {err:.3e}");
        assert!(err < TOL, "{kind}: {err}");
        let merged = merge_lora(unet);
        let err = max_abs_err(run(&merged, &device), &want);
        println!("{kind} unet LoRA merged: max abs err {err:.3e}");
        assert!(err < TOL, "{kind} merged: {err}");
    }
}

#[test]
fn written_unet_lora_reloads_to_the_same_output() {
    let device = gb_core::BackendKind::Flex.device();
    let file = LoraFile::read(&fixtures().join("lora/unet_lora.safetensors")).unwrap();
    let (unet, _) = load_unet(&image_fixtures().join("pipeline"), &device).unwrap();
    let (unet, _) = apply_lora(unet, &file, LoraComponent::Unet, &keymap::UNET).unwrap();
    let factors = collect_lora(&unet).unwrap();
    assert_eq!(factors.len(), file.entries.len());
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("pytorch_lora_weights.safetensors");
    write_peft_lora(
        &out,
        &[LoraExport {
            component: LoraComponent::Unet,
            section: &keymap::UNET,
            factors,
            alpha: 3.0,
        }],
    )
    .unwrap();
    if let Some(dir) = std::env::var_os("GB_LORA_EXPORT_DIR") {
        std::fs::copy(
            &out,
            std::path::Path::new(&dir).join("rust_unet_lora.safetensors"),
        )
        .unwrap();
    }
    let reread = LoraFile::read(&out).unwrap();
    for e in &reread.entries {
        let twin = file.entries.iter().find(|o| o.module == e.module).unwrap();
        assert_eq!(
            (&twin.down_shape, &twin.up_shape),
            (&e.down_shape, &e.up_shape)
        );
        assert_eq!(twin.scale, e.scale);
    }
    let (fresh, _) = load_unet(&image_fixtures().join("pipeline"), &device).unwrap();
    let (fresh, _) = apply_lora(fresh, &reread, LoraComponent::Unet, &keymap::UNET).unwrap();
    let err = max_abs_err(run(&fresh, &device), &expected());
    assert!(err < TOL, "round trip: {err}");
}
