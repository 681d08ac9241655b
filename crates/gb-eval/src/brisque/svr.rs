//! The epsilon-SVR with an RBF kernel that scores BRISQUE features, and the per-feature
//! range scaling to [-1, 1] that precedes it. Loaded from OpenCV's `cv::ml::SVM` YAML or
//! from a libsvm text model (see [`super::libsvm`]).

use std::path::Path;

use super::error::BrisqueError;
use super::opencv_yaml::{parse_opencv_yaml, YamlValue};

/// Arithmetic used for the kernel sum, to reproduce the implementation a model came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KernelPrecision {
    /// OpenCV `cv::ml::SVM`: squared distances in f64 of f32 differences, the scaled
    /// exponent rounded to f32, `exp` in f32, the weighted sum in f64, the result in f32.
    OpenCv,
    /// libsvm: everything in f64.
    F64,
}

/// A trained RBF-kernel support-vector regressor: `sum_i coef_i exp(-gamma |x - sv_i|^2) - rho`.
#[derive(Debug, Clone)]
pub struct RbfSvr {
    /// Kernel width.
    pub gamma: f64,
    /// Bias subtracted from the kernel sum.
    pub rho: f64,
    /// One coefficient (alpha) per support vector.
    pub coefs: Vec<f64>,
    /// Support vectors, row-major `coefs.len() x dim`.
    pub support_vectors: Vec<f64>,
    /// Feature count.
    pub dim: usize,
    /// How [`RbfSvr::predict`] rounds.
    pub precision: KernelPrecision,
}

impl RbfSvr {
    /// The regression output for one (already scaled) feature vector of length `dim`.
    pub fn predict(&self, x: &[f32]) -> f64 {
        let mut sum = -self.rho;
        for (coef, sv) in self
            .coefs
            .iter()
            .zip(self.support_vectors.chunks_exact(self.dim))
        {
            let k = match self.precision {
                KernelPrecision::OpenCv => opencv_rbf(sv, x, self.gamma),
                KernelPrecision::F64 => {
                    let d2: f64 = sv.iter().zip(x).map(|(s, v)| (s - *v as f64).powi(2)).sum();
                    (-self.gamma * d2).exp()
                }
            };
            sum += coef * k;
        }
        match self.precision {
            KernelPrecision::OpenCv => sum as f32 as f64,
            KernelPrecision::F64 => sum,
        }
    }

