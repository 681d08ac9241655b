//! Parity of the U-Net and VAE with diffusers 0.42.1 on tiny random-weight models, on every
//! test backend: max abs error 1e-4 in f32.

use crate::sd_image_common;

use gb_core::heavy_test_backends;
use gb_diffusion::models::{load_unet, load_vae};
use sd_image_common::{fixture, max_abs_err, read_f32, tensor3, tensor4};

const TOL: f32 = 1e-4;

fn unet_parity(model_dir: &str, io: &str) {
    for kind in heavy_test_backends() {
        let device = kind.device();
        let (unet, _) = load_unet(&fixture(model_dir), &device).expect("load unet");
        let sample = tensor4(io, "sample", &device);
        let (t, _) = read_f32(io, "timestep");
        let ehs = tensor3(io, "encoder_hidden_states", &device);
        let out = unet.forward(sample, &t, ehs);
        let (want, shape) = read_f32(io, "out");
        let err = max_abs_err(out, &want, &shape);
        println!("{model_dir} on {kind}: max abs err {err:.3e}");
        assert!(err < TOL, "{model_dir} on {kind}: max abs err {err}");
    }
}

#[test]
fn unet_sd15_inpainting_matches_diffusers() {
    unet_parity("pipeline", "unet_sd15_io.safetensors");
}

#[test]
fn unet_sd2_linear_projection_matches_diffusers() {
    unet_parity("unet_sd2", "unet_sd2_io.safetensors");
}

fn vae_encode_parity(model_dir: &str) {
    let io = "vae_encode_io.safetensors";
    for kind in heavy_test_backends() {
        let device = kind.device();
        let (vae, _) = load_vae(&fixture(model_dir), &device).expect("load vae");
        let mean = vae.encode_mean(tensor4(io, "image", &device));
        let (want, shape) = read_f32(io, "mean");
        let err = max_abs_err(mean, &want, &shape);
        println!("vae-encode ({model_dir}) on {kind}: max abs err {err:.3e}");
        assert!(err < TOL, "vae-encode ({model_dir}) on {kind}: {err}");
    }
}

#[test]
fn vae_encode_matches_diffusers() {
    vae_encode_parity("vae");
}

#[test]
fn vae_with_old_attention_names_matches_diffusers() {
    vae_encode_parity("vae_old");
}

#[test]
fn vae_decode_matches_diffusers() {
    let io = "vae_decode_io.safetensors";
    for kind in heavy_test_backends() {
        let device = kind.device();
        let (vae, _) = load_vae(&fixture("vae"), &device).expect("load vae");
        let image = vae.decode(tensor4(io, "latents", &device));
        let (want, shape) = read_f32(io, "image");
        let err = max_abs_err(image, &want, &shape);
        println!("vae-decode on {kind}: max abs err {err:.3e}");
        assert!(err < TOL, "vae-decode on {kind}: {err}");
    }
}
