//! The guided step on a tiny procedural stairs scene with the committed tiny SD-inpainting
//! fixture (crates/gb-diffusion/tests/fixtures/sd_image/pipeline, resolution 32), on flex:
//!
//! - with no guidance, the guided trainer is gb-nerf's trainer, bit for bit;
//! - the gradient that reaches the rendered crop is exactly `lambda * sqrt(alpha_bar) *
//!   J_enc^T g` (the injection), and the field receives exactly the vector-Jacobian product
//!   of that image gradient through the crop render (so the guidance changes the field only
//!   through the masked crop); outside the mask the prior input is the ground truth;
//! - the normal-map input is a valid `(n + 1) / 2` image whose term reaches the field;
//! - a skipped (NaN) step leaves the field unchanged, and the run stops after the configured
//!   streak naming the last good checkpoint.

use std::path::Path;

use burn::tensor::{Tensor, TensorData};
use gb_core::BackendKind;
use gb_diffusion::distill::{LatentEncoder, PriorInputMode};
use gb_inpaint::{
    FitOptions, GuidedTrainer, InpaintError, MethodConfig, Modality, PromptOverrides, SceneCaptions,
};
use gb_nerf::field::NerfField;
use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};
use gb_nerf::scene::{LoadOptions, Scene};
use gb_nerf::train::{NerfConfig, Trainer};

use crate::DEVICE_RNG as LOCK;

const KIND: BackendKind = BackendKind::Flex;

fn scene(dir: &Path) -> Scene {
    let opts = ProceduralOptions {
        name: SceneName::Stairs,
        seed: 3,
        width: 40,
        height: 30,
        views: 5,
        test_views: 1,
        dilate: 1,
    };
    procedural::write(&opts, dir).unwrap();
    gb_nerf::scene::load(dir, &LoadOptions::default())
        .unwrap()
        .1
}

fn config() -> NerfConfig {
    let mut c = NerfConfig::preset("fast").unwrap();
    c.train.rays_per_batch = 64;
    c.train.steps = 3;
    c.sampler.samples_per_ray = 16;
    c
}

fn guided(
    scene: &Scene,
    dir: &Path,
    method: &str,
    edit: impl Fn(&mut MethodConfig),
) -> GuidedTrainer {
    let mut m = MethodConfig::builtin(method).unwrap();
    edit(&mut m);
    let guidance = m.needs_prior().then(|| {
        let prior = crate::fixture_prior();
        let prompts = m.resolve_prompts(&SceneCaptions::read(dir), &PromptOverrides::default());
        (prior, prompts)
    });
    GuidedTrainer::new(scene, config(), m, guidance, KIND).unwrap()
}

fn values<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().unwrap()
}

fn params(f: &NerfField) -> Vec<f32> {
    let mut v = Vec::new();
    if let Some(g) = &f.grid {
        v.extend(values(g.table.val()));
    }
    for mlp in [&f.density_net, &f.color_net] {
        for l in &mlp.layers {
            v.extend(values(l.weight.val()));
        }
    }
    v
}

/// The gradients of the hash table and the density MLP weights, then of the colour MLP
/// weights (`None` when no gradient reached the colour MLP).
fn param_grads(f: &NerfField, grads: &burn::tensor::Gradients) -> (Vec<f32>, Option<Vec<f32>>) {
    let mut v = Vec::new();
    if let Some(g) = &f.grid {
        v.extend(values(g.table.val().grad(grads).unwrap()));
    }
    for l in &f.density_net.layers {
        v.extend(values(l.weight.val().grad(grads).unwrap()));
    }
    let color: Option<Vec<f32>> = f
        .color_net
        .layers
        .iter()
        .map(|l| l.weight.val().grad(grads).map(values))
        .collect::<Option<Vec<_>>>()
        .map(|v| v.concat());
    (v, color)
}

fn max_rel(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(0.0f32, |m, x| m.max(x.abs())).max(1e-30);
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max)
        / scale
}

