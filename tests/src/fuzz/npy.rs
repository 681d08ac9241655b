//! The `.npy` readers of gb-nerf (poses, bounds, depth), gb-finetune (DIODE depth and
//! normals) and gb-eval (disparity maps).

use std::path::Path;

use proptest::prelude::*;
use proptest::test_runner::TestCaseError;

use super::mutate::{any_bytes, mutated, mutations, Mutation};
use super::{ensure, Harness};

/// Tokens for mutating an npy header.
const NPY_TOKENS: &[&str] = &[
    "descr",
    "shape",
    "fortran_order",
    "True",
    "False",
    "'<f4'",
    "'>f8'",
    "'<i8'",
    "'|b1'",
    "'<c8'",
    "'<U3'",
    "'|V0'",
    "[('a', '<f4')]",
    "(2, 3)",
    "(18446744073709551615, 2)",
    "(4294967296, 4294967296)",
    "(-1,)",
    "()",
];

/// A valid array to write: shape, values in C order, f64 (`double`) or f32 storage, C or
/// Fortran order, little- or big-endian.
#[derive(Debug, Clone)]
pub struct ValidNpy {
    shape: Vec<u64>,
    values: Vec<f32>,
    double: bool,
    big_endian: bool,
    fortran: bool,
}

/// An input of the npy readers.
#[derive(Debug, Clone)]
pub enum NpyCase {
    /// Arbitrary bytes.
    Raw(Vec<u8>),
    /// A hand-made header (any dict text, any declared length and version) and data bytes.
    Header {
        version: (u8, u8),
        declared_len: Option<u32>,
        dict: String,
        data: Vec<u8>,
    },
    /// A valid file, then `mutations` (none: it must read back exactly).
    Valid(ValidNpy, Vec<Mutation>),
}

