//! BRISQUE model files: OpenCV's YAML (`parse_opencv_yaml`, the SVM and range loaders on
//! top of it) and the libsvm text model with its svm-scale range file.

use std::path::Path;

use gb_eval::brisque::libsvm::{load_libsvm_model, load_svm_scale_range};
use gb_eval::brisque::opencv_yaml::parse_opencv_yaml;
use gb_eval::brisque::{FeatureRange, RbfSvr};
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;

use super::mutate::{any_bytes, mutated, mutations, Mutation};
use super::{ensure, Harness};

/// Tokens for mutating YAML and libsvm files.
const MODEL_TOKENS: &[&str] = &[
    "!!opencv-matrix",
    "!<tag:x>",
    "opencv_ml_svm",
    "svmType",
    "EPS_SVR",
    "kernel",
    "RBF",
    "gamma",
    "var_count",
    "support_vectors",
    "decision_functions",
    "rho",
    "alpha",
    "index",
    "rows",
    "cols",
    "data",
    "range",
    "%YAML:1.0",
    "---",
    "...",
    "- -",
    "- a: 1",
    "\"a\": 1",
    "{ a:1 }",
    "[ 1, [ 2, 3 ] ]",
    "SV",
    "svm_type",
    "kernel_type",
    "1:0.5",
    "37:1",
    "0:1",
    "x",
];

/// A small RBF regressor (`dim` features, support vectors stored as f32 like OpenCV).
#[derive(Debug, Clone)]
struct Model {
    gamma: f64,
    rho: f64,
    dim: usize,
    alphas: Vec<f64>,
    svs: Vec<Vec<f32>>,
    /// Which support vector each alpha uses (OpenCV's `index`), when written.
    index: Option<Vec<usize>>,
    min: Vec<f32>,
    max: Vec<f32>,
}

fn model() -> impl Strategy<Value = Model> {
    (1usize..6, 1usize..5).prop_flat_map(|(dim, n)| {
        (
            (-1e3f64..1e3, -1e3f64..1e3),
            proptest::collection::vec(-1e3f64..1e3, n),
            proptest::collection::vec(proptest::collection::vec(-1e3f32..1e3, dim), n),
            proptest::option::of(proptest::collection::vec(
                any::<proptest::sample::Index>(),
                n,
            )),
            proptest::collection::vec(-1e3f32..1e3, dim),
            proptest::collection::vec(-1e3f32..1e3, dim),
        )
            .prop_map(move |((gamma, rho), alphas, svs, index, min, max)| Model {
                gamma,
                rho,
                dim,
                alphas,
                svs,
                index: index.map(|idx| idx.iter().map(|i| i.index(n)).collect()),
                min,
                max,
            })
    })
}

