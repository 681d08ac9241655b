//! The DDIM inpainting sampler against diffusers' `StableDiffusionInpaintPipeline` on the
//! tiny fixture folder (3 steps, guidance 7.5, fixed initial latents).

use crate::sd_image_common;

use gb_core::{heavy_test_backends, read_gray, read_rgb};
use gb_diffusion::inpaint::{inpaint, prepare_conditioning, InpaintRequest};
use gb_diffusion::pipeline::SdComponents;
use sd_image_common::{fixture, max_abs_err, read_f32};

const IO: &str = "pipeline_io.safetensors";

fn request() -> InpaintRequest {
    let img = read_rgb(&fixture("pipeline_image.png"), None).unwrap();
    let (_, _, mask) = read_gray(&fixture("pipeline_mask.png")).unwrap();
    InpaintRequest {
        width: img.width,
        height: img.height,
        rgb: img.data,
        mask,
        prompt: "remove the stairs".into(),
        negative_prompt: "ob".into(),
        steps: 3,
        guidance: 7.5,
        seed: 0,
        init_latents: Some(read_f32(IO, "latents").0),
        blend_known: false,
    }
}

#[test]
fn inpainting_matches_diffusers_pipeline() {
    let req = request();
    for kind in heavy_test_backends() {
        let device = kind.device();
        let prior =
            SdComponents::load_inpainting(&fixture("pipeline"), &device).expect("load prior");
        let cond = prepare_conditioning(&prior, &req).unwrap();
        let (want, shape) = read_f32(IO, "masked_image_latents");
        let err = max_abs_err(cond.masked_image_latents, &want, &shape);
        assert!(err < 1e-4, "masked-image latents on {kind}: {err}");

        let mut steps = Vec::new();
        let image = inpaint(&prior, &req, |i, t| steps.push((i, t))).unwrap();
        assert_eq!(steps, vec![(0, 667), (1, 334), (2, 1)]);
        let (want, shape) = read_f32(IO, "image");
        let err = max_abs_err(image, &want, &shape);
        println!("inpaint pipeline on {kind}: max abs err {err:.3e}");
        assert!(err < 1e-4, "inpainted image on {kind}: {err}");
    }
}

#[test]
fn sizes_that_do_not_fit_the_vae_are_rejected() {
    let device = gb_core::BackendKind::Ndarray.device();
    let prior = SdComponents::load_inpainting(&fixture("pipeline"), &device).unwrap();
    let mut req = request();
    req.width = 30;
    req.height = 30;
    req.rgb.truncate(30 * 30 * 3);
    req.mask.truncate(30 * 30);
    let err = inpaint(&prior, &req, |_, _| {}).unwrap_err().to_string();
    assert!(err.contains("30x30") && err.contains("multiple"), "{err}");
    let mut req = request();
    req.init_latents = Some(vec![0.0; 3]);
    assert!(inpaint(&prior, &req, |_, _| {}).is_err());
}

#[test]
fn text_to_image_unet_is_not_an_inpainting_prior() {
    let err = match SdComponents::load_inpainting(
        &fixture("unet_sd2"),
        &gb_core::BackendKind::Ndarray.device(),
    ) {
        Ok(_) => panic!("unet_sd2 has no tokenizer or 9-channel U-Net"),
        Err(e) => e.to_string(),
    };
    assert!(err.contains("tokenizer"), "{err}");
}

#[test]
fn blending_the_known_region_pins_it_to_the_image_latent_whatever_the_noise() {
    // nothing to repaint: with blending the final latent is the image's own latent, so two
    // noise seeds decode to the same image; without it they differ
    let device = gb_core::BackendKind::Flex.device();
    let prior = SdComponents::load_inpainting(&fixture("pipeline"), &device).unwrap();
    let run = |seed: u64, blend: bool| {
        let mut req = request();
        req.mask = vec![0.0; req.mask.len()];
        req.init_latents = None;
        req.seed = seed;
        req.blend_known = blend;
        inpaint(&prior, &req, |_, _| {})
            .unwrap()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap()
    };
    let diff = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max)
    };
    let (a, b) = (run(1, true), run(2, true));
    assert!(diff(&a, &b) < 1e-6, "blended: {}", diff(&a, &b));
    let (c, d) = (run(1, false), run(2, false));
    assert!(diff(&c, &d) > 1e-3, "unblended: {}", diff(&c, &d));
}
