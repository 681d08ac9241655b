//! Loading errors, config validation and the VAE encoder under autodiff.

use crate::sd_image_common;

use std::collections::HashMap;

use burn::tensor::{Tensor, TensorData};
use gb_core::BackendKind;
use gb_diffusion::config::{AutoencoderKLConfig, UNet2DConditionConfig};
use gb_diffusion::models::{load_unet, load_vae, AutoencoderKL};
use sd_image_common::fixture;

/// Copies the `vae` fixture into a temp folder, dropping or reshaping one tensor.
fn broken_vae(drop: Option<&str>, reshape: Option<&str>) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let vae_dir = dir.path().join("vae");
    std::fs::create_dir_all(&vae_dir).unwrap();
    std::fs::copy(fixture("vae/vae/config.json"), vae_dir.join("config.json")).unwrap();
    let bytes = std::fs::read(fixture("vae/vae/diffusion_pytorch_model.safetensors")).unwrap();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let mut owned: HashMap<String, (Vec<usize>, Vec<u8>)> = HashMap::new();
    for (name, view) in st.tensors() {
        if Some(name.as_str()) == drop {
            continue;
        }
        let mut shape = view.shape().to_vec();
        let mut data = view.data().to_vec();
        if Some(name.as_str()) == reshape {
            shape = vec![shape.iter().product::<usize>() / 2];
            data.truncate(shape[0] * 4);
        }
        owned.insert(name, (shape, data));
    }
    let views: Vec<(String, safetensors::tensor::TensorView)> = owned
        .iter()
        .map(|(k, (s, d))| {
            (
                k.clone(),
                safetensors::tensor::TensorView::new(safetensors::Dtype::F32, s.clone(), d)
                    .unwrap(),
            )
        })
        .collect();
    safetensors::serialize_to_file(
        views,
        None,
        &vae_dir.join("diffusion_pytorch_model.safetensors"),
    )
    .unwrap();
    dir
}

#[test]
fn missing_vae_tensor_is_named_with_shape_and_file() {
    let key = "decoder.up_blocks.1.resnets.0.conv2.weight";
    let dir = broken_vae(Some(key), None);
    let err = load_vae(dir.path(), &BackendKind::Ndarray.device())
        .unwrap_err()
        .to_string();
    assert!(err.contains(key), "{err}");
    assert!(err.contains("[16, 16, 3, 3]"), "{err}");
    assert!(err.contains("diffusion_pytorch_model.safetensors"), "{err}");
}

#[test]
fn misshaped_vae_tensor_is_an_error() {
    let key = "encoder.conv_in.weight";
    let dir = broken_vae(None, Some(key));
    let err = load_vae(dir.path(), &BackendKind::Ndarray.device())
        .unwrap_err()
        .to_string();
    assert!(err.contains("encoder.conv_in.weight"), "{err}");
}

#[test]
fn missing_component_folder_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let err = load_unet(dir.path(), &BackendKind::Ndarray.device())
        .unwrap_err()
        .to_string();
    assert!(err.contains("unet"), "{err}");
}

#[test]
fn configs_read_diffusers_json_and_reject_unsupported_fields() {
    let unet = UNet2DConditionConfig::from_file(&fixture("pipeline/unet/config.json")).unwrap();
    assert_eq!(unet.in_channels, 9);
    assert_eq!(unet.heads(0), 2);
    assert!(!unet.use_linear_projection);
    let sd2 = UNet2DConditionConfig::from_file(&fixture("unet_sd2/unet/config.json")).unwrap();
    assert!(sd2.use_linear_projection);
    assert_eq!((sd2.heads(0), sd2.heads(2)), (2, 4));
    assert!(!sd2.flip_sin_to_cos);
    let vae = AutoencoderKLConfig::from_file(&fixture("vae/vae/config.json")).unwrap();
    assert_eq!(vae.scale_factor(), 4);
    assert!((vae.scaling_factor - 0.18215).abs() < 1e-12);

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("config.json");
    let text = std::fs::read_to_string(fixture("pipeline/unet/config.json")).unwrap();
    std::fs::write(
        &path,
        text.replace(
            "\"resnet_time_scale_shift\": \"default\"",
            "\"resnet_time_scale_shift\": \"scale_shift\"",
        ),
    )
    .unwrap();
    let err = UNet2DConditionConfig::from_file(&path)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("resnet_time_scale_shift") && err.contains("scale_shift"),
        "{err}"
    );
    std::fs::write(
        &path,
        text.replace("\"attention_head_dim\": 2", "\"attention_head_dim\": 3"),
    )
    .unwrap();
    let err = UNet2DConditionConfig::from_file(&path)
        .unwrap_err()
        .to_string();
    assert!(err.contains("attention_head_dim"), "{err}");
}

/// The encoder is differentiable: d(sum(mean * w))/d(image) matches central finite
/// differences of the frozen forward pass.
#[test]
fn vae_encoder_gradient_matches_finite_differences() {
    let ad = BackendKind::Ndarray.autodiff_device();
    let plain = BackendKind::Ndarray.device();
    let (vae_ad, _): (AutoencoderKL, _) = load_vae(&fixture("vae"), &ad).unwrap();
    let (vae, _) = load_vae(&fixture("vae"), &plain).unwrap();
    let n = 3 * 16 * 16;
    let img: Vec<f32> = (0..n)
        .map(|i| ((i * 37 % 101) as f32 / 50.0) - 1.0)
        .collect();
    let w: Vec<f32> = (0..4 * 4 * 4)
        .map(|i| ((i * 13 % 7) as f32 - 3.0) / 3.0)
        .collect();
    let objective =
        |vae: &AutoencoderKL, x: Tensor<4>, device: &burn::tensor::Device| -> Tensor<1> {
            let wt = Tensor::<4>::from_data(TensorData::new(w.clone(), [1, 4, 4, 4]), device);
            (vae.encode_mean(x) * wt).sum()
        };
    let x =
        Tensor::<4>::from_data(TensorData::new(img.clone(), [1, 3, 16, 16]), &ad).require_grad();
    let loss = objective(&vae_ad, x.clone(), &ad);
    let grads = loss.backward();
    let g: Vec<f32> = x
        .grad(&grads)
        .unwrap()
        .into_data()
        .convert::<f32>()
        .try_to_vec()
        .unwrap();
    let f = |v: &[f32]| -> f64 {
        let x = Tensor::<4>::from_data(TensorData::new(v.to_vec(), [1, 3, 16, 16]), &plain);
        objective(&vae, x, &plain).into_scalar::<f32>() as f64
    };
    let h = 1e-2f32;
    for idx in [0usize, 77, 300, 511, 767] {
        let mut p = img.clone();
        p[idx] += h;
        let mut m = img.clone();
        m[idx] -= h;
        let fd = (f(&p) - f(&m)) / (2.0 * h as f64);
        let an = g[idx] as f64;
        assert!(
            (fd - an).abs() <= 2e-2 * an.abs().max(0.05),
            "pixel {idx}: autodiff {an} vs finite difference {fd}"
        );
    }
    assert!(g.iter().any(|v| v.abs() > 1e-4), "gradient is not all zero");
}
