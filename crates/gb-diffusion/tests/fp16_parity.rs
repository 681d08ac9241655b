//! `--precision f16`: the U-Net, the VAE and CLIP cast to half precision against diffusers /
//! transformers in fp16 on the same fixture models and inputs
//! (tools/parity/make_fp16_fixtures.py), on every test backend with f16 tensors (flex, and
//! wgpu on lavapipe in CI). Tolerance: the largest difference at most 1e-2 of the reference's
//! largest magnitude. The extremes: activations near 1e4 at t = 0.98 and 0.02 stay finite
//! and close to f32. A floor the other way: each f16 output differs from the fp32 reference
//! by at least [`F16_GAP_FLOOR`], a tenth of the gap between diffusers' own fp16 and fp32
//! outputs on these fixtures (1.1e-3 U-Net, 1.2e-3 at the extremes, 0.7e-3 and 1.3e-3 VAE
//! encoder and decoder, 1.1e-3 CLIP), so that a network that silently computes in f32 fails.
//!
//! These are among the suite's slowest tests (92 to 274 s together on 2 cores): whole f16
//! networks on wgpu, whose kernels lavapipe JIT-compiles. They stay: they are the only check
//! of the f16 path that a GPU runs (SPIR-V f16), and CI has no GPU.

use crate::sd_image_common;

use burn::module::Module;
use burn::tensor::{DType, Device, Tensor};
use gb_core::{test_backends, BackendKind, Precision};
use gb_diffusion::checkpoint::{DiffusersFolder, WeightVariant};
use gb_diffusion::clip::load_text_encoder;
use gb_diffusion::models::{load_unet, load_vae};
use gb_diffusion::precision::cast_frozen;
use sd_image_common::{fixture, read_f32, tensor3, tensor4};

/// Largest difference relative to the reference's largest magnitude.
const REL_TOL: f32 = 1e-2;
/// Least difference from the fp32 reference that shows the network computed in f16 (module
/// docs); our own f32 path is within about 1e-6 of it.
const F16_GAP_FLOOR: f32 = 1e-4;
const FP16_IO: &str = "../fp16/fp16_io.safetensors";
const TEXT_IO: &str = "../sd_text/text_io.safetensors";

/// The backends of this run that have f16 tensors.
fn f16_backends() -> Vec<(BackendKind, Device)> {
    test_backends()
        .into_iter()
        .map(|k| (k, k.device()))
        .filter(|(_, d)| d.supports_dtype(DType::F16))
        .collect()
}

/// `max |got - want| / max |want|`, with the shape checked and every value finite.
fn rel_err<const D: usize>(
    got: Tensor<D>,
    (want, shape): &(Vec<f32>, Vec<usize>),
    what: &str,
) -> f32 {
    assert_eq!(got.dims().as_slice(), shape.as_slice(), "{what}: shape");
    assert_eq!(got.dtype(), DType::F32, "{what}: the network returns f32");
    let got: Vec<f32> = got.into_data().convert::<f32>().try_to_vec().unwrap();
    assert!(
        got.iter().all(|v| v.is_finite()),
        "{what}: non-finite output"
    );
    let scale = want.iter().fold(0f32, |m, v| m.max(v.abs()));
    let diff = got
        .iter()
        .zip(want)
        .fold(0f32, |m, (a, b)| m.max((a - b).abs()));
    diff / scale
}

#[test]
fn ndarray_has_no_f16_and_the_error_says_so() {
    let err = Precision::resolve(Some(Precision::F16), &BackendKind::Ndarray.device()).unwrap_err();
    assert!(
        err.to_string().contains("ndarray computes in f32 only"),
        "{err}"
    );
}

#[test]
fn cast_weights_are_f16_except_the_norms() {
    let device = BackendKind::Flex.device();
    let (unet, _) = load_unet(&fixture("pipeline"), &device).unwrap();
    let unet = cast_frozen(unet, Precision::F16);
    assert_eq!(unet.conv_in.weight.val().dtype(), DType::F16);
    assert_eq!(
        unet.time_embedding.linear_1.weight.val().dtype(),
        DType::F16
    );
    let norm = &unet.conv_norm_out;
    assert_eq!(norm.gamma.as_ref().unwrap().val().dtype(), DType::F32);
    // Back to f32: the weights come back f32, and the cast of an f32 model changes nothing.
    let back = cast_frozen(unet, Precision::F32);
    assert_eq!(back.conv_in.weight.val().dtype(), DType::F32);
}