    /// Loads an `opencv_ml_svm` node (EPS_SVR or NU_SVR, RBF kernel) from a YAML file.
    pub fn load_opencv_yaml(path: &Path) -> Result<Self, BrisqueError> {
        let text = std::fs::read_to_string(path).map_err(|source| BrisqueError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let doc = parse_opencv_yaml(&text, path)?;
        let field_err = |field: &str, message: &str| BrisqueError::Field {
            path: path.to_path_buf(),
            field: field.to_string(),
            message: message.to_string(),
        };
        let svm = doc
            .get("opencv_ml_svm")
            .ok_or_else(|| field_err("opencv_ml_svm", "missing (not an OpenCV SVM file)"))?;
        let svm_type = svm.get("svmType").and_then(YamlValue::as_str).unwrap_or("");
        if svm_type != "EPS_SVR" && svm_type != "NU_SVR" {
            return Err(field_err(
                "opencv_ml_svm.svmType",
                &format!("'{svm_type}' is not a regression (EPS_SVR or NU_SVR)"),
            ));
        }
        let kernel = svm
            .get("kernel")
            .ok_or_else(|| field_err("opencv_ml_svm.kernel", "missing"))?;
        let kernel_type = kernel.get("type").and_then(YamlValue::as_str).unwrap_or("");
        if kernel_type != "RBF" {
            return Err(field_err(
                "opencv_ml_svm.kernel.type",
                &format!("'{kernel_type}' is not RBF"),
            ));
        }
        let gamma = kernel
            .get("gamma")
            .and_then(YamlValue::as_f64)
            .ok_or_else(|| field_err("opencv_ml_svm.kernel.gamma", "missing or not a number"))?;
        let dim = svm
            .get("var_count")
            .and_then(YamlValue::as_f64)
            .ok_or_else(|| field_err("opencv_ml_svm.var_count", "missing or not a number"))?
            as usize;
        let YamlValue::Seq(rows) = svm
            .get("support_vectors")
            .ok_or_else(|| field_err("opencv_ml_svm.support_vectors", "missing"))?
        else {
            return Err(field_err("opencv_ml_svm.support_vectors", "not a sequence"));
        };
        // No capacity from `var_count`: it is the file's word, the rows are what it holds.
        let mut support_vectors = Vec::new();
        for (i, row) in rows.iter().enumerate() {
            let values = row.as_f64_vec().ok_or_else(|| {
                field_err(
                    &format!("opencv_ml_svm.support_vectors[{i}]"),
                    "not a list of numbers",
                )
            })?;
            if values.len() != dim {
                return Err(field_err(
                    &format!("opencv_ml_svm.support_vectors[{i}]"),
                    &format!("has {} values, var_count is {dim}", values.len()),
                ));
            }
            // OpenCV keeps support vectors in f32.
            support_vectors.extend(values.iter().map(|v| *v as f32 as f64));
        }
        let df = match svm.get("decision_functions") {
            Some(YamlValue::Seq(items)) if !items.is_empty() => &items[0],
            _ => {
                return Err(field_err(
                    "opencv_ml_svm.decision_functions",
                    "missing or empty",
                ))
            }
        };
        let rho = df.get("rho").and_then(YamlValue::as_f64).ok_or_else(|| {
            field_err(
                "opencv_ml_svm.decision_functions[0].rho",
                "missing or not a number",
            )
        })?;
        let alpha = df
            .get("alpha")
            .and_then(YamlValue::as_f64_vec)
            .ok_or_else(|| {
                field_err(
                    "opencv_ml_svm.decision_functions[0].alpha",
                    "missing or not a list of numbers",
                )
            })?;
        let n_sv = rows.len();
        // `index` maps each alpha to a support vector; without it alpha k belongs to vector k.
        let index: Vec<usize> = match df.get("index").and_then(YamlValue::as_f64_vec) {
            Some(idx) => idx.iter().map(|v| *v as usize).collect(),
            None => (0..alpha.len()).collect(),
        };
        // More alphas than support vectors would copy vectors (`alpha.len() * dim` values
        // from a small file); OpenCV writes at most one alpha per support vector.
        if index.len() != alpha.len() || alpha.len() > n_sv || index.iter().any(|i| *i >= n_sv) {
            return Err(field_err(
                "opencv_ml_svm.decision_functions[0].index",
                &format!(
                    "{} alphas, {} indices, {n_sv} support vectors",
                    alpha.len(),
                    index.len()
                ),
            ));
        }
        let mut svs = Vec::with_capacity(alpha.len() * dim);
        for i in &index {
            svs.extend_from_slice(&support_vectors[i * dim..(i + 1) * dim]);
        }
        Ok(Self {
            gamma,
            rho,
            coefs: alpha,
            support_vectors: svs,
            dim,
            precision: KernelPrecision::OpenCv,
        })
    }
}

/// OpenCV's `calc_rbf` followed by its f32 `exp`.
fn opencv_rbf(sv: &[f64], x: &[f32], gamma: f64) -> f64 {
    let diff = |k: usize| ((sv[k] as f32) - x[k]) as f64;
    let n = x.len();
    let mut s = 0.0f64;
    let mut k = 0;
    while k + 4 <= n {
        let (t0, t1) = (diff(k), diff(k + 1));
        s += t0 * t0 + t1 * t1;
        let (t2, t3) = (diff(k + 2), diff(k + 3));
        s += t2 * t2 + t3 * t3;
        k += 4;
    }
    while k < n {
        let t = diff(k);
        s += t * t;
        k += 1;
    }
    let e = (s * -gamma) as f32;
    e.exp() as f64
}

/// Linear scaling of each feature from its observed [min, max] to [lower, upper].
#[derive(Debug, Clone)]
pub struct FeatureRange {
    /// Per-feature minimum.
    pub min: Vec<f32>,
    /// Per-feature maximum.
    pub max: Vec<f32>,
    /// Target lower bound (-1 for BRISQUE).
    pub lower: f32,
    /// Target upper bound (1 for BRISQUE).
    pub upper: f32,
}

impl FeatureRange {
    /// Reads OpenCV's range file: a 2 x N `!!opencv-matrix` named `range` (row 0 min, row 1 max).
    pub fn load_opencv_yaml(path: &Path) -> Result<Self, BrisqueError> {
        let text = std::fs::read_to_string(path).map_err(|source| BrisqueError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let doc = parse_opencv_yaml(&text, path)?;
        let (rows, cols, data) = doc
            .get("range")
            .and_then(YamlValue::opencv_matrix)
            .ok_or_else(|| BrisqueError::Field {
                path: path.to_path_buf(),
                field: "range".into(),
                message: "missing or not an opencv-matrix with rows*cols data".into(),
            })?;
        if rows != 2 {
            return Err(BrisqueError::Field {
                path: path.to_path_buf(),
                field: "range".into(),
                message: format!("has {rows} rows, expected 2 (min, max)"),
            });
        }
        Ok(Self {
            min: data[..cols].iter().map(|v| *v as f32).collect(),
            max: data[cols..].iter().map(|v| *v as f32).collect(),
            lower: -1.0,
            upper: 1.0,
        })
    }

    /// Scales features as OpenCV's `quality_utils::scale` does, in f32.
    pub fn scale(&self, features: &[f32]) -> Vec<f32> {
        features
            .iter()
            .zip(self.min.iter().zip(&self.max))
            .map(|(x, (lo, hi))| self.lower + (self.upper - self.lower) * (x - lo) / (hi - lo))
            .collect()
    }
}
