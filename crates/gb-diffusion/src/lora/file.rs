//! Reading LoRA files: diffusers/PEFT (`lora_A`/`lora_B`, older `lora.down`/`lora.up`,
//! `lora_linear_layer.down/up`, attention-processor `to_q_lora.down`), and kohya
//! (`lora_te_...`/`lora_unet_...` with `lora_down`/`lora_up` and `alpha`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use safetensors::SafeTensors;
use serde::{Deserialize, Serialize};

use super::tensor_io::view_to_f32;
use super::LoraError;

/// The network a LoRA entry belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum LoraComponent {
    /// The CLIP text encoder (`text_encoder.` / `lora_te_`).
    TextEncoder,
    /// The U-Net (`unet.` / `lora_unet_`).
    Unet,
}

impl LoraComponent {
    /// The diffusers prefix of this component's keys (without the dot).
    pub fn prefix(self) -> &'static str {
        match self {
            LoraComponent::TextEncoder => "text_encoder",
            LoraComponent::Unet => "unet",
        }
    }
}

/// Suffixes that mark the down (A) factor, longest first.
const DOWN_SUFFIXES: &[&str] = &[
    ".lora_linear_layer.down.weight",
    ".lora.down.weight",
    ".lora_down.weight",
    ".lora_A.weight",
    ".down.weight",
];
/// Suffixes that mark the up (B) factor.
const UP_SUFFIXES: &[&str] = &[
    ".lora_linear_layer.up.weight",
    ".lora.up.weight",
    ".lora_up.weight",
    ".lora_B.weight",
    ".up.weight",
];

/// One low-rank update of one weight.
#[derive(Debug, Clone)]
pub struct LoraEntry {
    /// Which network it belongs to.
    pub component: LoraComponent,
    /// The target module as named in the file: a dotted diffusers path
    /// (`encoder.layers.0.self_attn.q_proj`), or a kohya underscored name when `kohya`.
    pub module: String,
    /// Whether `module` is a kohya underscored name.
    pub kohya: bool,
    /// Down / A factor, PyTorch layout `[r, in]` or `[r, in, kh, kw]`.
    pub down: Vec<f32>,
    /// Shape of `down`.
    pub down_shape: Vec<usize>,
    /// Up / B factor, PyTorch layout `[out, r]` or `[out, r, 1, 1]`.
    pub up: Vec<f32>,
    /// Shape of `up`.
    pub up_shape: Vec<usize>,
    /// The multiplier of `up @ down`: `alpha / r` (PEFT, kohya), `alpha / sqrt(r)` (rsLoRA).
    pub scale: f64,
    /// The first key of this entry in the file (for error messages).
    pub key: String,
}

impl LoraEntry {
    /// The rank `r`.
    pub fn rank(&self) -> usize {
        self.down_shape[0]
    }
}

/// A parsed LoRA file.
#[derive(Debug, Clone)]
pub struct LoraFile {
    /// Where it was read from.
    pub path: PathBuf,
    /// Every entry, sorted by component and module.
    pub entries: Vec<LoraEntry>,
}

#[derive(Default)]
struct Partial {
    down: Option<(Vec<f32>, Vec<usize>)>,
    up: Option<(Vec<f32>, Vec<usize>)>,
    alpha: Option<f64>,
    key: String,
}

/// PEFT adapter settings for one component, from `lora_adapter_metadata`.
#[derive(Debug, Default, Clone)]
struct PeftSettings {
    lora_alpha: Option<f64>,
    alpha_pattern: BTreeMap<String, f64>,
    use_rslora: bool,
}