#[test]
fn unet_f16_matches_diffusers_fp16() {
    let io = "unet_sd15_io.safetensors";
    for (kind, device) in f16_backends() {
        let (unet, _) = load_unet(&fixture("pipeline"), &device).unwrap();
        let unet = cast_frozen(unet, Precision::F16);
        let (t, _) = read_f32(io, "timestep");
        let out = unet.forward(
            tensor4(io, "sample", &device),
            &t,
            tensor3(io, "encoder_hidden_states", &device),
        );
        let vs_fp16 = rel_err(out.clone(), &read_f32(FP16_IO, "unet_out"), "unet");
        let vs_fp32 = rel_err(out, &read_f32(io, "out"), "unet");
        println!("unet f16 on {kind}: {vs_fp16:.2e} of diffusers fp16, {vs_fp32:.2e} of fp32");
        assert!(
            vs_fp16 <= REL_TOL,
            "unet f16 on {kind}: {vs_fp16} vs diffusers fp16"
        );
        assert!(
            (F16_GAP_FLOOR..=REL_TOL).contains(&vs_fp32),
            "unet f16 on {kind}: {vs_fp32} vs diffusers fp32 (under {F16_GAP_FLOOR}: computed in f32)"
        );
    }
}

#[test]
fn vae_f16_matches_diffusers_fp16() {
    for (kind, device) in f16_backends() {
        let (vae, _) = load_vae(&fixture("vae"), &device).unwrap();
        let vae = cast_frozen(vae, Precision::F16);
        let enc = "vae_encode_io.safetensors";
        let mean = vae.encode_mean(tensor4(enc, "image", &device));
        let e_mean = rel_err(mean.clone(), &read_f32(FP16_IO, "vae_mean"), "vae mean");
        let g_mean = rel_err(mean, &read_f32(enc, "mean"), "vae mean");
        let dec = "vae_decode_io.safetensors";
        let image = vae.decode(tensor4(dec, "latents", &device));
        let e_image = rel_err(image.clone(), &read_f32(FP16_IO, "vae_image"), "vae image");
        let g_image = rel_err(image, &read_f32(dec, "image"), "vae image");
        println!(
            "vae f16 on {kind}: encode {e_mean:.2e}, decode {e_image:.2e} of diffusers fp16; \
             {g_mean:.2e}, {g_image:.2e} of fp32"
        );
        assert!(
            e_mean <= REL_TOL && e_image <= REL_TOL,
            "vae f16 on {kind}: {e_mean} {e_image}"
        );
        assert!(
            g_mean >= F16_GAP_FLOOR && g_image >= F16_GAP_FLOOR,
            "vae f16 on {kind}: {g_mean} {g_image} of fp32, under {F16_GAP_FLOOR}: computed in f32"
        );
    }
}

#[test]
fn clip_f16_matches_transformers_fp16() {
    let root = fixture("../sd_text/clip_quick");
    let (ids, shape) = read_f32(TEXT_IO, "input_ids");
    let rows: Vec<Vec<i64>> = ids
        .chunks(shape[1])
        .map(|r| r.iter().map(|&v| v as i64).collect())
        .collect();
    for (kind, device) in f16_backends() {
        let folder = DiffusersFolder::open(&root).unwrap();
        let clip = load_text_encoder(&folder, WeightVariant::Auto, &device)
            .unwrap()
            .valid();
        let clip = cast_frozen(clip, Precision::F16);
        let out = clip.forward(clip.ids_tensor(&rows, &device).unwrap());
        let err = rel_err(
            out.clone(),
            &read_f32(FP16_IO, "clip_last_hidden_state"),
            "clip",
        );
        let gap = rel_err(out, &read_f32(TEXT_IO, "last_hidden_state_quick"), "clip");
        println!("clip f16 on {kind}: {err:.2e} of transformers fp16, {gap:.2e} of fp32");
        assert!(err <= REL_TOL, "clip f16 on {kind}: {err}");
        assert!(
            gap >= F16_GAP_FLOOR,
            "clip f16 on {kind}: {gap} of fp32, under {F16_GAP_FLOOR}: computed in f32"
        );
    }
}

/// Activations near 1e4 (past f16's square root of its largest value, so a norm's variance
/// would overflow in f16) at t = 0.98 and 0.02: the f16 U-Net stays finite and within the
/// tolerance of diffusers' fp32 output.
#[test]
fn unet_f16_at_the_extremes_stays_finite_and_close_to_f32() {
    let (absmax, _) = read_f32(FP16_IO, "extreme_activation_absmax");
    assert!(absmax[0] > 1e4, "the fixture reaches {} only", absmax[0]);
    let io = "unet_sd15_io.safetensors";
    for (kind, device) in f16_backends() {
        let (unet, _) = load_unet(&fixture("pipeline"), &device).unwrap();
        let unet = cast_frozen(unet, Precision::F16);
        let (t, _) = read_f32(FP16_IO, "extreme_timestep");
        assert_eq!(t, vec![980.0, 20.0]);
        let out = unet.forward(
            tensor4(FP16_IO, "extreme_sample", &device),
            &t,
            tensor3(io, "encoder_hidden_states", &device),
        );
        let err = rel_err(out, &read_f32(FP16_IO, "extreme_out_f32"), "unet extremes");
        println!("unet f16 extremes on {kind}: {err:.2e} of diffusers fp32");
        assert!(
            (F16_GAP_FLOOR..=REL_TOL).contains(&err),
            "unet f16 extremes on {kind}: {err} (under {F16_GAP_FLOOR}: computed in f32)"
        );
    }
}