fn list<T: std::fmt::Display>(v: &[T]) -> String {
    v.iter()
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// f32 values written as the f64 they widen to, so that any reader gets them exactly.
fn list_f32(v: &[f32]) -> String {
    list(&v.iter().map(|x| f64::from(*x)).collect::<Vec<_>>())
}

impl Model {
    fn opencv_model(&self) -> String {
        let mut s = format!(
            "%YAML:1.0\n---\nopencv_ml_svm:\n   format: 3\n   svmType: EPS_SVR\n   kernel:\n      type: RBF\n      gamma: {}\n   var_count: {}\n   sv_total: {}\n   support_vectors:\n",
            self.gamma,
            self.dim,
            self.svs.len()
        );
        for sv in &self.svs {
            s += &format!("      - [ {} ]\n", list_f32(sv));
        }
        s += &format!(
            "   decision_functions:\n      -\n         sv_count: {}\n         rho: {}\n         alpha: [ {} ]\n",
            self.alphas.len(),
            self.rho,
            list(&self.alphas)
        );
        if let Some(idx) = &self.index {
            s += &format!("         index: [ {} ]\n", list(idx));
        }
        s
    }

    fn opencv_range(&self) -> String {
        let data: Vec<f32> = self.min.iter().chain(&self.max).copied().collect();
        format!(
            "%YAML:1.0\n---\nrange: !!opencv-matrix\n   rows: 2\n   cols: {}\n   dt: f\n   data: [ {} ]\n",
            self.dim,
            list_f32(&data)
        )
    }

    /// The libsvm model: one support vector per alpha (sparse: zeros left out).
    fn libsvm_model(&self) -> String {
        let mut s = format!(
            "svm_type epsilon_svr\nkernel_type rbf\ngamma {}\nnr_class 2\ntotal_sv {}\nrho {}\nSV\n",
            self.gamma,
            self.alphas.len(),
            self.rho
        );
        for (a, sv) in self.alphas.iter().zip(self.expanded()) {
            let entries: Vec<String> = sv
                .iter()
                .enumerate()
                .filter(|(_, v)| **v != 0.0)
                .map(|(i, v)| format!("{}:{}", i + 1, f64::from(*v)))
                .collect();
            s += &format!("{a} {}\n", entries.join(" "));
        }
        s
    }

    fn libsvm_range(&self) -> String {
        let mut s = "x\n-1 1\n".to_string();
        for (i, (lo, hi)) in self.min.iter().zip(&self.max).enumerate() {
            s += &format!("{} {lo} {hi}\n", i + 1);
        }
        s
    }

    /// The support vector of each alpha, in alpha order.
    fn expanded(&self) -> Vec<Vec<f32>> {
        match &self.index {
            Some(idx) => idx.iter().map(|&i| self.svs[i].clone()).collect(),
            None => self.svs.clone(),
        }
    }

    fn check_svr(&self, svr: &RbfSvr) -> Result<(), TestCaseError> {
        let svs: Vec<f64> = self
            .expanded()
            .concat()
            .into_iter()
            .map(f64::from)
            .collect();
        ensure(
            svr.gamma == self.gamma
                && svr.rho == self.rho
                && svr.dim == self.dim
                && svr.coefs == self.alphas
                && svr.support_vectors == svs,
            || format!("read {svr:?}"),
        )
    }

    fn check_range(&self, r: &FeatureRange) -> Result<(), TestCaseError> {
        ensure(r.min == self.min && r.max == self.max, || {
            format!("read {r:?}")
        })
    }
}

#[derive(Debug, Clone)]
enum Case {
    /// A valid model and range, then mutations of the model and of the range file.
    Valid(Model, Vec<Mutation>, Vec<Mutation>),
    /// Arbitrary bytes for both files.
    Raw(Vec<u8>, Vec<u8>),
}

fn case(tokens: &'static [&'static str]) -> impl Strategy<Value = Case> {
    let maybe = || prop_oneof![1 => Just(Vec::new()), 1 => mutations(tokens)];
    prop_oneof![
        2 => model().prop_map(|m| Case::Valid(m, Vec::new(), Vec::new())),
        6 => (model(), maybe(), maybe()).prop_map(|(m, a, b)| Case::Valid(m, a, b)),
        1 => (any_bytes(256), any_bytes(256)).prop_map(|(a, b)| Case::Raw(a, b)),
    ]
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).expect("cannot write the scratch file");
    p
}

/// The OpenCV YAML reader and the SVM / range loaders: never panic; valid files read back.
pub fn opencv_yaml(h: &mut Harness) -> Result<(), String> {
    h.check(case(MODEL_TOKENS), |case, dir| {
        let (model, range) = match &case {
            Case::Valid(m, a, b) => (
                mutated(m.opencv_model().as_bytes(), a),
                mutated(m.opencv_range().as_bytes(), b),
            ),
            Case::Raw(a, b) => (a.clone(), b.clone()),
        };
        let text = String::from_utf8_lossy(&model);
        let _ = parse_opencv_yaml(&text, Path::new("model.yml"));
        let svr = RbfSvr::load_opencv_yaml(&write(dir, "model.yml", &model));
        let rng = FeatureRange::load_opencv_yaml(&write(dir, "range.yml", &range));
        if let Case::Valid(m, a, b) = &case {
            if a.is_empty() {
                m.check_svr(&svr.map_err(|e| TestCaseError::fail(e.to_string()))?)?;
            }
            if b.is_empty() {
                m.check_range(&rng.map_err(|e| TestCaseError::fail(e.to_string()))?)?;
            }
        }
        Ok(())
    })
}

/// The libsvm model and svm-scale range readers: never panic; valid files read back.
pub fn libsvm(h: &mut Harness) -> Result<(), String> {
    h.check(case(MODEL_TOKENS), |case, dir| {
        let (model, range, dim) = match &case {
            Case::Valid(m, a, b) => (
                mutated(m.libsvm_model().as_bytes(), a),
                mutated(m.libsvm_range().as_bytes(), b),
                m.dim,
            ),
            Case::Raw(a, b) => (a.clone(), b.clone(), 36),
        };
        let svr = load_libsvm_model(&write(dir, "model.txt", &model), dim);
        let rng = load_svm_scale_range(&write(dir, "range.txt", &range), dim);
        if let Case::Valid(m, a, b) = &case {
            if a.is_empty() {
                let mut want = m.clone();
                want.svs = m.expanded();
                want.index = None;
                let svr = svr.map_err(|e| TestCaseError::fail(e.to_string()))?;
                want.check_svr(&svr)?;
            }
            if b.is_empty() {
                m.check_range(&rng.map_err(|e| TestCaseError::fail(e.to_string()))?)?;
            }
        }
        Ok(())
    })
}
