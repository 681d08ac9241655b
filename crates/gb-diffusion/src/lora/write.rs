//! Writing LoRA adapters in the diffusers/PEFT format that diffusers'
//! `load_lora_weights` accepts: `<component>.<module>.lora_A.weight` `[r, in(,kh,kw)]`,
//! `<component>.<module>.lora_B.weight` `[out, r(,1,1)]`, and a `lora_adapter_metadata`
//! entry (`<component>.r`, `.lora_alpha`, `.target_modules`, ...).

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use burn::module::Module;
use burn::store::{bridge, ModuleSnapshot};
use safetensors::tensor::TensorView;
use safetensors::Dtype;

use super::apply::LoraComponent;
use super::tensor_io::f32_bytes;
use super::LoraError;
use crate::checkpoint::KeymapSection;

/// The factors of one adapted weight, in PyTorch (PEFT) layout.
#[derive(Debug, Clone)]
pub struct CollectedLora {
    /// The module path in Burn (the weight's path without `.weight`).
    pub module: String,
    /// `lora_A`: `[r, in]` or `[r, in, kh, kw]`.
    pub down: Vec<f32>,
    /// Shape of `down`.
    pub down_shape: Vec<usize>,
    /// `lora_B`: `[out, r]` or `[out, r, 1, 1]`.
    pub up: Vec<f32>,
    /// Shape of `up`.
    pub up_shape: Vec<usize>,
}

/// One component's adapters with the settings to record.
#[derive(Debug, Clone)]
pub struct LoraExport<'a> {
    /// The component (key prefix).
    pub component: LoraComponent,
    /// Its keymap section (Burn paths are mapped back with `unmap_key`).
    pub section: &'a KeymapSection,
    /// The factors.
    pub factors: Vec<CollectedLora>,
    /// `lora_alpha` (the scale of every adapter is `alpha / r`).
    pub alpha: f64,
}

/// Reads every LoRA adapter (burn's `LoraAdapter` and [`super::ConvLoraAdapter`]) of
/// `module` out in PyTorch layout.
pub fn collect_lora<M: Module>(module: &M) -> Result<Vec<CollectedLora>, LoraError> {
    let mut tensors: BTreeMap<String, (Vec<f32>, Vec<usize>)> = BTreeMap::new();
    for t in module.collect(None, None, false) {
        let name = t.name.clone();
        let shape: Vec<usize> = t.shape.iter().copied().collect();
        let is_factor = name.contains(".lora.") || name.contains(".conv_lora.");
        let is_weight = name.ends_with(".weight");
        if !is_factor && !is_weight {
            continue;
        }
        if is_weight && !is_factor {
            tensors.insert(name, (Vec::new(), shape));
            continue;
        }
        let data = bridge::into_data(t).map_err(|e| LoraError::File {
            path: name.clone().into(),
            message: format!("cannot read adapter tensor: {e:?}"),
        })?;
        let values = data
            .convert::<f32>()
            .try_to_vec::<f32>()
            .map_err(|e| LoraError::File {
                path: name.clone().into(),
                message: format!("cannot read adapter tensor: {e:?}"),
            })?;
        tensors.insert(name, (values, shape));
    }
    let mut out = Vec::new();
    let bases: BTreeSet<String> = tensors
        .keys()
        .filter_map(|k| {
            k.strip_suffix(".lora.a")
                .or_else(|| k.strip_suffix(".conv_lora.up"))
                .map(str::to_string)
        })
        .collect();
    for base in bases {
        let module = base.strip_suffix(".weight").unwrap_or(&base).to_string();
        let weight_shape = tensors.get(&base).map(|t| t.1.clone()).unwrap_or_default();
        let missing = || LoraError::BadPair {
            path: base.clone().into(),
            module: module.clone(),
            message: "adapter factor missing".into(),
        };
        if let Some((a, a_shape)) = tensors.get(&format!("{base}.lora.a")) {
            // burn: a [in, r], b [r, out]  ->  PEFT: A [r, in], B [out, r]
            let (b, b_shape) = tensors.get(&format!("{base}.lora.b")).ok_or_else(missing)?;
            let (d_in, r) = (a_shape[0], a_shape[1]);
            let d_out = b_shape[1];
            out.push(CollectedLora {
                module,
                down: transpose(a, d_in, r),
                down_shape: vec![r, d_in],
                up: transpose(b, r, d_out),
                up_shape: vec![d_out, r],
            });
        } else {
            let (up, up_shape) = tensors
                .get(&format!("{base}.conv_lora.up"))
                .ok_or_else(missing)?;
            let (down, _) = tensors
                .get(&format!("{base}.conv_lora.down"))
                .ok_or_else(missing)?;
            let (d_out, r) = (up_shape[0], up_shape[1]);
            let mut down_shape = vec![r];
            down_shape.extend_from_slice(weight_shape.get(1..).unwrap_or(&[]));
            let mut up_full = vec![d_out, r];
            up_full.extend(std::iter::repeat_n(1, down_shape.len().saturating_sub(2)));
            out.push(CollectedLora {
                module,
                down: down.clone(),
                down_shape,
                up: up.clone(),
                up_shape: up_full,
            });
        }
    }
    Ok(out)
}

