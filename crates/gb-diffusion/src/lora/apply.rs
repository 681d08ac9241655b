//! Attaching the entries of a [`LoraFile`] to a module, and merging them.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use burn::module::{LoraAdapter, Module, Param, Reparameterizer};
use burn::store::ModuleSnapshot;
use burn::tensor::{Tensor, TensorData};

use super::conv_adapter::ConvLoraAdapter;
pub use super::file::LoraComponent;
use super::file::{LoraEntry, LoraFile};
use super::LoraError;
use crate::checkpoint::KeymapSection;

/// Factors of one target in Burn layout, with their scale.
struct Factors {
    first: TensorData,
    second: TensorData,
    scale: f64,
}

/// Attaches every `component` entry of `file` to `module` (whose base weights must already
/// be loaded). Diffusers keys are mapped to module paths through `section` (the same
/// table as the base checkpoint); kohya names are matched against the module's own paths.
/// Returns the module and the number of adapted weights.
pub fn apply_lora<M: Module>(
    module: M,
    file: &LoraFile,
    component: LoraComponent,
    section: &KeymapSection,
) -> Result<(M, usize), LoraError> {
    let params = param_shapes(&module);
    let adapted = adapted_paths(&params);
    let mut kohya_index: HashMap<String, String> = HashMap::new();
    for path in params.keys().filter(|p| p.ends_with(".weight")) {
        let original = section.unmap_key(path)?;
        let stem = original.strip_suffix(".weight").unwrap_or(&original);
        kohya_index.insert(stem.replace('.', "_"), path.clone());
    }
    let mut linear = HashMap::new();
    let mut conv = HashMap::new();
    for entry in file.entries_for(component) {
        let target = resolve_target(entry, section, &kohya_index, &params)?;
        if adapted.contains(&target) {
            return Err(LoraError::AlreadyAdapted { target });
        }
        let weight = params[&target].clone();
        let factors = burn_factors(entry, &target, &weight)?;
        if weight.len() == 2 {
            linear.insert(target, factors);
        } else {
            conv.insert(target, factors);
        }
    }
    let count = linear.len() + conv.len();
    let mut linear_loader = LinearLoader { targets: linear };
    let module = module.apply_reparameterization(&mut linear_loader);
    let mut conv_loader = ConvLoader { targets: conv };
    let module = module.apply_reparameterization(&mut conv_loader);
    debug_assert!(linear_loader.targets.is_empty() && conv_loader.targets.is_empty());
    tracing::info!(
        file = %file.path.display(),
        component = component.prefix(),
        adapted = count,
        "LoRA applied"
    );
    Ok((module, count))
}

/// Folds every LoRA adapter into its dense weight (`base + delta`) and drops the adapters.
pub fn merge_lora<M: Module>(module: M) -> M {
    module.materialize()
}

/// Every float parameter path of `module` with its Burn shape.
fn param_shapes<M: Module>(module: &M) -> BTreeMap<String, Vec<usize>> {
    module
        .collect(None, None, false)
        .into_iter()
        .map(|t| {
            let shape: Vec<usize> = t.shape.iter().copied().collect();
            (t.name, shape)
        })
        .collect()
}

/// Base weights that already carry an adapter (`x.weight.lora.a` marks `x.weight`).
fn adapted_paths(params: &BTreeMap<String, Vec<usize>>) -> BTreeSet<String> {
    params
        .keys()
        .filter_map(|p| {
            p.rsplit_once(".lora.")
                .or_else(|| p.rsplit_once(".conv_lora."))
                .map(|(base, _)| base.to_string())
        })
        .collect()
}

fn resolve_target(
    entry: &LoraEntry,
    section: &KeymapSection,
    kohya_index: &HashMap<String, String>,
    params: &BTreeMap<String, Vec<usize>>,
) -> Result<String, LoraError> {
    let unknown = |target: String| LoraError::UnknownTarget {
        target,
        key: entry.key.clone(),
        component: section.name.to_string(),
    };
    if entry.kohya {
        let prefixed = format!("text_model_{}", entry.module);
        return kohya_index
            .get(&entry.module)
            .or_else(|| match entry.component {
                LoraComponent::TextEncoder => kohya_index.get(&prefixed),
                LoraComponent::Unet => None,
            })
            .cloned()
            .ok_or_else(|| unknown(entry.module.clone()));
    }
    let target = section.map_key(&format!("{}.weight", entry.module))?;
    if params.contains_key(&target) {
        Ok(target)
    } else {
        Err(unknown(target))
    }
}

