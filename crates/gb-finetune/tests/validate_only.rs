//! `finetune --validate-only` as a library call ([`validate_prior`]) on the shipped tiny
//! prior: the base and its own LoRA, with the fill baselines.

use gb_core::BackendKind;
use gb_diffusion::pipeline::SdComponents;
use gb_finetune::tiny_prior::SyntheticData;
use gb_finetune::train::FinetuneConfig;
use gb_finetune::validate_only::validate_prior;

#[test]
fn the_prior_s_own_lora_is_validated_beside_the_base_on_the_same_holes() {
    // draws from Burn's process-global device RNG (crate::DEVICE_RNG)
    let _rng = crate::DEVICE_RNG.lock().unwrap_or_else(|e| e.into_inner());
    let dir = gb_core::tiny_prior_dir();
    let device = BackendKind::Flex.device();
    let val = SyntheticData::builtin().held_out().expect("held-out pairs");
    let prior = SdComponents::load_inpainting(&dir, &device).expect("the tiny prior loads");
    let cfg = FinetuneConfig {
        resolution: prior.unet_config.native_resolution(prior.vae_factor()),
        validation_samples: 2,
        validation_average: 1,
        validation_ddim_steps: 4,
        ..FinetuneConfig::default()
    };
    let r = validate_prior(&prior, &dir, None, &val, &cfg, &device).expect("validation runs");
    let lora = r.lora.as_deref().expect("the prior's own LoRA is found");
    assert!(lora.ends_with(gb_diffusion::lora::LORA_FILE_NAME), "{lora}");
    assert_eq!(r.samples, 2);
    assert!(
        r.autoencoder_psnr.is_finite() && r.autoencoder_psnr > 10.0,
        "{r:?}"
    );
    let with = r.with_lora.as_ref().expect("a report with the LoRA");
    // the same holes: the baselines do not depend on the prior
    assert_eq!(with.fill_mean, r.base.fill_mean);
    assert_eq!(with.fill_nearest, r.base.fill_nearest);
    // the LoRA changes the prior's own fill
    assert_ne!(with.prior, r.base.prior, "{r:?}");
    let base_psnr = r.base.prior.rgb_masked_psnr.expect("an RGB score");
    assert!(base_psnr.is_finite() && base_psnr > 5.0, "{base_psnr}");
    // an explicit LoRA that does not exist is an error naming it
    let missing = dir.join("no-such-lora.safetensors");
    let err = validate_prior(&prior, &dir, Some(&missing), &val, &cfg, &device).unwrap_err();
    assert!(
        err.to_string().contains("no-such-lora.safetensors"),
        "{err}"
    );
}
