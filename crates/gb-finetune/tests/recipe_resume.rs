//! Resuming the tiny prior's recipe after its autoencoder stage: the stage's loss log is read
//! back, and an unreadable one is an error naming the file (not an empty log).

use std::path::Path;

use gb_core::BackendKind;

fn recipe_copy(dir: &Path) -> std::path::PathBuf {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/tiny-prior");
    let recipe = dir.join("recipe");
    std::fs::create_dir_all(recipe.join("vae")).unwrap();
    let text = std::fs::read_to_string(src.join("recipe.toml"))
        .unwrap()
        .replace("train_seeds = [1, 2, 3, 4, 5, 6]", "train_seeds = [1]")
        .replace("val_seeds = [101, 102]", "val_seeds = [101]")
        .replace("width = 96", "width = 32")
        .replace("height = 72", "height = 24");
    std::fs::write(recipe.join("recipe.toml"), text).unwrap();
    std::fs::copy(src.join("vae/config.json"), recipe.join("vae/config.json")).unwrap();
    recipe
}

#[test]
fn an_unreadable_autoencoder_loss_log_is_an_error_naming_it() {
    // draws from Burn's process-global device RNG (crate::DEVICE_RNG)
    let _rng = crate::DEVICE_RNG.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let recipe = recipe_copy(dir.path());
    let out = dir.path().join("out");
    // a finished autoencoder stage on disk, with a broken loss log
    let done = out.join("vae/vae");
    std::fs::create_dir_all(&done).unwrap();
    std::fs::write(done.join("diffusion_pytorch_model.safetensors"), b"x").unwrap();
    std::fs::write(out.join("vae/losses.json"), "{ not a list").unwrap();
    let kind = BackendKind::Flex;
    let run = || {
        gb_finetune::tiny_prior::run_recipe(
            &recipe,
            &out,
            &kind.autodiff_device(),
            &kind.device(),
            true,
            false,
        )
    };
    let refused = |why: &str| match run() {
        Ok(_) => panic!("{why} is refused"),
        Err(e) => e.to_string(),
    };
    let err = refused("a broken loss log");
    assert!(
        err.contains("losses.json") && err.contains("not a list"),
        "{err}"
    );
    std::fs::remove_file(out.join("vae/losses.json")).unwrap();
    let err = refused("a missing loss log");
    assert!(err.contains("losses.json"), "{err}");
}