/// Transposes a row-major `[rows, cols]` matrix.
fn transpose(values: &[f32], rows: usize, cols: usize) -> Vec<f32> {
    let mut out = vec![0.0; values.len()];
    for r in 0..rows {
        for c in 0..cols {
            out[c * rows + r] = values[r * cols + c];
        }
    }
    out
}

/// The factors in the layout the adapter wants: linear `a: [in, r]`, `b: [r, out]`
/// (Burn's `[in, out]` weights); conv `up: [out, r]`, `down: [r, in*kh*kw]`.
fn burn_factors(entry: &LoraEntry, target: &str, weight: &[usize]) -> Result<Factors, LoraError> {
    let mismatch = || LoraError::ShapeMismatch {
        target: target.to_string(),
        key: entry.key.clone(),
        weight: weight.to_vec(),
        down: entry.down_shape.clone(),
        up: entry.up_shape.clone(),
    };
    let r = entry.rank();
    let down_cols: usize = entry.down_shape[1..].iter().product();
    let up_out = entry.up_shape[0];
    if entry.up_shape[2..].iter().any(|&d| d != 1) {
        return Err(mismatch());
    }
    if weight.len() == 2 {
        let (d_in, d_out) = (weight[0], weight[1]);
        if down_cols != d_in || up_out != d_out || entry.down_shape.len() != 2 {
            return Err(mismatch());
        }
        Ok(Factors {
            first: TensorData::new(transpose(&entry.down, r, d_in), [d_in, r]),
            second: TensorData::new(transpose(&entry.up, d_out, r), [r, d_out]),
            scale: entry.scale,
        })
    } else {
        let out = weight[0];
        let rest: usize = weight[1..].iter().product();
        if up_out != out || down_cols != rest {
            return Err(mismatch());
        }
        Ok(Factors {
            first: TensorData::new(entry.up.clone(), [out, r]),
            second: TensorData::new(entry.down.clone(), [r, rest]),
            scale: entry.scale,
        })
    }
}

/// Attaches burn's `LoraAdapter` with given factors to 2-D (linear) weights.
struct LinearLoader {
    targets: HashMap<String, Factors>,
}

impl Reparameterizer for &mut LinearLoader {
    type Reparam = LoraAdapter;

    fn reparameterize<const D: usize>(
        &mut self,
        path: &str,
        param: Param<Tensor<D>>,
    ) -> (Param<Tensor<D>>, Option<LoraAdapter>) {
        if D != 2 {
            return (param, None);
        }
        let Some(f) = self.targets.remove(path) else {
            return (param, None);
        };
        let device = param.lazy_device();
        let adapter = LoraAdapter {
            a: Param::from_tensor(Tensor::from_data(f.first, &device)),
            b: Param::from_tensor(Tensor::from_data(f.second, &device)),
            scale: f.scale,
        };
        (param.set_require_grad(false), Some(adapter))
    }
}

/// Attaches [`ConvLoraAdapter`] to convolution kernels.
struct ConvLoader {
    targets: HashMap<String, Factors>,
}

impl Reparameterizer for &mut ConvLoader {
    type Reparam = ConvLoraAdapter;

    fn reparameterize<const D: usize>(
        &mut self,
        path: &str,
        param: Param<Tensor<D>>,
    ) -> (Param<Tensor<D>>, Option<ConvLoraAdapter>) {
        if D < 3 {
            return (param, None);
        }
        let Some(f) = self.targets.remove(path) else {
            return (param, None);
        };
        let device = param.lazy_device();
        let adapter = ConvLoraAdapter {
            up: Param::from_tensor(Tensor::from_data(f.first, &device)),
            down: Param::from_tensor(Tensor::from_data(f.second, &device)),
            scale: f.scale,
        };
        (param.set_require_grad(false), Some(adapter))
    }
}