impl LoraFile {
    /// Reads and parses `path`.
    pub fn read(path: &Path) -> Result<Self, LoraError> {
        let file_err = |message: String| LoraError::File {
            path: path.to_path_buf(),
            message,
        };
        if path.is_file() && crate::checkpoint::folder::is_pickle(path) {
            return Err(file_err(format!(
                "a PyTorch pickle, which is never loaded (unpickling can run code); convert it \
                 to safetensors: python -c \"import torch; from safetensors.torch import \
                 save_file; save_file(torch.load('{0}', weights_only=True), '{0}.safetensors')\"",
                path.display()
            )));
        }
        let bytes = std::fs::read(path).map_err(|e| file_err(e.to_string()))?;
        crate::checkpoint::header::check_layout(&bytes, bytes.len() as u64).map_err(file_err)?;
        let (_, meta) = SafeTensors::read_metadata(&bytes).map_err(|e| file_err(e.to_string()))?;
        let settings = peft_settings(meta.metadata().as_ref(), path)?;
        let st = SafeTensors::deserialize(&bytes).map_err(|e| file_err(e.to_string()))?;
        let mut partials: BTreeMap<(LoraComponent, String, bool), Partial> = BTreeMap::new();
        for (key, view) in st.tensors() {
            let (component, kohya, rest) = split_component(&key);
            let (module, role) = split_role(rest).ok_or_else(|| LoraError::UnknownKey {
                path: path.to_path_buf(),
                key: key.clone(),
            })?;
            let module = if kohya {
                module.to_string()
            } else {
                legacy_module_name(module, component)
            };
            let values = view_to_f32(&view).ok_or_else(|| {
                file_err(format!(
                    "tensor `{key}` has dtype {:?}, expected a float dtype (F32, F16, BF16, F64)",
                    view.dtype()
                ))
            })?;
            let shape = view.shape().to_vec();
            let p = partials.entry((component, module, kohya)).or_default();
            if p.key.is_empty() || key < p.key {
                p.key = key.clone();
            }
            match role {
                Role::Down => p.down = Some((values, shape)),
                Role::Up => p.up = Some((values, shape)),
                Role::Alpha => p.alpha = values.first().map(|v| *v as f64),
            }
        }
        let mut entries = Vec::with_capacity(partials.len());
        for ((component, module, kohya), p) in partials {
            let bad = |message: &str| LoraError::BadPair {
                path: path.to_path_buf(),
                module: module.clone(),
                message: message.to_string(),
            };
            let (down, down_shape) = p.down.ok_or_else(|| bad("no down / lora_A factor"))?;
            let (up, up_shape) = p.up.ok_or_else(|| bad("no up / lora_B factor"))?;
            if down_shape.len() < 2 || up_shape.len() < 2 || down_shape[0] != up_shape[1] {
                return Err(bad(&format!(
                    "rank mismatch: down {down_shape:?}, up {up_shape:?}"
                )));
            }
            if down_shape[0] == 0 {
                return Err(bad("rank 0: the factors hold no update"));
            }
            let rank = down_shape[0] as f64;
            let peft = settings.get(&component);
            let alpha = p
                .alpha
                .or_else(|| peft.and_then(|s| pattern_alpha(&s.alpha_pattern, &module)))
                .or_else(|| peft.and_then(|s| s.lora_alpha))
                .unwrap_or(rank);
            if !alpha.is_finite() {
                return Err(bad(&format!("alpha {alpha} is not finite")));
            }
            let rslora = peft.is_some_and(|s| s.use_rslora);
            let scale = if rslora {
                alpha / rank.sqrt()
            } else {
                alpha / rank
            };
            entries.push(LoraEntry {
                component,
                module,
                kohya,
                down,
                down_shape,
                up,
                up_shape,
                scale,
                key: p.key,
            });
        }
        Ok(Self {
            path: path.to_path_buf(),
            entries,
        })
    }

    /// The entries for one component.
    pub fn entries_for(&self, component: LoraComponent) -> impl Iterator<Item = &LoraEntry> {
        self.entries
            .iter()
            .filter(move |e| e.component == component)
    }
}

#[derive(Debug, Clone, Copy)]
enum Role {
    Down,
    Up,
    Alpha,
}

/// Splits the component prefix off a key: `(component, is_kohya, rest)`.
fn split_component(key: &str) -> (LoraComponent, bool, &str) {
    for (prefix, component, kohya) in [
        ("text_encoder.", LoraComponent::TextEncoder, false),
        ("unet.", LoraComponent::Unet, false),
        ("lora_te1_", LoraComponent::TextEncoder, true),
        ("lora_te_", LoraComponent::TextEncoder, true),
        ("lora_unet_", LoraComponent::Unet, true),
    ] {
        if let Some(rest) = key.strip_prefix(prefix) {
            return (component, kohya, rest);
        }
    }
    // Oldest diffusers files hold U-Net attention processors without a prefix.
    (LoraComponent::Unet, false, key)
}

