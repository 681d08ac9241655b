//! Safetensors files: the shared generators (hand-made headers, valid files of any dtype)
//! and the plain tensor readers of gb-diffusion (`tensor_file`) and gb-eval (FID weights).

use std::collections::BTreeMap;
use std::path::Path;

use proptest::prelude::*;
use proptest::test_runner::TestCaseError;
use safetensors::tensor::TensorView;
use safetensors::Dtype;

use super::mutate::{any_bytes, any_short_string, mutated, mutations, Mutation};
use super::{ensure, Harness};

/// Tokens for mutating a safetensors header.
pub const HEADER_TOKENS: &[&str] = &[
    "dtype",
    "shape",
    "data_offsets",
    "__metadata__",
    "\"F32\"",
    "\"F16\"",
    "\"BF16\"",
    "\"F64\"",
    "\"I64\"",
    "\"F4\"",
    "\"F8_E4M3\"",
    "\"C64\"",
    "\"XX\"",
    "[0, 4294967296]",
    "[18446744073709551615]",
    "[4294967296, 4294967296]",
];

/// The dtypes of generated tensors.
const DTYPES: &[Dtype] = &[
    Dtype::F32,
    Dtype::F64,
    Dtype::F16,
    Dtype::BF16,
    Dtype::I64,
    Dtype::I32,
    Dtype::U8,
    Dtype::BOOL,
    Dtype::I8,
    Dtype::F8_E4M3,
    Dtype::C64,
];

/// One tensor of a valid file: dtype, shape and raw little-endian bytes.
#[derive(Debug, Clone)]
pub struct TensorSpec {
    /// The dtype.
    pub dtype: Dtype,
    /// The shape.
    pub shape: Vec<usize>,
    /// `numel * size` bytes.
    pub data: Vec<u8>,
}

impl TensorSpec {
    /// The values as f32, for F32 and F64 tensors.
    pub fn f32_values(&self) -> Option<Vec<f32>> {
        match self.dtype {
            Dtype::F32 => Some(
                self.data
                    .chunks_exact(4)
                    .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
                    .collect(),
            ),
            Dtype::F64 => Some(
                self.data
                    .chunks_exact(8)
                    .map(|c| f64::from_le_bytes(c.try_into().unwrap()) as f32)
                    .collect(),
            ),
            _ => None,
        }
    }

    /// The values as i64, for I64 and I32 tensors.
    pub fn i64_values(&self) -> Option<Vec<i64>> {
        match self.dtype {
            Dtype::I64 => Some(
                self.data
                    .chunks_exact(8)
                    .map(|c| i64::from_le_bytes(c.try_into().unwrap()))
                    .collect(),
            ),
            Dtype::I32 => Some(
                self.data
                    .chunks_exact(4)
                    .map(|c| i32::from_le_bytes(c.try_into().unwrap()) as i64)
                    .collect(),
            ),
            _ => None,
        }
    }

    /// Elements.
    pub fn numel(&self) -> usize {
        self.shape.iter().product()
    }
}

/// A tensor of `dtype` and `shape` with arbitrary bytes.
pub fn tensor_of(dtype: Dtype, shape: Vec<usize>) -> impl Strategy<Value = TensorSpec> {
    let n = shape.iter().product::<usize>() * dtype.bitsize() / 8;
    any_bytes(n + 1).prop_map(move |mut data| {
        data.resize(n, 0);
        TensorSpec {
            dtype,
            shape: shape.clone(),
            data,
        }
    })
}

/// A tensor of any generated dtype and a small shape (zero-sized dimensions included).
pub fn any_tensor() -> impl Strategy<Value = TensorSpec> {
    (
        proptest::sample::select(DTYPES),
        proptest::collection::vec(0usize..4, 0..4),
    )
        .prop_flat_map(|(d, s)| tensor_of(d, s))
}

