//! LoRA files: valid diffusers/PEFT and kohya files read back with the right factors and
//! scale, byte mutations of them, and files whose keys, shapes and adapter metadata are
//! arbitrary (the key parser).

use std::collections::{BTreeMap, HashMap};

use gb_diffusion::lora::{LoraComponent, LoraFile};
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;
use safetensors::Dtype;

use super::mutate::{any_short_string, mutated, mutations, Mutation};
use super::safetensors_files::{serialize, tensor_of, write, TensorSpec, HEADER_TOKENS};
use super::{ensure, Harness};

/// How the keys of one module are written.
#[derive(Debug, Clone, Copy)]
enum KeyStyle {
    Peft,
    LoraDot,
    LinearLayer,
    Processor,
    Kohya,
}

/// One low-rank pair of a valid file.
#[derive(Debug, Clone)]
struct Pair {
    style: KeyStyle,
    unet: bool,
    rank: usize,
    down: TensorSpec,
    up: TensorSpec,
    /// kohya `.alpha`.
    alpha: Option<f32>,
}

/// A valid LoRA file: pairs on modules `m0`, `m1`, ..., and PEFT metadata
/// (`lora_alpha`, `use_rslora`) for both components.
#[derive(Debug, Clone)]
struct ValidLora {
    pairs: Vec<Pair>,
    peft_alpha: Option<f32>,
    rslora: bool,
}

fn pair() -> impl Strategy<Value = Pair> {
    (
        proptest::sample::select(vec![
            KeyStyle::Peft,
            KeyStyle::LoraDot,
            KeyStyle::LinearLayer,
            KeyStyle::Processor,
            KeyStyle::Kohya,
        ]),
        any::<bool>(),
        prop_oneof![9 => 1usize..4, 1 => Just(0)],
        1usize..4,
        1usize..4,
        proptest::option::of(prop_oneof![
            9 => 0.5f32..64.0,
            1 => proptest::sample::select(vec![f32::NAN, f32::INFINITY, f32::NEG_INFINITY]),
        ]),
    )
        .prop_flat_map(|(style, unet, rank, d_in, d_out, alpha)| {
            (
                tensor_of(Dtype::F32, vec![rank, d_in]),
                tensor_of(Dtype::F32, vec![d_out, rank]),
            )
                .prop_map(move |(down, up)| Pair {
                    style,
                    unet,
                    rank,
                    down,
                    up,
                    alpha: alpha.filter(|_| matches!(style, KeyStyle::Kohya)),
                })
        })
}

fn valid_lora() -> impl Strategy<Value = ValidLora> {
    (
        proptest::collection::vec(pair(), 1..4),
        proptest::option::of(0.5f32..64.0),
        any::<bool>(),
    )
        .prop_map(|(pairs, peft_alpha, rslora)| ValidLora {
            pairs,
            peft_alpha,
            rslora,
        })
}

impl Pair {
    /// `(down key, up key, module name as read)`.
    fn keys(&self, i: usize) -> (String, String, String) {
        let p = if self.unet { "unet." } else { "text_encoder." };
        let m = format!("m{i}");
        match self.style {
            KeyStyle::Peft => (
                format!("{p}{m}.lora_A.weight"),
                format!("{p}{m}.lora_B.weight"),
                m,
            ),
            KeyStyle::LoraDot => (
                format!("{p}{m}.lora.down.weight"),
                format!("{p}{m}.lora.up.weight"),
                m,
            ),
            KeyStyle::LinearLayer => (
                format!("{p}{m}.lora_linear_layer.down.weight"),
                format!("{p}{m}.lora_linear_layer.up.weight"),
                m,
            ),
            KeyStyle::Processor => (
                format!("{p}{m}.processor.to_k_lora.down.weight"),
                format!("{p}{m}.processor.to_k_lora.up.weight"),
                format!("{m}.{}", if self.unet { "to_k" } else { "k_proj" }),
            ),
            KeyStyle::Kohya => {
                let k = if self.unet { "lora_unet_" } else { "lora_te_" };
                (
                    format!("{k}{m}.lora_down.weight"),
                    format!("{k}{m}.lora_up.weight"),
                    m,
                )
            }
        }
    }