fn split_role(rest: &str) -> Option<(&str, Role)> {
    for s in DOWN_SUFFIXES {
        if let Some(m) = rest.strip_suffix(s) {
            return Some((m, Role::Down));
        }
    }
    for s in UP_SUFFIXES {
        if let Some(m) = rest.strip_suffix(s) {
            return Some((m, Role::Up));
        }
    }
    rest.strip_suffix(".alpha").map(|m| (m, Role::Alpha))
}

/// Old attention-processor names: `attn1.processor.to_q_lora` -> `attn1.to_q`,
/// `to_out_lora` -> `to_out.0`; in the text encoder `self_attn.to_q_lora` -> `q_proj`.
fn legacy_module_name(module: &str, component: LoraComponent) -> String {
    let module = module.replace(".processor.", ".");
    for (old, unet, te) in [
        ("to_q_lora", "to_q", "q_proj"),
        ("to_k_lora", "to_k", "k_proj"),
        ("to_v_lora", "to_v", "v_proj"),
        ("to_out_lora", "to_out.0", "out_proj"),
    ] {
        if let Some(stem) = module.strip_suffix(old) {
            let new = match component {
                LoraComponent::Unet => unet,
                LoraComponent::TextEncoder => te,
            };
            return format!("{stem}{new}");
        }
    }
    module
}

/// PEFT's `alpha_pattern`: a key matches a module whose path ends with `.key` (or equals it).
fn pattern_alpha(patterns: &BTreeMap<String, f64>, module: &str) -> Option<f64> {
    patterns
        .iter()
        .find(|(k, _)| module == k.as_str() || module.ends_with(&format!(".{k}")))
        .map(|(_, v)| *v)
}

fn peft_settings(
    meta: Option<&std::collections::HashMap<String, String>>,
    path: &Path,
) -> Result<BTreeMap<LoraComponent, PeftSettings>, LoraError> {
    let mut out = BTreeMap::new();
    let Some(json) = meta.and_then(|m| m.get("lora_adapter_metadata")) else {
        return Ok(out);
    };
    let value: serde_json::Value = serde_json::from_str(json).map_err(|e| LoraError::File {
        path: path.to_path_buf(),
        message: format!("invalid lora_adapter_metadata: {e}"),
    })?;
    let Some(map) = value.as_object() else {
        return Ok(out);
    };
    for (prefix, component) in [
        ("text_encoder.", LoraComponent::TextEncoder),
        ("unet.", LoraComponent::Unet),
    ] {
        let get = |name: &str| map.get(&format!("{prefix}{name}"));
        if get("r").is_none() && get("lora_alpha").is_none() {
            continue;
        }
        let alpha_pattern = get("alpha_pattern")
            .and_then(|v| v.as_object())
            .map(|m| {
                m.iter()
                    .filter_map(|(k, v)| v.as_f64().map(|a| (k.clone(), a)))
                    .collect()
            })
            .unwrap_or_default();
        out.insert(
            component,
            PeftSettings {
                lora_alpha: get("lora_alpha").and_then(|v| v.as_f64()),
                alpha_pattern,
                use_rslora: get("use_rslora").and_then(|v| v.as_bool()).unwrap_or(false),
            },
        );
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn key_forms_resolve_to_modules() {
        let te = LoraComponent::TextEncoder;
        assert_eq!(
            split_role("encoder.layers.0.self_attn.q_proj.lora_A.weight")
                .unwrap()
                .0,
            "encoder.layers.0.self_attn.q_proj"
        );
        assert!(matches!(
            split_role("x.lora.up.weight").unwrap().1,
            Role::Up
        ));
        assert!(matches!(split_role("x.alpha").unwrap().1, Role::Alpha));
        assert!(split_role("x.weight").is_none());
        assert_eq!(
            legacy_module_name("text_model.encoder.layers.0.self_attn.to_out_lora", te),
            "text_model.encoder.layers.0.self_attn.out_proj"
        );
        assert_eq!(
            legacy_module_name(
                "down_blocks.0.attentions.0.transformer_blocks.0.attn1.processor.to_out_lora",
                LoraComponent::Unet
            ),
            "down_blocks.0.attentions.0.transformer_blocks.0.attn1.to_out.0"
        );
        let (c, kohya, rest) = split_component("lora_te_text_model_encoder_layers_0_mlp_fc1.alpha");
        assert_eq!(
            (c, kohya, rest),
            (te, true, "text_model_encoder_layers_0_mlp_fc1.alpha")
        );
    }
}
