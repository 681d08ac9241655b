//! Per-scene personalisation with the built-in tiny prior and its geometric LoRA on a small
//! procedural stairs scene: the patches never show the object, training moves only the new
//! adapters and lowers the inpainting loss on fresh masks of its patches, and a run reuses
//! its cached LoRA until something it was trained from changes.

use std::path::{Path, PathBuf};

use gb_core::BackendKind;
use gb_finetune::sample::PairSource;
use gb_inpaint::personalize::{
    fresh_mask_loss, new_trainer, personalize, scene_patches, PersonalizeInputs,
    PersonalizeSettings,
};
use gb_inpaint::InpaintError;
use gb_nerf::scene::procedural::{self, ProceduralOptions, SceneName};
use gb_nerf::scene::{LoadOptions, Scene, Split};

use crate::DEVICE_RNG as LOCK;

fn scene(dir: &Path) -> Scene {
    let opts = ProceduralOptions {
        name: SceneName::Stairs,
        seed: 5,
        width: 48,
        height: 36,
        views: 5,
        test_views: 1,
        dilate: 1,
    };
    procedural::write(&opts, dir).unwrap();
    gb_nerf::scene::load(dir, &LoadOptions::default())
        .unwrap()
        .1
}

fn tiny() -> (PathBuf, PathBuf) {
    let dir = gb_diffusion::checkpoint::resolve_prior("tiny").unwrap();
    let lora = dir.join(gb_inpaint::prior::LORA_FILE_NAME);
    (dir, lora)
}

fn inputs<'a>(
    scene: &'a Scene,
    prior: &'a Path,
    lora: &'a Path,
    settings: &'a PersonalizeSettings,
    out: &'a Path,
) -> PersonalizeInputs<'a> {
    PersonalizeInputs {
        scene,
        downscale: 1,
        crop_margin: 0.25,
        prior,
        lora: Some(lora),
        resolution: 64,
        prompt: "RGB image, stairs",
        settings,
        references: &[],
        devices: BackendKind::Flex.into(),
        out,
    }
}

use gb_finetune::train::models::parameter_values;

fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let target = to.join(e.file_name());
        if e.path().is_dir() {
            copy_tree(&e.path(), &target);
        } else {
            std::fs::copy(e.path(), target).unwrap();
        }
    }
}

/// Every float parameter of `m` by path.
fn params<M: burn::module::Module>(m: &M) -> std::collections::BTreeMap<String, Vec<f32>> {
    parameter_values(m).unwrap()
}

#[test]
fn patches_avoid_the_masks_and_training_moves_only_the_adapters_and_lowers_the_loss() {
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let (prior, lora) = tiny();
    let settings = PersonalizeSettings {
        steps: 25,
        lr: 3e-3,
        ..PersonalizeSettings::default()
    };
    let out = dir.path().join("run");
    let i = inputs(&s, &prior, &lora, &settings, &out);

    let patches = scene_patches(&i).unwrap();
    assert!(patches.len() >= 10, "{} patches", patches.len());
    let train: Vec<_> = s.split(Split::Train).collect();
    let side = patches.rects[0].side;
    assert!((8..=36).contains(&side), "side {side}");
    for r in &patches.rects {
        assert_eq!(r.side, side);
        let view = train[r.view];
        let w = view.image.width;
        if let Some(m) = &view.mask {
            for y in r.y0..r.y0 + side {
                for x in r.x0..r.x0 + side {
                    assert!(!m.data[y * w + x], "patch {r:?} shows the object");
                }
            }
        }
        // the sample is the view's pixels there
        let sample = patches.load(patches.rects.iter().position(|q| q == r).unwrap());
        let sample = sample.unwrap();
        assert_eq!(&sample.rgb[..3], &view.image.get(r.x0, r.y0)[..]);
        assert_eq!(sample.caption, "RGB image, stairs");
    }

    let mut trainer = new_trainer(&i).unwrap();
    let before = params(&trainer.models.trainable);
    let loss_before = fresh_mask_loss(&trainer, &patches).unwrap();
    for _ in 0..settings.steps {
        let step = trainer.train_step(&patches).unwrap();
        assert!(!step.skipped && step.loss.is_finite(), "{step:?}");
    }
    let loss_after = fresh_mask_loss(&trainer, &patches).unwrap();
    eprintln!("fresh-mask inpainting loss {loss_before:.5} -> {loss_after:.5}");
    assert!(
        loss_after < 0.97 * loss_before,
        "{loss_before} -> {loss_after}"
    );
    let after = params(&trainer.models.trainable);
    let is_factor = |k: &str| k.contains(".lora.");
    for (k, v) in &before {
        if !is_factor(k) {
            assert!(after[k] == *v, "base parameter {k} changed");
        }
    }
    let moved: Vec<&String> = after
        .keys()
        .filter(|k| is_factor(k) && before.get(*k) != after.get(*k))
        .collect();
    assert!(!moved.is_empty(), "no adapter moved");
    assert!(moved.iter().all(|k| k.starts_with("unet.")), "{moved:?}");
}