#[test]
fn without_guidance_the_guided_trainer_is_gb_nerfs_trainer() {
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let mut reference = Trainer::new(&s, config(), KIND).unwrap();
    for _ in 0..3 {
        reference.train_step().unwrap();
    }
    let mut ours = guided(&s, dir.path(), "none", |_| {});
    for _ in 0..3 {
        let rec = ours.train_step().unwrap();
        assert!(rec.guidance.is_empty() && !rec.skipped);
    }
    let (a, b) = (params(&reference.field), params(&ours.field));
    assert!(!a.is_empty());
    assert_eq!(a, b, "the fields differ after 3 steps");
}

#[test]
fn the_injected_gradient_is_lambda_times_the_encoder_vjp_and_reaches_the_field_through_the_crop() {
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let mut t = guided(&s, dir.path(), "bsd", |m| {
        m.lambda_rgb = 0.37.into();
        m.prior_input = PriorInputMode::PasteOnGroundTruth;
    });
    let view = t.guidance.as_ref().unwrap().views[0];
    let device = KIND.autodiff_device();

    // the prior input: rendered inside the mask, ground truth outside
    let (image, rays) = t.rgb_prior_input(view).unwrap();
    let vg = t.view_guidance(view).unwrap().clone();
    let r = vg.geometry.resolution;
    assert_eq!(image.dims(), [1, 3, r, r]);
    assert_eq!(rays, vg.geometry.masked.len());
    assert!(
        rays > 0 && rays < r * r,
        "{rays} masked crop pixels of {}",
        r * r
    );
    let img = values(image.clone());
    let gt = values(vg.ground_truth.clone());
    for (i, m) in vg.geometry.mask.iter().enumerate() {
        if !*m {
            for c in 0..3 {
                assert_eq!(
                    img[c * r * r + i],
                    gt[c * r * r + i],
                    "pixel {i} outside the mask"
                );
            }
        }
    }

    // (1) gradient w.r.t. the prior input = lambda * sqrt(alpha_bar) * J_enc^T g, exactly
    let dims = t.guidance.as_ref().unwrap().prior.info.resolution / 4;
    let noise_values: Vec<f32> = (0..4 * dims * dims)
        .map(|i| ((i * 7919) % 1000) as f32 / 500.0 - 1.0)
        .collect();
    let noise = || {
        Tensor::<4>::from_data(
            TensorData::new(noise_values.clone(), [1, 4, dims, dims]),
            &KIND.device(),
        )
    };
    let timestep = 500;
    let x =
        Tensor::<4>::from_data(TensorData::new(img.clone(), [1, 3, r, r]), &device).require_grad();
    let out = t
        .term(Modality::Rgb, view, x.clone(), 0, Some((timestep, noise())))
        .unwrap();
    let alpha_bar = t.guidance.as_ref().unwrap().prior.alphas.at(timestep);
    assert!(
        (out.scale - 0.37 * alpha_bar.sqrt()).abs() < 1e-12,
        "{}",
        out.scale
    );
    assert_eq!(out.diagnostics.unet_calls, 1);
    assert_eq!(out.diagnostics.unet_batch, 2);
    let g_latent = out.gradient.clone();
    let gx = values(x.grad(&out.loss.backward()).unwrap());
    let x2 =
        Tensor::<4>::from_data(TensorData::new(img.clone(), [1, 3, r, r]), &device).require_grad();
    let prior = &t.guidance.as_ref().unwrap().prior;
    let z = prior
        .encoder
        .encode(x2.clone().mul_scalar(2.0).sub_scalar(1.0))
        .unwrap();
    let plain = (z * g_latent.autodiff().detach()).sum();
    let vjp: Vec<f32> = values(x2.grad(&plain.backward()).unwrap())
        .into_iter()
        .map(|v| v * out.scale as f32)
        .collect();
    let err = max_rel(&gx, &vjp);
    println!("image gradient vs lambda * s * J^T g: max rel err {err:.2e}");
    assert!(err < 1e-5, "{err}");
    assert!(
        gx.iter().any(|v| v.abs() > 0.0),
        "no gradient reached the image"
    );

    // (2) the field gradient of the term = the VJP of that image gradient through the crop
    let (image, _) = t.rgb_prior_input(view).unwrap();
    let out = t
        .term(Modality::Rgb, view, image, 0, Some((timestep, noise())))
        .unwrap();
    let (d_geo, d_color) = param_grads(&t.field, &out.loss.backward());
    let (image, _) = t.rgb_prior_input(view).unwrap();
    let gimg = Tensor::<4>::from_data(TensorData::new(gx.clone(), [1, 3, r, r]), &device);
    let (t_geo, t_color) = param_grads(&t.field, &(image * gimg).sum().backward());
    let direct = [d_geo, d_color.unwrap()].concat();
    let through = [t_geo, t_color.unwrap()].concat();
    let err = max_rel(&direct, &through);
    println!("field gradient vs VJP through the crop render: max rel err {err:.2e}");
    assert!(err < 1e-4, "{err}");
    assert!(
        direct.iter().any(|v| v.abs() > 0.0),
        "no gradient reached the field"
    );
}

