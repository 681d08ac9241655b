//! `model_index.json`: the table of contents of a diffusers pipeline folder.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// One pipeline component: `["library", "ClassName"]`, or `[null, null]` when absent.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ComponentRef(pub Option<String>, pub Option<String>);

impl ComponentRef {
    /// The library that defines the component (`diffusers`, `transformers`).
    pub fn library(&self) -> Option<&str> {
        self.0.as_deref()
    }
    /// The class name (`UNet2DConditionModel`, `CLIPTextModel`, ...).
    pub fn class_name(&self) -> Option<&str> {
        self.1.as_deref()
    }
}

/// Parsed `model_index.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelIndex {
    /// The pipeline class (`StableDiffusionInpaintPipeline`).
    #[serde(rename = "_class_name")]
    pub class_name: String,
    /// The diffusers version that wrote the file.
    #[serde(rename = "_diffusers_version", default)]
    pub diffusers_version: Option<String>,
    /// Every other entry: sub-folder name -> component, or a plain value
    /// (e.g. `requires_safety_checker: true`).
    #[serde(flatten)]
    pub entries: BTreeMap<String, serde_json::Value>,
}

impl ModelIndex {
    /// The component stored in sub-folder `name`, if the index lists one (non-null).
    pub fn component(&self, name: &str) -> Option<ComponentRef> {
        let value = self.entries.get(name)?;
        let c: ComponentRef = serde_json::from_value(value.clone()).ok()?;
        c.class_name()?;
        Some(c)
    }

    /// The names of all listed (non-null) components.
    pub fn component_names(&self) -> Vec<String> {
        self.entries
            .keys()
            .filter(|k| self.component(k).is_some())
            .cloned()
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_sd_inpainting_index() {
        let json = r#"{"_class_name":"StableDiffusionInpaintPipeline","_diffusers_version":"0.6.0",
          "feature_extractor":["transformers","CLIPImageProcessor"],
          "safety_checker":[null,null],"requires_safety_checker":false,
          "scheduler":["diffusers","PNDMScheduler"],"text_encoder":["transformers","CLIPTextModel"],
          "tokenizer":["transformers","CLIPTokenizer"],"unet":["diffusers","UNet2DConditionModel"],
          "vae":["diffusers","AutoencoderKL"]}"#;
        let m: ModelIndex = serde_json::from_str(json).unwrap();
        assert_eq!(m.class_name, "StableDiffusionInpaintPipeline");
        assert_eq!(
            m.component("unet").unwrap().class_name(),
            Some("UNet2DConditionModel")
        );
        assert!(m.component("safety_checker").is_none());
        assert!(m.component("requires_safety_checker").is_none());
        assert_eq!(
            m.component_names(),
            vec![
                "feature_extractor",
                "scheduler",
                "text_encoder",
                "tokenizer",
                "unet",
                "vae"
            ]
        );
    }
}