#[test]
fn a_run_reuses_its_lora_until_what_it_was_trained_from_changes() {
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let (prior, lora) = tiny();
    let settings = PersonalizeSettings {
        steps: 2,
        ..PersonalizeSettings::default()
    };
    let out = dir.path().join("run");
    let first = personalize(&inputs(&s, &prior, &lora, &settings, &out)).unwrap();
    assert!(!first.cached);
    let file = out.join(&first.lora);
    assert!(file.is_file() && out.join("personalize/personalize.json").is_file());
    let again = personalize(&inputs(&s, &prior, &lora, &settings, &out)).unwrap();
    assert!(again.cached);
    // the cached losses come back from `personalize.json` bit for bit (serde_json's
    // float_roundtrip parser)
    assert_eq!(
        (again.loss_before, again.loss_after),
        (first.loss_before, first.loss_after),
        "{again:?} against {first:?}"
    );
    assert_eq!(again.patches, first.patches);
    // the cache follows the prior's contents, not its path: a copy elsewhere reuses it
    let copy = dir.path().join("prior-copy");
    copy_tree(&prior, &copy);
    let moved = personalize(&inputs(&s, &copy, &lora, &settings, &out)).unwrap();
    assert!(moved.cached, "a copy of the same prior must reuse the LoRA");
    let reseeded = PersonalizeSettings {
        seed: 1,
        ..settings.clone()
    };
    let other = personalize(&inputs(&s, &prior, &lora, &reseeded, &out)).unwrap();
    assert!(!other.cached, "another seed must retrain");
    // the prior loads with both LoRAs merged, and says so
    let p = gb_inpaint::prior::load_prior(
        &prior,
        &gb_inpaint::prior::PriorOptions {
            lora: Some(lora.clone()),
            personal: Some(file.clone()),
            precision: Some(gb_core::Precision::F32),
        },
        &BackendKind::Flex.device(),
    )
    .unwrap();
    assert_eq!(p.info.personal_lora.as_deref(), Some(file.as_path()));
    assert!(p.info.lora_unet_weights > 0);

    // a scene without masks has nothing to personalise around
    let mut unmasked = s.clone();
    unmasked.views.iter_mut().for_each(|v| v.mask = None);
    let e = personalize(&inputs(&unmasked, &prior, &lora, &settings, &out)).unwrap_err();
    assert!(
        matches!(e, InpaintError::Personalize { .. }) && e.to_string().contains("no masked"),
        "{e}"
    );
}

