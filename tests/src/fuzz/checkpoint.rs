//! Checkpoint loading (`gb_diffusion::checkpoint::load_module`, burn's safetensors store
//! behind it) into a small `Linear` (PyTorch weight `[2, 3]`, bias `[2]`).

use std::collections::BTreeMap;

use burn::nn::{Linear, LinearConfig};
use gb_diffusion::checkpoint::{load_module, KeymapSection};
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;
use safetensors::Dtype;

use super::mutate::{mutated, mutations, Mutation};
use super::safetensors_files::{
    any_tensor, hand_made_file, serialize, tensor_of, write, TensorSpec, HEADER_TOKENS,
};
use super::{ensure, Harness};

/// No remapping: the file's keys are the module's (`weight`, `bias`).
const SECTION: KeymapSection = KeymapSection {
    name: "fuzz",
    rules: &[],
    ignored: &[],
    to_checkpoint: &[],
};

fn fresh() -> Linear {
    LinearConfig::new(3, 2).init(&gb_core::BackendKind::Flex.device())
}

#[derive(Debug, Clone)]
enum CkptCase {
    /// `weight` and `bias` in one float dtype, then `mutations` (none: exact round trip
    /// for f32 and f64).
    Valid(BTreeMap<String, TensorSpec>, Vec<Mutation>),
    /// Tensors with module-like names, any dtype and shape.
    Shuffled(BTreeMap<String, TensorSpec>),
    /// A hand-made header.
    Raw(Vec<u8>),
}

fn valid() -> impl Strategy<Value = BTreeMap<String, TensorSpec>> {
    proptest::sample::select(vec![Dtype::F32, Dtype::F64, Dtype::F16, Dtype::BF16])
        .prop_flat_map(|d| (tensor_of(d, vec![2, 3]), tensor_of(d, vec![2])))
        .prop_map(|(w, b)| BTreeMap::from([("weight".into(), w), ("bias".into(), b)]))
}

fn case() -> impl Strategy<Value = CkptCase> {
    let name = proptest::sample::select(vec!["weight", "bias", "w", "weight.x", "", "gamma"])
        .prop_map(String::from);
    prop_oneof![
        2 => valid().prop_map(|t| CkptCase::Valid(t, Vec::new())),
        3 => (valid(), mutations(HEADER_TOKENS)).prop_map(|(t, m)| CkptCase::Valid(t, m)),
        3 => proptest::collection::btree_map(name, any_tensor(), 0..4).prop_map(CkptCase::Shuffled),
        1 => hand_made_file().prop_map(CkptCase::Raw),
    ]
}

fn same(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()))
}

/// `load_module` never panics; a valid f32/f64 file loads exactly (weight transposed).
pub fn load(h: &mut Harness) -> Result<(), String> {
    h.check(case(), |case, dir| {
        let bytes = match &case {
            CkptCase::Valid(t, m) => mutated(&serialize(t, None), m),
            CkptCase::Shuffled(t) => serialize(t, None),
            CkptCase::Raw(b) => b.clone(),
        };
        let path = write(dir, "model.safetensors", &bytes);
        let got = load_module(fresh(), std::slice::from_ref(&path), &SECTION);
        let CkptCase::Valid(t, m) = &case else {
            return Ok(());
        };
        if !m.is_empty() {
            return Ok(());
        }
        let (module, _) =
            got.map_err(|e| TestCaseError::fail(format!("valid file rejected: {e}")))?;
        let (Some(w), Some(b)) = (t["weight"].f32_values(), t["bias"].f32_values()) else {
            return Ok(()); // f16 / bf16: loading is enough
        };
        let read = |v: burn::tensor::TensorData| v.try_to_vec::<f32>().unwrap_or_default();
        let got_w = read(module.weight.val().into_data());
        // Burn keeps `[in, out]`; the file holds PyTorch's `[out, in]`.
        let want_w: Vec<f32> = (0..3)
            .flat_map(|i| (0..2).map(move |o| (i, o)))
            .map(|(i, o)| w[o * 3 + i])
            .collect();
        ensure(same(&got_w, &want_w), || format!("weight {got_w:?}"))?;
        let bias = module.bias.as_ref().map(|p| read(p.val().into_data()));
        ensure(bias.as_deref().is_some_and(|g| same(g, &b)), || {
            format!("bias {bias:?}")
        })?;
        Ok(())
    })
}
