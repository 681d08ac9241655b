//! A method's prompts: the templates (`[prompts]`), the captions a scene folder provides, the
//! command-line overrides, and the prompts of a run resolved from the three.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

/// Prompt templates; `{caption}` and `{object_caption}` are replaced by the scene's captions
/// (a procedural scene's `scene.json`: `caption_without_object`, `caption_with_object`), or by
/// the defaults below when the scene has none.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PromptTemplates {
    /// `{caption}` when the scene has no caption.
    #[serde(default = "default_caption")]
    pub caption: String,
    /// `{object_caption}` when the scene has no caption of the object.
    #[serde(default = "default_object_caption")]
    pub object_caption: String,
    /// Appearance prompt (RGB guidance).
    #[serde(default = "default_appearance")]
    pub appearance: String,
    /// Negative prompt of the RGB guidance.
    #[serde(default = "default_negative")]
    pub negative: String,
    /// Geometry prompt (normal-map guidance).
    #[serde(default = "default_geometry")]
    pub geometry: String,
    /// Negative prompt of the normal-map guidance.
    #[serde(default = "default_geometry_negative")]
    pub geometry_negative: String,
}

fn default_caption() -> String {
    "a scene".into()
}
fn default_object_caption() -> String {
    "an object in the scene".into()
}
fn default_appearance() -> String {
    "RGB image, {caption}".into()
}
fn default_negative() -> String {
    "RGB image, {object_caption}".into()
}
fn default_geometry() -> String {
    "normal map, {caption}".into()
}
fn default_geometry_negative() -> String {
    "normal map, {object_caption}".into()
}

impl Default for PromptTemplates {
    fn default() -> Self {
        Self {
            caption: default_caption(),
            object_caption: default_object_caption(),
            appearance: default_appearance(),
            negative: default_negative(),
            geometry: default_geometry(),
            geometry_negative: default_geometry_negative(),
        }
    }
}

/// The captions a scene folder provides.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SceneCaptions {
    /// The scene without the object.
    pub caption: Option<String>,
    /// The scene with the object.
    pub object_caption: Option<String>,
}

impl SceneCaptions {
    /// Reads `caption_without_object` / `caption_with_object` from `DIR/scene.json` (written
    /// by the procedural generator); a missing file or key gives `None`.
    pub fn read(scene_dir: &Path) -> Self {
        let Ok(text) = std::fs::read_to_string(scene_dir.join("scene.json")) else {
            return Self::default();
        };
        let Ok(v) = serde_json::from_str::<serde_json::Value>(&text) else {
            return Self::default();
        };
        let get = |k: &str| v.get(k).and_then(|s| s.as_str()).map(str::to_string);
        Self {
            caption: get("caption_without_object"),
            object_caption: get("caption_with_object"),
        }
    }
}

/// Prompts given on the command line; each replaces the resolved template. With the `clap`
/// feature these are the flags `--prompt`, `--negative-prompt` and `--normal-prompt`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct PromptOverrides {
    /// Appearance prompt (RGB guidance).
    #[cfg_attr(feature = "clap", arg(long = "prompt", value_name = "PROMPT"))]
    pub appearance: Option<String>,
    /// Negative prompt of the RGB guidance.
    #[cfg_attr(
        feature = "clap",
        arg(long = "negative-prompt", value_name = "NEGATIVE_PROMPT")
    )]
    pub negative: Option<String>,
    /// Geometry prompt (normal-map guidance).
    #[cfg_attr(
        feature = "clap",
        arg(long = "normal-prompt", value_name = "NORMAL_PROMPT")
    )]
    pub geometry: Option<String>,
}

/// The prompts of a run, resolved.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Prompts {
    /// Appearance prompt.
    pub appearance: String,
    /// Negative prompt of the RGB guidance.
    pub negative: String,
    /// Geometry prompt.
    pub geometry: String,
    /// Negative prompt of the normal guidance.
    pub geometry_negative: String,
}

impl PromptTemplates {
    /// The prompts of a run: the templates with the scene's captions filled in, then the
    /// command-line overrides.
    pub fn resolve(&self, scene: &SceneCaptions, overrides: &PromptOverrides) -> Prompts {
        let t = self;
        let mut vars = BTreeMap::new();
        vars.insert(
            "{caption}",
            scene.caption.clone().unwrap_or_else(|| t.caption.clone()),
        );
        vars.insert(
            "{object_caption}",
            scene
                .object_caption
                .clone()
                .unwrap_or_else(|| t.object_caption.clone()),
        );
        let fill = |s: &str| {
            let mut out = s.to_string();
            for (k, v) in &vars {
                out = out.replace(k, v);
            }
            out
        };
        Prompts {
            appearance: overrides
                .appearance
                .clone()
                .unwrap_or_else(|| fill(&t.appearance)),
            negative: overrides
                .negative
                .clone()
                .unwrap_or_else(|| fill(&t.negative)),
            geometry: overrides
                .geometry
                .clone()
                .unwrap_or_else(|| fill(&t.geometry)),
            geometry_negative: fill(&t.geometry_negative),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::MethodConfig;

    #[test]
    fn prompts_fill_captions_and_take_overrides() {
        let m = MethodConfig::builtin("gb-nerf").unwrap();
        let scene = SceneCaptions {
            caption: Some("a staircase".into()),
            object_caption: Some("a staircase with a vase".into()),
        };
        let p = m.resolve_prompts(&scene, &PromptOverrides::default());
        assert_eq!(p.appearance, "RGB image, a staircase");
        assert_eq!(p.negative, "RGB image, a staircase with a vase");
        assert_eq!(p.geometry, "normal map, a staircase");
        let p = m.resolve_prompts(
            &SceneCaptions::default(),
            &PromptOverrides {
                appearance: Some("a bench".into()),
                ..Default::default()
            },
        );
        assert_eq!(p.appearance, "a bench");
        assert_eq!(p.geometry, format!("normal map, {}", m.prompts.caption));
    }
}