#[test]
fn the_normal_map_input_is_an_image_and_its_term_reaches_the_field() {
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let mut t = guided(&s, dir.path(), "bsd", |m| m.normal_render_divisor = 2);
    let view = t.guidance.as_ref().unwrap().views[0];
    let (image, rays) = t.normal_prior_input(view).unwrap();
    let r = t.guidance.as_ref().unwrap().resolution();
    assert_eq!(image.dims(), [1, 3, r, r]);
    assert_eq!(rays, (r / 2) * (r / 2));
    let v = values(image.clone());
    assert!(v
        .iter()
        .all(|x| x.is_finite() && (-1e-5..=1.0 + 1e-5).contains(x)));
    let out = t.term(Modality::Normal, view, image, 0, None).unwrap();
    assert!(out.loss.clone().detach().into_scalar::<f32>().is_finite());
    let (g, color) = param_grads(&t.field, &out.loss.backward());
    assert!(g.iter().all(|x| x.is_finite()));
    assert!(
        g.iter().any(|x| x.abs() > 0.0),
        "the normal term does not reach the geometry"
    );
    assert!(color.is_none(), "the normal map depends on geometry only");

    // a guided step: one backward of recon + both terms
    let rec = t.train_step().unwrap();
    let kinds: Vec<Modality> = rec.guidance.iter().map(|g| g.modality).collect();
    assert_eq!(
        kinds,
        [Modality::Rgb, Modality::Normal],
        "normal_start is 0 at 3 steps"
    );
    assert!(rec.loss.is_some() && !rec.skipped);
}

#[test]
fn non_finite_losses_are_skipped_then_stop_the_run_naming_the_last_good_checkpoint() {
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let mut t = guided(&s, dir.path(), "none", |m| {
        m.max_consecutive_nan = 3;
    });
    t.inject_nan_from_step = Some(2);
    t.config.train.steps = 10;
    t.config.train.checkpoint_every = 1;
    let ckpt = dir.path().join("out/checkpoint.bin");
    let log = dir.path().join("out/train_log.jsonl");
    let mut before = None;
    // steps 0 and 1 are finite (checkpoint after each); 2, 3, 4 are NaN
    let err = t
        .fit(&FitOptions {
            checkpoint: Some(ckpt.clone()),
            log: Some(log.clone()),
            append_log: false,
            progress: false,
        })
        .unwrap_err();
    if let Some((p, step)) = t.last_good_checkpoint() {
        before = Some((p.clone(), *step));
    }
    let msg = err.to_string();
    assert!(
        matches!(
            err,
            InpaintError::NonFiniteLoss {
                count: 3,
                step: 4,
                ..
            }
        ),
        "{msg}"
    );
    assert!(
        msg.contains(&ckpt.display().to_string()) && msg.contains("(step 2)"),
        "{msg}"
    );
    assert_eq!(before, Some((ckpt.clone(), 2)));
    let lines: Vec<serde_json::Value> = std::fs::read_to_string(&log)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let skipped: Vec<bool> = lines
        .iter()
        .map(|l| l["skipped"].as_bool().unwrap())
        .collect();
    assert_eq!(skipped, [false, false, true, true, true]);
    assert!(lines[2]["loss"].is_null());
    // skipped steps did not touch the field: it equals the checkpoint of step 2
    let resumed = GuidedTrainer::resume(
        &s,
        &ckpt,
        MethodConfig::builtin("none").unwrap(),
        None,
        KIND,
        None,
    )
    .unwrap();
    assert_eq!(resumed.step, 2);
    assert_eq!(params(&resumed.field), params(&t.field));
}

