//! The shipped tiny prior (`assets/tiny-prior`) loads in our stack exactly as diffusers loads
//! it: text encoder and U-Net outputs, without and with its `pytorch_lora_weights.safetensors`,
//! against `tools/parity/check_tiny_prior.py` (diffusers 0.42.1).

use std::path::PathBuf;

use burn::tensor::{Int, Tensor, TensorData};
use gb_core::heavy_test_backends;
use gb_diffusion::checkpoint::{keymap, DiffusersFolder, WeightVariant};
use gb_diffusion::clip::text_model::load_text_encoder;
use gb_diffusion::lora::{apply_lora, LoraComponent, LoraFile};
use gb_diffusion::models::load_unet;
use gb_diffusion::tensor_file::{read_f32, read_i64};

fn io() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/tiny_prior_io.safetensors")
}

fn max_abs(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn tiny_prior_and_its_lora_match_diffusers() {
    let root = gb_core::tiny_prior_dir();
    let (ids, ids_shape) = read_i64(&io(), "input_ids").unwrap();
    let (x, x_shape) = read_f32(&io(), "sample").unwrap();
    let (t, _) = read_f32(&io(), "timesteps").unwrap();
    let lora = LoraFile::read(&root.join("pytorch_lora_weights.safetensors")).unwrap();
    for kind in heavy_test_backends() {
        let device = kind.device();
        let folder = DiffusersFolder::open(&root).unwrap();
        let te = load_text_encoder(&folder, WeightVariant::Auto, &device).unwrap();
        let (unet, _) = load_unet(&root, &device).unwrap();
        let ids_t: Tensor<2, Int> = Tensor::from_data(
            TensorData::new(ids.clone(), [ids_shape[0], ids_shape[1]]),
            &device,
        );
        let sample = || {
            Tensor::<4>::from_data(
                TensorData::new(x.clone(), [x_shape[0], x_shape[1], x_shape[2], x_shape[3]]),
                &device,
            )
        };
        for (suffix, te, unet) in [
            ("", te.clone(), unet.clone()),
            (
                "_lora",
                apply_lora(te, &lora, LoraComponent::TextEncoder, &keymap::TEXT_ENCODER)
                    .unwrap()
                    .0,
                apply_lora(unet, &lora, LoraComponent::Unet, &keymap::UNET)
                    .unwrap()
                    .0,
            ),
        ] {
            let ctx = te.forward(ids_t.clone());
            let ctx_v: Vec<f32> = ctx.clone().into_data().try_to_vec::<f32>().unwrap();
            let (want_ctx, _) = read_f32(&io(), &format!("context{suffix}")).unwrap();
            let e = max_abs(&ctx_v, &want_ctx);
            assert!(e < 1e-4, "{kind:?} context{suffix}: {e}");
            let eps: Vec<f32> = unet
                .forward(sample(), &t, ctx)
                .into_data()
                .try_to_vec::<f32>()
                .unwrap();
            let (want, _) = read_f32(&io(), &format!("eps{suffix}")).unwrap();
            let e = max_abs(&eps, &want);
            assert!(e < 1e-4, "{kind:?} eps{suffix}: {e}");
        }
    }
    // the LoRA is not a no-op
    let (a, _) = read_f32(&io(), "eps").unwrap();
    let (b, _) = read_f32(&io(), "eps_lora").unwrap();
    assert!(max_abs(&a, &b) > 1e-3);
}