    fn component(&self) -> LoraComponent {
        if self.unet {
            LoraComponent::Unet
        } else {
            LoraComponent::TextEncoder
        }
    }
}

/// `(component, module, kohya, down, up, scale)` of one pair as the reader must give it.
type ExpectedPair = (LoraComponent, String, bool, Vec<f32>, Vec<f32>, f64);

impl ValidLora {
    /// Whether the reader must reject the file: a rank-0 pair or a non-finite kohya alpha.
    fn invalid(&self) -> bool {
        self.pairs
            .iter()
            .any(|p| p.rank == 0 || p.alpha.is_some_and(|a| !a.is_finite()))
    }

    fn bytes(&self) -> Vec<u8> {
        let mut tensors = BTreeMap::new();
        for (i, p) in self.pairs.iter().enumerate() {
            let (down, up, _) = p.keys(i);
            tensors.insert(down.clone(), p.down.clone());
            tensors.insert(up, p.up.clone());
            if let Some(a) = p.alpha {
                let stem = down.trim_end_matches(".lora_down.weight");
                let alpha = TensorSpec {
                    dtype: Dtype::F32,
                    shape: vec![],
                    data: a.to_le_bytes().to_vec(),
                };
                tensors.insert(format!("{stem}.alpha"), alpha);
            }
        }
        let meta = self.peft_alpha.map(|a| {
            let mut m = serde_json::Map::new();
            for c in ["unet.", "text_encoder."] {
                m.insert(format!("{c}r"), 4.into());
                m.insert(format!("{c}lora_alpha"), f64::from(a).into());
                m.insert(format!("{c}use_rslora"), self.rslora.into());
            }
            HashMap::from([(
                "lora_adapter_metadata".to_string(),
                serde_json::Value::Object(m).to_string(),
            )])
        });
        serialize(&tensors, meta)
    }

    /// `(component, module, kohya, down, up, scale)` of each pair as the reader must give it.
    fn expected(&self) -> Vec<ExpectedPair> {
        self.pairs
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let kohya = matches!(p.style, KeyStyle::Kohya);
                let r = p.rank as f64;
                let alpha = p.alpha.or(self.peft_alpha).map(f64::from).unwrap_or(r);
                let scale = if self.rslora && self.peft_alpha.is_some() {
                    alpha / r.sqrt()
                } else {
                    alpha / r
                };
                let f = |t: &TensorSpec| t.f32_values().unwrap_or_default();
                (
                    p.component(),
                    p.keys(i).2,
                    kohya,
                    f(&p.down),
                    f(&p.up),
                    scale,
                )
            })
            .collect()
    }
}

/// Checks what every successful read must satisfy: ranks >= 1, factor lengths that match
/// their shapes, finite scales.
fn check_entries(file: &LoraFile) -> Result<(), TestCaseError> {
    for e in &file.entries {
        ensure(e.down_shape.len() >= 2 && e.up_shape.len() >= 2, || {
            format!(
                "{}: factor shapes {:?} {:?}",
                e.key, e.down_shape, e.up_shape
            )
        })?;
        ensure(e.rank() >= 1, || format!("{}: rank 0 accepted", e.key))?;
        ensure(
            e.down.len() == e.down_shape.iter().product::<usize>()
                && e.up.len() == e.up_shape.iter().product::<usize>(),
            || format!("{}: factor lengths do not match the shapes", e.key),
        )?;
        ensure(e.scale.is_finite(), || {
            format!("{}: scale {} accepted", e.key, e.scale)
        })?;
    }
    Ok(())
}

#[derive(Debug, Clone)]
enum LoraCase {
    Valid(ValidLora, Vec<Mutation>),
    Raw(Vec<u8>),
}