#[test]
fn pre_inpainted_images_and_depths_replace_the_masked_views() {
    let dir = tempfile::tempdir().unwrap();
    let mut s = scene(dir.path());
    let rgb_dir = dir.path().join("RGB_inpainted");
    let depth_dir = dir.path().join("Depth_inpainted");
    std::fs::create_dir_all(&rgb_dir).unwrap();
    std::fs::create_dir_all(&depth_dir).unwrap();
    let masked: Vec<usize> = (0..s.views.len())
        .filter(|&i| s.views[i].mask.is_some() && s.views[i].split == gb_nerf::scene::Split::Train)
        .collect();
    assert!(masked.len() >= 2);
    for &i in &masked {
        let v = &s.views[i];
        let img = gb_core::RgbImage::filled(v.image.width, v.image.height, [0.2, 0.4, 0.6]);
        gb_core::write_rgb_png(&rgb_dir.join(format!("{}.png", v.name)), &img).unwrap();
    }
    // a depth file for the first masked view only: near-scaled disparity 0.5 -> z = 2 near
    let first = &s.views[masked[0]];
    let (w, h) = (first.image.width, first.image.height);
    gb_core::write_gray_png(
        &depth_dir.join(format!("{}.png", first.name)),
        w,
        h,
        &vec![0.5; w * h],
    )
    .unwrap();
    let second_mask = s.views[masked[1]].mask.clone().unwrap();
    let masks: Vec<gb_nerf::scene::Mask> = masked
        .iter()
        .map(|&i| s.views[i].mask.clone().unwrap())
        .collect();
    let under_masks = |s: &gb_nerf::scene::Scene| -> (usize, usize) {
        let (mut under, mut all) = (0, 0);
        for (&i, m) in masked.iter().zip(&masks) {
            for p in &s.sparse_depth[&s.views[i].name] {
                all += 1;
                under += m.data[p.y as usize * m.width + p.x as usize] as usize;
            }
        }
        (under, all)
    };
    let (under_before, all_before) = under_masks(&s);
    let report = gb_inpaint::pre_inpainted::apply(&mut s, dir.path()).unwrap();
    // the object's sparse points go with its masks; the others stay
    let (under_after, all_after) = under_masks(&s);
    assert!(under_before > 0, "the generated object has sparse points");
    assert_eq!((under_after, all_after), (0, all_before - under_before));
    assert_eq!((report.images, report.depths), (masked.len(), 1));
    let near = s.near;
    for &i in &masked {
        let v = &s.views[i];
        assert!(v.mask.is_none(), "the mask of {} is dropped", v.name);
        assert!((v.image.get(3, 3)[1] - 0.4).abs() < 1.0 / 255.0);
    }
    let d = s.views[masked[0]].depth.as_ref().unwrap();
    assert!(
        d.iter().all(|z| (z - 2.0 * near).abs() < 1e-2 * near),
        "{}",
        d[0]
    );
    // no depth file: the ground-truth depth (which shows the object) is dropped in the mask
    let d = s.views[masked[1]].depth.as_ref().unwrap();
    for (z, m) in d.iter().zip(&second_mask.data) {
        if *m {
            assert_eq!(*z, 0.0);
        }
    }
    assert!(d.iter().any(|z| *z > 0.0));
}