fn transpose(values: &[f32], rows: usize, cols: usize) -> Vec<f32> {
    let mut out = vec![0.0; values.len()];
    for r in 0..rows {
        for c in 0..cols {
            out[c * rows + r] = values[r * cols + c];
        }
    }
    out
}

/// Writes `exports` to `path` as one diffusers/PEFT LoRA safetensors file.
pub fn write_peft_lora(path: &Path, exports: &[LoraExport<'_>]) -> Result<(), LoraError> {
    let mut names: Vec<(String, Vec<u8>, Vec<usize>)> = Vec::new();
    let mut meta = serde_json::Map::new();
    for export in exports {
        let prefix = export.component.prefix();
        let mut ranks: BTreeMap<String, usize> = BTreeMap::new();
        let mut targets: BTreeSet<String> = BTreeSet::new();
        for f in &export.factors {
            let original = export.section.unmap_key(&format!("{}.weight", f.module))?;
            let module = original
                .strip_suffix(".weight")
                .unwrap_or(&original)
                .to_string();
            let leaf = module.rsplit('.').next().unwrap_or(&module).to_string();
            targets.insert(if leaf.chars().all(|c| c.is_ascii_digit()) {
                // `to_out.0`: PEFT matches the full suffix.
                module
                    .rsplit('.')
                    .take(2)
                    .collect::<Vec<_>>()
                    .into_iter()
                    .rev()
                    .collect::<Vec<_>>()
                    .join(".")
            } else {
                leaf
            });
            ranks.insert(module.clone(), f.down_shape[0]);
            names.push((
                format!("{prefix}.{module}.lora_A.weight"),
                f32_bytes(&f.down),
                f.down_shape.clone(),
            ));
            names.push((
                format!("{prefix}.{module}.lora_B.weight"),
                f32_bytes(&f.up),
                f.up_shape.clone(),
            ));
        }
        let Some(&r) = ranks.values().next() else {
            continue;
        };
        let rank_pattern: serde_json::Map<String, serde_json::Value> = ranks
            .iter()
            .filter(|(_, &v)| v != r)
            .map(|(k, v)| (k.clone(), serde_json::json!(v)))
            .collect();
        let entries = [
            ("r", serde_json::json!(r)),
            ("lora_alpha", serde_json::json!(export.alpha)),
            ("target_modules", serde_json::json!(targets)),
            ("rank_pattern", serde_json::Value::Object(rank_pattern)),
            ("alpha_pattern", serde_json::json!({})),
            ("bias", serde_json::json!("none")),
            ("use_rslora", serde_json::json!(false)),
            ("use_dora", serde_json::json!(false)),
            ("init_lora_weights", serde_json::json!(true)),
            ("lora_dropout", serde_json::json!(0.0)),
            ("fan_in_fan_out", serde_json::json!(false)),
            ("peft_type", serde_json::json!("LORA")),
        ];
        for (k, v) in entries {
            meta.insert(format!("{prefix}.{k}"), v);
        }
    }
    let views: Vec<(String, TensorView<'_>)> = names
        .iter()
        .map(|(name, bytes, shape)| {
            TensorView::new(Dtype::F32, shape.clone(), bytes)
                .map(|v| (name.clone(), v))
                .map_err(|e| LoraError::File {
                    path: path.to_path_buf(),
                    message: format!("tensor {name}: {e}"),
                })
        })
        .collect::<Result<_, _>>()?;
    let mut metadata = std::collections::HashMap::new();
    metadata.insert("format".to_string(), "pt".to_string());
    let meta_json =
        serde_json::to_string_pretty(&serde_json::Value::Object(meta)).map_err(|e| {
            LoraError::File {
                path: path.to_path_buf(),
                message: e.to_string(),
            }
        })?;
    metadata.insert("lora_adapter_metadata".to_string(), meta_json);
    let bytes = safetensors::serialize(views, Some(metadata)).map_err(|e| LoraError::File {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    gb_core::write_atomic(path, &bytes).map_err(|e| LoraError::File {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}