/// `LoraFile::read` on valid files (exact factors and scale) and their byte mutations.
pub fn file(h: &mut Harness) -> Result<(), String> {
    let case = prop_oneof![
        2 => valid_lora().prop_map(|v| LoraCase::Valid(v, Vec::new())),
        3 => (valid_lora(), mutations(HEADER_TOKENS)).prop_map(|(v, m)| LoraCase::Valid(v, m)),
        1 => super::safetensors_files::hand_made_file().prop_map(LoraCase::Raw),
    ];
    h.check(case, |case, dir| {
        let bytes = match &case {
            LoraCase::Valid(v, m) => mutated(&v.bytes(), m),
            LoraCase::Raw(b) => b.clone(),
        };
        let path = write(dir, "lora.safetensors", &bytes);
        let got = LoraFile::read(&path);
        let expected = match &case {
            LoraCase::Valid(v, m) if m.is_empty() && v.invalid() => {
                return ensure(got.is_err(), || {
                    "rank 0 or non-finite alpha accepted".into()
                });
            }
            LoraCase::Valid(v, m) if m.is_empty() => v.expected(),
            _ => {
                if let Ok(f) = &got {
                    check_entries(f)?;
                }
                return Ok(());
            }
        };
        let f = got.map_err(|e| TestCaseError::fail(format!("valid file rejected: {e}")))?;
        check_entries(&f)?;
        ensure(f.entries.len() == expected.len(), || {
            format!("{} entries", f.entries.len())
        })?;
        for (component, module, kohya, down, up, scale) in expected {
            let e = f
                .entries
                .iter()
                .find(|e| e.component == component && e.module == module && e.kohya == kohya)
                .ok_or_else(|| TestCaseError::fail(format!("no entry {module}")))?;
            ensure(
                bits(&e.down) == bits(&down) && bits(&e.up) == bits(&up),
                || format!("{module}: factors differ"),
            )?;
            ensure((e.scale - scale).abs() <= 1e-9 * scale.abs(), || {
                format!("{module}: scale {} != {scale}", e.scale)
            })?;
        }
        Ok(())
    })
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// A key made of LoRA-ish segments or arbitrary text.
fn key() -> impl Strategy<Value = String> {
    let segment = proptest::sample::select(vec![
        "unet",
        "text_encoder",
        "lora_unet_",
        "lora_te_",
        "lora_te1_",
        "m",
        "processor",
        "to_q_lora",
        "to_out_lora",
        "lora_A",
        "lora_B",
        "lora",
        "lora_down",
        "lora_up",
        "lora_linear_layer",
        "down",
        "up",
        "weight",
        "alpha",
        "",
        ".",
    ]);
    prop_oneof![
        4 => proptest::collection::vec(segment, 1..7).prop_map(|s| s.join(".")),
        1 => any_short_string(),
    ]
}

/// Arbitrary adapter metadata: JSON-ish text with the PEFT keys and odd values.
fn metadata() -> impl Strategy<Value = Option<String>> {
    let value = proptest::sample::select(vec![
        "4",
        "0",
        "-1",
        "1e308",
        "\"x\"",
        "true",
        "null",
        "[]",
        "{\"m\": 2}",
        "{\"m\": \"x\"}",
        "1e999",
        "[[[[[[[[",
    ]);
    let entry = (
        proptest::sample::select(vec![
            "unet.r",
            "unet.lora_alpha",
            "unet.use_rslora",
            "unet.alpha_pattern",
            "text_encoder.lora_alpha",
            "text_encoder.use_rslora",
            "x",
        ]),
        value,
    )
        .prop_map(|(k, v)| format!("\"{k}\": {v}"));
    proptest::option::of(prop_oneof![
        4 => proptest::collection::vec(entry, 0..5).prop_map(|e| format!("{{{}}}", e.join(", "))),
        1 => any_short_string(),
    ])
}

/// `LoraFile::read` on files whose keys, dtypes, shapes and metadata are arbitrary.
pub fn keys(h: &mut Harness) -> Result<(), String> {
    let tensors =
        proptest::collection::btree_map(key(), super::safetensors_files::any_tensor(), 0..6);
    h.check((tensors, metadata()), |(tensors, meta), dir| {
        let meta = meta.map(|m| HashMap::from([("lora_adapter_metadata".to_string(), m)]));
        let path = write(dir, "keys.safetensors", &serialize(&tensors, meta));
        if let Ok(f) = LoraFile::read(&path) {
            check_entries(&f)?;
        }
        Ok(())
    })
}