/// The field gradients of one RGB term and one normal term of the first guided view, at a
/// fixed timestep and noise.
fn term_grads(t: &mut GuidedTrainer) -> Vec<Vec<f32>> {
    let view = t.guidance.as_ref().unwrap().views[0];
    let dims = t.guidance.as_ref().unwrap().prior.info.resolution / 4;
    let noise: Vec<f32> = (0..4 * dims * dims)
        .map(|i| ((i * 7919) % 1000) as f32 / 500.0 - 1.0)
        .collect();
    let mut out = Vec::new();
    for modality in [Modality::Rgb, Modality::Normal] {
        let (image, _) = match modality {
            Modality::Rgb => t.rgb_prior_input(view).unwrap(),
            Modality::Normal => t.normal_prior_input(view).unwrap(),
        };
        let n = Tensor::<4>::from_data(
            TensorData::new(noise.clone(), [1, 4, dims, dims]),
            &KIND.device(),
        );
        let term = t.term(modality, view, image, 0, Some((400, n))).unwrap();
        let (g, _) = param_grads(&t.field, &term.loss.backward());
        out.push(g);
    }
    out
}

#[test]
fn visibility_gating_scales_the_guidance_that_reaches_the_field() {
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let plain = term_grads(&mut guided(&s, dir.path(), "bsd", |_| {}));
    // before `visibility.start_step` every pixel counts as observed: a uniform 0.5
    let mut half = guided(&s, dir.path(), "bsd", |m| {
        m.visibility.observed_weight = 0.5;
        m.visibility.start_step = m.reference_steps;
    });
    assert_eq!(half.visibility_start(), 3);
    let gated = term_grads(&mut half);
    for (modality, (a, b)) in ["rgb", "normal"].iter().zip(plain.iter().zip(&gated)) {
        assert!(b.iter().any(|x| x.abs() > 0.0), "{modality}: no gradient");
        let halved: Vec<f32> = a.iter().map(|x| 0.5 * x).collect();
        let e = max_rel(b, &halved);
        assert!(
            e < 1e-4,
            "{modality}: gated gradient is not half the plain one ({e})"
        );
    }
    // at weight 0 the terms before the start would carry nothing: they are not computed
    let mut off = guided(&s, dir.path(), "bsd", |m| {
        m.visibility.observed_weight = 0.0;
        m.visibility.start_step = m.reference_steps;
    });
    let rec = off.train_step().unwrap();
    assert!(rec.guidance.is_empty(), "{:?}", rec.guidance.len());
    // an out-of-range weight is refused when the method is read
    let mut bad = MethodConfig::builtin("bsd").unwrap();
    bad.visibility.observed_weight = 2.0;
    assert!(bad.validate().unwrap_err().contains("observed_weight"));
}

