//! Which files of a hub listing a diffusers inpainting pipeline needs, and whether a cached
//! snapshot already holds them.

use std::path::Path;

use crate::checkpoint::WeightVariant;
use crate::config::{read_json_config, ModelIndex};

/// The file whose presence marks a diffusers pipeline snapshot.
pub const MARKER: &str = "model_index.json";

/// The pipeline components that gb-diffusion loads, and so downloads (others, such as
/// `safety_checker` or `feature_extractor`, are skipped: they are never used here and the
/// safety checker alone is over 1 GB).
pub const LOADED_COMPONENTS: [&str; 5] = ["scheduler", "text_encoder", "tokenizer", "unet", "vae"];

/// The loaded components that carry weights.
const WEIGHTED_COMPONENTS: [&str; 3] = ["text_encoder", "unet", "vae"];

/// File endings of pickled (PyTorch `torch.save`) weights, which gb-diffusion never loads.
const PICKLED: [&str; 6] = [".bin", ".ckpt", ".pt", ".pth", ".pkl", ".pickle"];

/// The files of `files` (the repository listing) that the components of `index` need: for
/// each listed component in [`LOADED_COMPONENTS`], the `*.json` / `*.txt` files directly in
/// its folder and the `*.safetensors` weights of `variant` (`Auto`: the plain ones when the
/// component has them, else its `.fp16` ones). Sorted.
///
/// Errors (one line naming the component): a weighted component with only pickled weights
/// (with advice), or without safetensors weights of `variant`.
pub fn select_files(
    index: &ModelIndex,
    files: &[String],
    variant: WeightVariant,
) -> Result<Vec<String>, String> {
    let mut out = Vec::new();
    for component in index.component_names() {
        if !LOADED_COMPONENTS.contains(&component.as_str()) {
            continue;
        }
        let prefix = format!("{component}/");
        let direct: Vec<&str> = files
            .iter()
            .filter_map(|f| f.strip_prefix(&prefix))
            .filter(|rest| !rest.contains('/') && !rest.contains('\\'))
            .collect();
        let mut full = Vec::new();
        let mut fp16 = Vec::new();
        for name in &direct {
            if name.ends_with(".json") || name.ends_with(".txt") {
                out.push(format!("{prefix}{name}"));
            } else if let Some(stem) = name.strip_suffix(".safetensors") {
                // Same rule as `folder::list_safetensors`.
                if stem.ends_with(".fp16") || stem.contains(".fp16-") {
                    fp16.push(format!("{prefix}{name}"));
                } else if !stem.contains('.') {
                    full.push(format!("{prefix}{name}"));
                }
            }
        }
        let has_safetensors = !full.is_empty() || !fp16.is_empty();
        let chosen = match variant {
            WeightVariant::Full => full,
            WeightVariant::Fp16 => fp16,
            WeightVariant::Auto if !full.is_empty() => full,
            WeightVariant::Auto => fp16,
        };
        if chosen.is_empty() && WEIGHTED_COMPONENTS.contains(&component.as_str()) {
            return Err(missing_weights(
                &component,
                &direct,
                has_safetensors,
                variant,
            ));
        }
        out.extend(chosen);
    }
    out.sort();
    Ok(out)
}

/// Why weighted `component` has no usable weights, with what to do about it.
fn missing_weights(
    component: &str,
    direct: &[&str],
    has_safetensors: bool,
    variant: WeightVariant,
) -> String {
    if has_safetensors {
        return format!("component `{component}` has no {variant:?} safetensors weights (choose another weight variant)");
    }
    match direct
        .iter()
        .find(|n| PICKLED.iter().any(|ext| n.ends_with(ext)))
    {
        Some(pickled) => format!(
            "component `{component}` has only pickled weights (`{component}/{pickled}`), which \
             gb-diffusion does not load: use a revision with `*.safetensors` weights (e.g. the \
             hub's conversion pull request, `ID@refs/pr/N`), or convert them with diffusers \
             (`pipe.save_pretrained(DIR, safe_serialization=True)`) and pass DIR"
        ),
        None => format!("component `{component}` lists no `*.safetensors` weights"),
    }
}