fn shape_text(shape: &[u64]) -> String {
    match shape {
        [] => "()".into(),
        [d] => format!("({d},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(u64::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// The bytes of a version 1.0 `.npy` file with `dict` as its header.
fn npy_bytes(version: (u8, u8), declared_len: Option<u32>, dict: &str, data: &[u8]) -> Vec<u8> {
    let mut out = b"\x93NUMPY".to_vec();
    out.extend([version.0, version.1]);
    let wide = version.0 >= 2;
    let prefix = if wide { 12 } else { 10 };
    let mut text = dict.to_string();
    while !(prefix + text.len() + 1).is_multiple_of(64) {
        text.push(' ');
    }
    text.push('\n');
    let len = declared_len.unwrap_or(text.len() as u32);
    if wide {
        out.extend(len.to_le_bytes());
    } else {
        out.extend((len as u16).to_le_bytes());
    }
    out.extend(text.bytes());
    out.extend(data);
    out
}

impl ValidNpy {
    /// The file's bytes.
    fn bytes(&self) -> Vec<u8> {
        let descr = match (self.big_endian, self.double) {
            (false, false) => "<f4",
            (false, true) => "<f8",
            (true, false) => ">f4",
            (true, true) => ">f8",
        };
        let dict = format!(
            "{{'descr': '{descr}', 'fortran_order': {}, 'shape': {}, }}",
            if self.fortran { "True" } else { "False" },
            shape_text(&self.shape)
        );
        let order: Vec<f32> = if self.fortran {
            c_to_fortran(&self.shape, &self.values)
        } else {
            self.values.clone()
        };
        let mut data = Vec::new();
        for v in order {
            match (self.big_endian, self.double) {
                (false, false) => data.extend(v.to_le_bytes()),
                (false, true) => data.extend(f64::from(v).to_le_bytes()),
                (true, false) => data.extend(v.to_be_bytes()),
                (true, true) => data.extend(f64::from(v).to_be_bytes()),
            }
        }
        npy_bytes((1, 0), None, &dict, &data)
    }
}

/// Reorders C-order values of `shape` to Fortran order (first axis fastest).
fn c_to_fortran(shape: &[u64], c: &[f32]) -> Vec<f32> {
    let dims: Vec<usize> = shape.iter().map(|&d| d as usize).collect();
    let mut out = vec![0.0; c.len()];
    for (c_pos, v) in c.iter().enumerate() {
        let mut rem = c_pos;
        let mut idx = vec![0; dims.len()];
        for a in (0..dims.len()).rev() {
            idx[a] = rem % dims[a];
            rem /= dims[a];
        }
        let (mut f_pos, mut stride) = (0, 1);
        for (a, &d) in dims.iter().enumerate() {
            f_pos += idx[a] * stride;
            stride *= d;
        }
        out[f_pos] = *v;
    }
    out
}

fn valid_npy() -> impl Strategy<Value = ValidNpy> {
    (
        proptest::collection::vec(1u64..5, 0..4),
        any::<(bool, bool, bool)>(),
    )
        .prop_flat_map(|(shape, (double, big_endian, fortran))| {
            let n = shape.iter().product::<u64>() as usize;
            proptest::collection::vec(any::<f32>(), n).prop_map(move |values| ValidNpy {
                shape: shape.clone(),
                values,
                double,
                big_endian,
                fortran,
            })
        })
}

fn header_case() -> impl Strategy<Value = NpyCase> {
    let descr = proptest::sample::select(vec![
        "'<f4'",
        "'<f8'",
        "'>f4'",
        "'|f4'",
        "'<f2'",
        "'<f16'",
        "'<i4'",
        "'|u1'",
        "'|b1'",
        "'<c16'",
        "'|V0'",
        "'<f99999999999999999999'",
        "'zz'",
        "[('a', '<f4')]",
        "[('a', '<f4', (4294967296, 4294967296))]",
        "[]",
        "3",
    ]);
    let dim = prop_oneof![
        4 => (0u64..6).prop_map(|d| d.to_string()),
        1 => Just("4294967296".to_string()),
        1 => Just("18446744073709551615".to_string()),
        1 => Just("18446744073709551616".to_string()),
        1 => Just("-1".to_string()),
        1 => Just("2.5".to_string()),
        1 => Just("'x'".to_string()),
        1 => any::<u64>().prop_map(|d| d.to_string()),
    ];
    let shape = proptest::collection::vec(dim, 0..6);
    let fortran = proptest::sample::select(vec!["True", "False", "1", "None", "'x'"]);
    (
        (0u8..4, 0u8..2),
        proptest::option::weighted(0.2, any::<u32>()),
        descr,
        fortran,
        shape,
        any_bytes(256),
    )
        .prop_map(|(version, declared_len, descr, fortran, shape, data)| {
            let shape = match shape.len() {
                1 => format!("({},)", shape[0]),
                _ => format!("({})", shape.join(", ")),
            };
            NpyCase::Header {
                version,
                declared_len,
                dict: format!(
                    "{{'descr': {descr}, 'fortran_order': {fortran}, 'shape': {shape}, }}"
                ),
                data,
            }
        })
}

fn npy_case() -> impl Strategy<Value = NpyCase> {
    prop_oneof![
        1 => any_bytes(512).prop_map(NpyCase::Raw),
        3 => header_case(),
        2 => valid_npy().prop_map(|v| NpyCase::Valid(v, Vec::new())),
        4 => (valid_npy(), mutations(NPY_TOKENS)).prop_map(|(v, m)| NpyCase::Valid(v, m)),
    ]
}

impl NpyCase {
    fn bytes(&self) -> Vec<u8> {
        match self {
            NpyCase::Raw(b) => b.clone(),
            NpyCase::Header {
                version,
                declared_len,
                dict,
                data,
            } => npy_bytes(*version, *declared_len, dict, data),
            NpyCase::Valid(v, m) => mutated(&v.bytes(), m),
        }
    }

    /// The array a reader must return exactly (a valid, unmutated file).
    fn expected(&self) -> Option<&ValidNpy> {
        match self {
            NpyCase::Valid(v, m) if m.is_empty() => Some(v),
            _ => None,
        }
    }
}

fn same(a: f32, b: f32) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

fn write(dir: &Path, case: &NpyCase) -> std::path::PathBuf {
    let path = dir.join("fuzz.npy");
    std::fs::write(&path, case.bytes()).expect("cannot write the scratch file");
    path
}

/// gb-nerf: `read_float_array`.
pub fn nerf(h: &mut Harness) -> Result<(), String> {
    h.check(npy_case(), |case, dir| {
        let path = write(dir, &case);
        let got = gb_nerf::scene::npy::read_float_array(&path);
        if let Some(v) = case.expected() {
            let a = got.map_err(|e| TestCaseError::fail(format!("valid file rejected: {e}")))?;
            ensure(a.shape == v.shape, || format!("shape {:?}", a.shape))?;
            ensure(
                a.data.len() == v.values.len()
                    && a.data
                        .iter()
                        .zip(&v.values)
                        .all(|(x, y)| same(*x as f32, *y)),
                || format!("values {:?}", a.data),
            )?;
        } else if let Ok(a) = got {
            let n = a.shape.iter().try_fold(1u64, |p, &d| p.checked_mul(d));
            ensure(n == Some(a.data.len() as u64), || {
                format!("{} values for shape {:?}", a.data.len(), a.shape)
            })?;
        }
        Ok(())
    })
}

/// gb-finetune: `read_npy_f32`.
pub fn finetune(h: &mut Harness) -> Result<(), String> {
    h.check(npy_case(), |case, dir| {
        let path = write(dir, &case);
        let got = gb_finetune::diode::read_npy_f32(&path);
        if let Some(v) = case.expected() {
            let (shape, data) =
                got.map_err(|e| TestCaseError::fail(format!("valid file rejected: {e}")))?;
            ensure(shape == v.shape, || format!("shape {shape:?}"))?;
            ensure(
                data.len() == v.values.len()
                    && data.iter().zip(&v.values).all(|(x, y)| same(*x, *y)),
                || format!("values {data:?}"),
            )?;
        } else if let Ok((shape, data)) = got {
            let n = shape.iter().try_fold(1u64, |p, &d| p.checked_mul(d));
            ensure(n == Some(data.len() as u64), || {
                format!("{} values for shape {shape:?}", data.len())
            })?;
        }
        Ok(())
    })
}

/// gb-eval: `read_disparity` of a `.npy` file (`[h, w]` or `[h, w, 1]`).
pub fn eval(h: &mut Harness) -> Result<(), String> {
    use gb_eval::disparity::{read_disparity, DepthKind};
    h.check(npy_case(), |case, dir| {
        let path = write(dir, &case);
        let got = read_disparity(&path, DepthKind::Disparity);
        let _ = read_disparity(&path, DepthKind::Depth);
        if let Some(v) = case.expected() {
            let image = matches!(v.shape.as_slice(), [_, _] | [_, _, 1]);
            match got {
                Ok(m) => {
                    ensure(image, || format!("shape {:?} accepted", v.shape))?;
                    ensure(
                        (m.height as u64, m.width as u64) == (v.shape[0], v.shape[1]),
                        || format!("{}x{} for shape {:?}", m.width, m.height, v.shape),
                    )?;
                    ensure(
                        m.data.len() == v.values.len()
                            && m.data.iter().zip(&v.values).all(|(x, y)| same(*x, *y)),
                        || format!("values {:?}", m.data),
                    )?;
                }
                Err(e) => ensure(!image, || format!("valid map rejected: {e}"))?,
            }
        } else if let Ok(m) = got {
            ensure(m.data.len() == m.width * m.height, || {
                format!("{} values for {}x{}", m.data.len(), m.width, m.height)
            })?;
        }
        Ok(())
    })
}