/// Oracle guidance ([`gb_inpaint::oracle`]) with SDS at guidance scale 1: the term's latent
/// gradient is the pull `w(t) sqrt(a) / sqrt(1 - a) (z - z0)` to the object-free crop's
/// latents, whatever the noise: zero on the truth itself, non-zero on the view with the
/// object.
#[test]
fn an_oracle_score_pulls_to_the_object_free_crop_whatever_the_noise() {
    use gb_diffusion::distill::{Branch, GuidanceMethod};
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let clean_dir = dir.path().join("clean");
    let mut t = guided(&s, dir.path(), "bsd", |m| {
        m.lambda_rgb = 1.0.into();
        m.prior_input = PriorInputMode::PasteOnGroundTruth;
        m.rgb.as_mut().unwrap().guidance = GuidanceMethod::Sds {
            guidance_scale: 1.0,
        };
        m.oracle.clean = Some(clean_dir.clone());
        m.oracle.branches = vec![Branch::Text, Branch::Unconditional];
    });
    let downscale = t.nerf.config.train.image_downscale;
    let images =
        gb_inpaint::oracle::load_object_free(&s, &clean_dir, downscale, "[oracle] clean").unwrap();
    let view = t.guidance.as_ref().unwrap().views[0];
    let clean = images[view]
        .clone()
        .expect("every training view has a clean image");
    t.set_oracle(gb_inpaint::oracle::OracleTargets::new(
        images,
        vec![Branch::Text, Branch::Unconditional],
    ));
    let vg = t.view_guidance(view).unwrap().clone();
    let r = vg.geometry.resolution;
    let device = KIND.autodiff_device();
    let dims = t.guidance.as_ref().unwrap().prior.info.resolution / 4;
    let noise = |seed: usize| {
        let v: Vec<f32> = (0..4 * dims * dims)
            .map(|i| (((i + seed) * 7919) % 1000) as f32 / 500.0 - 1.0)
            .collect();
        Tensor::<4>::from_data(TensorData::new(v, [1, 4, dims, dims]), &KIND.device())
    };
    let truth = gb_inpaint::crop::crop_image(&clean, vg.geometry.bbox, r, &KIND.device());
    let norm = |g: &[f32]| g.iter().map(|v| v * v).sum::<f32>().sqrt();
    let mut grads = Vec::new();
    for (image, seed) in [
        (truth.clone(), 1),
        (vg.ground_truth.clone(), 1),
        (vg.ground_truth.clone(), 2),
    ] {
        let x = Tensor::<4>::from_data(image.into_data(), &device).require_grad();
        let out = t
            .term(Modality::Rgb, view, x, 0, Some((500, noise(seed))))
            .unwrap();
        assert_eq!(out.diagnostics.unet_calls, 1);
        grads.push(values(out.gradient));
    }
    let (on_truth, with_object) = (norm(&grads[0]), norm(&grads[1]));
    println!("oracle pull: {on_truth:.3e} on the truth, {with_object:.3e} with the object");
    assert!(with_object > 1e-3, "{with_object}");
    assert!(on_truth < 1e-4 * with_object, "{on_truth} vs {with_object}");
    assert!(
        max_rel(&grads[1], &grads[2]) < 1e-4,
        "the pull depends on the noise"
    );
}

/// `rgb_moves_geometry = false`: the RGB term's gradient reaches the colour head only, never
/// the hash table or the density network; the normal term still reaches the geometry.
#[test]
fn appearance_only_rgb_guidance_leaves_the_geometry_alone() {
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let mut t = guided(&s, dir.path(), "gb-nerf", |m| {
        m.lambda_rgb = 1.0.into();
        m.lambda_normal = 1.0.into();
        m.rgb_moves_geometry = false;
    });
    let view = t.guidance.as_ref().unwrap().views[0];
    let (image, _) = t.rgb_prior_input(view).unwrap();
    let out = t.term(Modality::Rgb, view, image, 0, None).unwrap();
    let grads = out.loss.backward();
    let f = &t.field;
    let reached = |g: Option<Tensor<2>>| g.is_some_and(|g| values(g).iter().any(|v| *v != 0.0));
    assert!(
        !f.grid
            .as_ref()
            .is_some_and(|g| reached(g.table.val().grad(&grads))),
        "the RGB term reached the hash table"
    );
    assert!(
        f.density_net
            .layers
            .iter()
            .all(|l| !reached(l.weight.val().grad(&grads))),
        "the RGB term reached the density network"
    );
    assert!(
        f.color_net
            .layers
            .iter()
            .any(|l| reached(l.weight.val().grad(&grads))),
        "the RGB term did not reach the colour head"
    );
    // the normal map still shapes the geometry
    let (normal, _) = t.normal_prior_input(view).unwrap();
    let out = t.term(Modality::Normal, view, normal, 0, None).unwrap();
    let (geometry, _) = param_grads(&t.field, &out.loss.backward());
    assert!(geometry.iter().any(|v| *v != 0.0));
}