/// What a cached snapshot at `dir` lacks before it can be loaded (`None`: nothing): its
/// `model_index.json` must parse, and each loaded component it lists must have its folder,
/// with `*.safetensors` weights for the weighted ones.
pub fn snapshot_gap(dir: &Path) -> Option<String> {
    let index: ModelIndex = match read_json_config(&dir.join(MARKER)) {
        Ok(index) => index,
        Err(e) => return Some(e.to_string()),
    };
    for component in index.component_names() {
        if !LOADED_COMPONENTS.contains(&component.as_str()) {
            continue;
        }
        let folder = dir.join(&component);
        let Ok(entries) = std::fs::read_dir(&folder) else {
            return Some(format!("component folder `{component}/` is missing"));
        };
        let weighted = WEIGHTED_COMPONENTS.contains(&component.as_str());
        let has_weights = entries.flatten().any(|e| {
            e.file_name().to_string_lossy().ends_with(".safetensors") && e.path().is_file()
        });
        if weighted && !has_weights {
            return Some(format!(
                "component `{component}/` has no `*.safetensors` weights"
            ));
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn index() -> ModelIndex {
        serde_json::from_str(
            r#"{"_class_name":"StableDiffusionInpaintPipeline",
                "unet":["diffusers","UNet2DConditionModel"],
                "vae":["diffusers","AutoencoderKL"],
                "safety_checker":["stable_diffusion","StableDiffusionSafetyChecker"],
                "tokenizer":["transformers","CLIPTokenizer"],
                "text_encoder":[null,null]}"#,
        )
        .unwrap()
    }

    fn listing(names: &[&str]) -> Vec<String> {
        names.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn selects_configs_and_the_weight_variant_of_loaded_components() {
        let files = listing(&[
            "model_index.json",
            "README.md",
            "unet/config.json",
            "unet/diffusion_pytorch_model.safetensors",
            "unet/diffusion_pytorch_model.fp16.safetensors",
            "unet/diffusion_pytorch_model.bin",
            "vae/config.json",
            "vae/diffusion_pytorch_model.fp16.safetensors",
            "vae/sub/x.json",
            "safety_checker/model.safetensors",
            "tokenizer/vocab.json",
            "tokenizer/merges.txt",
            "text_encoder/model.safetensors",
        ]);
        let auto = select_files(&index(), &files, WeightVariant::Auto).unwrap();
        assert_eq!(
            auto,
            [
                "tokenizer/merges.txt",
                "tokenizer/vocab.json",
                "unet/config.json",
                "unet/diffusion_pytorch_model.safetensors",
                "vae/config.json",
                "vae/diffusion_pytorch_model.fp16.safetensors",
            ]
        );
        let err = select_files(&index(), &files, WeightVariant::Full).unwrap_err();
        assert!(err.contains("`vae`") && err.contains("Full"), "{err}");
        let fp16 = select_files(&index(), &files, WeightVariant::Fp16).unwrap();
        assert!(fp16.contains(&"unet/diffusion_pytorch_model.fp16.safetensors".to_string()));
        assert!(!fp16.contains(&"unet/diffusion_pytorch_model.safetensors".to_string()));
    }

    #[test]
    fn refuses_pickled_only_weights_with_advice() {
        let files = listing(&[
            "unet/config.json",
            "unet/diffusion_pytorch_model.bin",
            "vae/config.json",
            "vae/diffusion_pytorch_model.safetensors",
            "tokenizer/vocab.json",
        ]);
        let err = select_files(&index(), &files, WeightVariant::Auto).unwrap_err();
        assert!(
            err.contains("`unet`")
                && err.contains("pickled")
                && err.contains("unet/diffusion_pytorch_model.bin")
                && err.contains("safe_serialization=True"),
            "{err}"
        );
        assert!(!err.contains('\n'));
        let files = listing(&["unet/config.json", "vae/x.safetensors"]);
        let err = select_files(&index(), &files, WeightVariant::Auto).unwrap_err();
        assert!(err.contains("`unet` lists no"), "{err}");
    }

    #[test]
    fn a_snapshot_gap_names_what_is_missing() {
        let dir = tempfile::tempdir().unwrap();
        assert!(snapshot_gap(dir.path()).unwrap().contains(MARKER));
        std::fs::write(
            dir.path().join(MARKER),
            r#"{"_class_name":"P","unet":["diffusers","UNet2DConditionModel"],"tokenizer":["transformers","CLIPTokenizer"],"safety_checker":["a","B"]}"#,
        )
        .unwrap();
        assert!(snapshot_gap(dir.path()).unwrap().contains("`tokenizer/`"));
        std::fs::create_dir_all(dir.path().join("tokenizer")).unwrap();
        std::fs::create_dir_all(dir.path().join("unet")).unwrap();
        std::fs::write(dir.path().join("unet/config.json"), "{}").unwrap();
        let gap = snapshot_gap(dir.path()).unwrap();
        assert!(
            gap.contains("`unet/`") && gap.contains("safetensors"),
            "{gap}"
        );
        std::fs::write(dir.path().join("unet/w.safetensors"), "x").unwrap();
        assert_eq!(snapshot_gap(dir.path()), None);
    }
}