/// Serialises named tensors (and optional metadata) with the `safetensors` crate.
pub fn serialize(
    tensors: &BTreeMap<String, TensorSpec>,
    metadata: Option<std::collections::HashMap<String, String>>,
) -> Vec<u8> {
    let views: Vec<(String, TensorView<'_>)> = tensors
        .iter()
        .map(|(n, t)| {
            let view = TensorView::new(t.dtype, t.shape.clone(), &t.data).expect("valid view");
            (n.clone(), view)
        })
        .collect();
    safetensors::serialize(views, metadata).expect("serialisable tensors")
}

/// A hand-made header: `{name: {dtype, shape, data_offsets}}` with arbitrary values, the
/// declared header length (sometimes wrong or huge) and data bytes.
pub fn hand_made_file() -> impl Strategy<Value = Vec<u8>> {
    let dim = prop_oneof![
        4 => (0u64..5).prop_map(|d| d.to_string()),
        1 => Just("4294967296".to_string()),
        1 => Just("18446744073709551615".to_string()),
        1 => Just("-1".to_string()),
        1 => Just("1.5".to_string()),
        1 => any::<u64>().prop_map(|d| d.to_string()),
    ];
    let entry = (
        prop_oneof![Just("w".to_string()), any_short_string()],
        proptest::sample::select(vec![
            "F32", "F16", "BF16", "F64", "I64", "I32", "U8", "BOOL", "F4", "F6_E2M3", "F8_E5M2",
            "C64", "U64", "XX", "",
        ]),
        proptest::collection::vec(dim, 0..5),
        (0u64..64, 0u64..64),
        proptest::option::weighted(0.1, (any::<u64>(), any::<u64>())),
    )
        .prop_map(|(name, dtype, shape, (a, b), huge)| {
            let (a, b) = huge.unwrap_or((a, b));
            format!(
                "{}: {{\"dtype\": \"{dtype}\", \"shape\": [{}], \"data_offsets\": [{a}, {b}]}}",
                serde_json::to_string(&name).expect("string"),
                shape.join(", ")
            )
        });
    (
        proptest::collection::vec(entry, 0..4),
        proptest::option::weighted(0.3, any_short_string()),
        proptest::option::weighted(0.2, any::<u64>()),
        any_bytes(128),
    )
        .prop_map(|(entries, meta, declared, data)| {
            let mut parts = entries;
            if let Some(m) = meta {
                parts.push(format!(
                    "\"__metadata__\": {{\"k\": {}}}",
                    serde_json::to_string(&m).expect("string")
                ));
            }
            let header = format!("{{{}}}", parts.join(", "));
            let n = declared.unwrap_or(header.len() as u64);
            let mut out = n.to_le_bytes().to_vec();
            out.extend(header.bytes());
            out.extend(data);
            out
        })
}

/// An input of a safetensors reader.
#[derive(Debug, Clone)]
pub enum StCase {
    /// Arbitrary bytes, or a hand-made header.
    Raw(Vec<u8>),
    /// A valid file, then `mutations` (none: it must read back exactly).
    Valid(BTreeMap<String, TensorSpec>, Vec<Mutation>),
}

impl StCase {
    /// The file's bytes.
    pub fn bytes(&self) -> Vec<u8> {
        match self {
            StCase::Raw(b) => b.clone(),
            StCase::Valid(t, m) => mutated(&serialize(t, None), m),
        }
    }

    /// The tensors a reader must return exactly.
    pub fn expected(&self) -> Option<&BTreeMap<String, TensorSpec>> {
        match self {
            StCase::Valid(t, m) if m.is_empty() => Some(t),
            _ => None,
        }
    }
}

fn named_tensors() -> impl Strategy<Value = BTreeMap<String, TensorSpec>> {
    proptest::collection::btree_map(
        prop_oneof![
            proptest::sample::select(vec!["a", "b.weight", "ids", ""]).prop_map(String::from),
            any_short_string()
        ],
        any_tensor(),
        0..4,
    )
}

fn st_case() -> impl Strategy<Value = StCase> {
    prop_oneof![
        1 => any_bytes(256).prop_map(StCase::Raw),
        3 => hand_made_file().prop_map(StCase::Raw),
        2 => named_tensors().prop_map(|t| StCase::Valid(t, Vec::new())),
        4 => (named_tensors(), mutations(HEADER_TOKENS)).prop_map(|(t, m)| StCase::Valid(t, m)),
    ]
}

/// Writes `bytes` to `dir/name`.
pub fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("cannot write the scratch file");
    path
}

fn same(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()))
}

/// gb-diffusion `tensor_file::read_f32` / `read_i64` on every tensor name.
pub fn tensor_file(h: &mut Harness) -> Result<(), String> {
    use gb_diffusion::tensor_file::{read_f32, read_i64};
    h.check(st_case(), |case, dir| {
        let path = write(dir, "fuzz.safetensors", &case.bytes());
        let Some(expected) = case.expected() else {
            for name in ["a", "b.weight", "ids", "w", ""] {
                let _ = read_f32(&path, name);
                let _ = read_i64(&path, name);
            }
            return Ok(());
        };
        for (name, t) in expected {
            let f = read_f32(&path, name);
            let i = read_i64(&path, name);
            match (t.f32_values(), &f) {
                (Some(v), Ok((got, shape))) => ensure(same(got, &v) && *shape == t.shape, || {
                    format!("{name}: read {got:?} {shape:?}")
                })?,
                (Some(_), Err(e)) => return Err(TestCaseError::fail(format!("{name}: {e}"))),
                (None, Ok((got, _))) => ensure(
                    matches!(t.dtype, Dtype::F16 | Dtype::BF16) && got.len() == t.numel(),
                    || format!("{name}: {:?} read as {} floats", t.dtype, got.len()),
                )?,
                (None, Err(_)) => {}
            }
            match (t.i64_values(), i) {
                (Some(v), Ok((got, _))) => ensure(got == v, || format!("{name}: {got:?}"))?,
                (Some(_), Err(e)) => return Err(TestCaseError::fail(format!("{name}: {e}"))),
                (None, Ok(_)) => return Err(TestCaseError::fail(format!("{name}: not integer"))),
                (None, Err(_)) => {}
            }
        }
        Ok(())
    })
}

/// gb-eval `F32Tensors::parse`, then `get_any` of every tensor.
pub fn fid(h: &mut Harness) -> Result<(), String> {
    use gb_eval::fid::safetensors_f32::F32Tensors;
    h.check(st_case(), |case, _| {
        let bytes = case.bytes();
        let parsed = F32Tensors::parse(&bytes, Path::new("fuzz.safetensors"));
        let Some(expected) = case.expected() else {
            if let Ok(t) = parsed {
                let names: Vec<String> = t.names().map(str::to_string).collect();
                for n in names {
                    let _ = t.get_any(&n);
                    let _ = t.get(&n, &[2, 2]);
                }
            }
            return Ok(());
        };
        let t = parsed.map_err(|e| TestCaseError::fail(format!("valid file rejected: {e}")))?;
        for (name, spec) in expected {
            match (spec.dtype, t.get_any(name)) {
                (Dtype::F32, Ok((shape, got))) => ensure(
                    shape == spec.shape && same(&got, &spec.f32_values().unwrap_or_default()),
                    || format!("{name}: {got:?}"),
                )?,
                (Dtype::F32, Err(e)) => return Err(TestCaseError::fail(format!("{name}: {e}"))),
                (other, Ok(_)) => {
                    return Err(TestCaseError::fail(format!(
                        "{name}: {other:?} read as F32"
                    )))
                }
                (_, Err(_)) => {}
            }
        }
        Ok(())
    })
}