#[test]
fn a_large_object_gets_smaller_patches_rather_than_none() {
    use gb_inpaint::personalize::patches::crop_side;
    use gb_inpaint::personalize::{MIN_PATCHES, MIN_PATCH_SIDE};
    let dir = tempfile::tempdir().unwrap();
    let opts = ProceduralOptions {
        name: SceneName::Alcove,
        seed: 5,
        width: 64,
        height: 48,
        views: 6,
        test_views: 1,
        dilate: 1,
    };
    procedural::write(&opts, dir.path()).unwrap();
    let s = gb_nerf::scene::load(dir.path(), &LoadOptions::default())
        .unwrap()
        .1;
    let (prior, lora) = tiny();
    let settings = PersonalizeSettings::default();
    let out = dir.path().join("run");
    let i = inputs(&s, &prior, &lora, &settings, &out);
    let data =
        gb_nerf::train::data::TrainData::from_scene(&s, 1, gb_nerf::train::DepthSupervision::None)
            .unwrap();
    let full = crop_side(&data.views, 0.25).unwrap();
    let at_full = gb_inpaint::personalize::ScenePatches::new(&data.views, full, "x");
    let patches = scene_patches(&i).unwrap();
    let side = patches.rects[0].side;
    eprintln!(
        "crop side {full}: {} patches; shrunk to {side}: {}",
        at_full.len(),
        patches.len()
    );
    assert!(at_full.len() < MIN_PATCHES, "{}", at_full.len());
    assert!(side < full && (patches.len() >= MIN_PATCHES || side == MIN_PATCH_SIDE));
    for r in &patches.rects {
        let m = data.views[r.view].mask.as_ref().unwrap();
        for y in r.y0..r.y0 + side {
            assert!((r.x0..r.x0 + side).all(|x| !m.data[y * m.width + x]));
        }
    }
}

/// The workspace's serde_json parses every float it wrote back to the same bits
/// (`float_roundtrip`); without it this value, a personalisation loss once cached on one CPU,
/// came back one ulp low and a cache hit reported another loss.
#[test]
fn json_floats_read_back_bit_for_bit() {
    for x in [
        0.025560281006619338_f64,
        1.0 / 3.0,
        2.2250738585072014e-308,
        1e23,
    ] {
        let text = serde_json::to_string(&x).unwrap();
        let back: f64 = serde_json::from_str(&text).unwrap();
        assert_eq!(back.to_bits(), x.to_bits(), "{x:e} written as {text}");
    }
}

/// With `object_free` (a procedural scene's `clean/`), the views' masked squares join the
/// patches, drawn from the object-free images; a folder without any view's image, or not a
/// folder, is refused naming the setting.
#[test]
fn object_free_views_give_their_masked_squares_from_the_clean_images() {
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let (prior, lora) = tiny();
    let out = dir.path().join("run");
    let settings = PersonalizeSettings {
        object_free: Some(dir.path().join("clean")),
        ..PersonalizeSettings::default()
    };
    let i = inputs(&s, &prior, &lora, &settings, &out);
    let patches = scene_patches(&i).unwrap();
    let data =
        gb_nerf::train::data::TrainData::from_scene(&s, 1, gb_nerf::train::DepthSupervision::None)
            .unwrap();
    let plain = gb_inpaint::personalize::ScenePatches::new(&data.views, patches.rects[0].side, "x");
    assert!(
        patches.len() > plain.len(),
        "{} patches with clean views, {} without",
        patches.len(),
        plain.len()
    );
    let train: Vec<_> = s.split(Split::Train).collect();
    let mut masked = 0;
    for (k, r) in patches.rects.iter().enumerate() {
        let view = train[r.view];
        let m = view.mask.as_ref().unwrap();
        let w = view.image.width;
        let hit = (r.y0..r.y0 + r.side)
            .flat_map(|y| (r.x0..r.x0 + r.side).map(move |x| (x, y)))
            .find(|&(x, y)| m.data[y * w + x]);
        if let Some((x, y)) = hit {
            masked += 1;
            // the masked pixel comes from clean/, not from the view with the object
            let clean = gb_core::read_rgb(
                &dir.path().join("clean").join(format!("{}.png", view.name)),
                Some(s.background),
            )
            .unwrap();
            let sample = patches.load(k).unwrap();
            let at = ((y - r.y0) * r.side + (x - r.x0)) * 3;
            assert_eq!(&sample.rgb[at..at + 3], &clean.get(x, y)[..]);
        }
    }
    assert!(masked > 0, "no patch covers a mask");

    std::fs::create_dir_all(dir.path().join("empty")).unwrap();
    for (bad, why) in [
        (dir.path().join("nowhere"), "not a folder"),
        (dir.path().join("empty"), "holds no training view's image"),
    ] {
        let settings = PersonalizeSettings {
            object_free: Some(bad),
            ..PersonalizeSettings::default()
        };
        let e = scene_patches(&inputs(&s, &prior, &lora, &settings, &out)).unwrap_err();
        let text = e.to_string();
        assert!(
            text.contains("[personalize] object_free") && text.contains(why),
            "{text}"
        );
    }
}
