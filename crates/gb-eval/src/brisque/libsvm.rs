//! libsvm text models (`svm_type epsilon_svr`, `kernel_type rbf`, sparse `index:value`
//! support vectors) and svm-scale range files, as shipped with the original BRISQUE release.

use std::path::Path;

use super::error::BrisqueError;
use super::svr::{FeatureRange, KernelPrecision, RbfSvr};

fn read(path: &Path) -> Result<String, BrisqueError> {
    std::fs::read_to_string(path).map_err(|source| BrisqueError::Io {
        path: path.to_path_buf(),
        source,
    })
}

fn parse_err(path: &Path, line: usize, message: impl Into<String>) -> BrisqueError {
    BrisqueError::Parse {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

/// Loads a libsvm regression model with an RBF kernel; `dim` is the feature count (entries
/// a sparse line omits are zero, as in libsvm).
pub fn load_libsvm_model(path: &Path, dim: usize) -> Result<RbfSvr, BrisqueError> {
    let text = read(path)?;
    let mut gamma = None;
    let mut rho = None;
    let mut coefs = Vec::new();
    let mut svs = Vec::new();
    let mut in_sv = false;
    for (idx, line) in text.lines().enumerate() {
        let number = idx + 1;
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        if !in_sv {
            let mut parts = line.split_whitespace();
            let key = parts.next().unwrap_or("");
            let value = parts.next();
            let number_of = |v: Option<&str>| {
                v.and_then(|s| s.parse::<f64>().ok())
                    .ok_or_else(|| parse_err(path, number, format!("'{key}' needs a number")))
            };
            match key {
                "svm_type" => {
                    let t = value.unwrap_or("");
                    if t != "epsilon_svr" && t != "nu_svr" {
                        return Err(parse_err(
                            path,
                            number,
                            format!("svm_type '{t}' is not a regression"),
                        ));
                    }
                }
                "kernel_type" => {
                    let t = value.unwrap_or("");
                    if t != "rbf" {
                        return Err(parse_err(
                            path,
                            number,
                            format!("kernel_type '{t}' is not rbf"),
                        ));
                    }
                }
                "gamma" => gamma = Some(number_of(value)?),
                "rho" => rho = Some(number_of(value)?),
                "SV" => in_sv = true,
                _ => {}
            }
            continue;
        }
        let mut parts = line.split_whitespace();
        let coef: f64 = parts.next().and_then(|s| s.parse().ok()).ok_or_else(|| {
            parse_err(
                path,
                number,
                "support vector line must start with its coefficient",
            )
        })?;
        let mut sv = vec![0.0f64; dim];
        for entry in parts {
            let (i, v) = entry.split_once(':').ok_or_else(|| {
                parse_err(
                    path,
                    number,
                    format!("expected index:value, found '{entry}'"),
                )
            })?;
            let i: usize = i
                .parse()
                .map_err(|_| parse_err(path, number, format!("bad feature index '{i}'")))?;
            let v: f64 = v
                .parse()
                .map_err(|_| parse_err(path, number, format!("bad feature value '{v}'")))?;
            if i == 0 || i > dim {
                return Err(parse_err(
                    path,
                    number,
                    format!("feature index {i} outside 1..={dim}"),
                ));
            }
            sv[i - 1] = v;
        }
        coefs.push(coef);
        svs.extend(sv);
    }
    let gamma = gamma.ok_or_else(|| parse_err(path, 0, "no 'gamma' line"))?;
    let rho = rho.ok_or_else(|| parse_err(path, 0, "no 'rho' line"))?;
    if coefs.is_empty() {
        return Err(parse_err(path, 0, "no support vectors after 'SV'"));
    }
    Ok(RbfSvr {
        gamma,
        rho,
        coefs,
        support_vectors: svs,
        dim,
        precision: KernelPrecision::F64,
    })
}

/// Loads an svm-scale range file (`x`, then `lower upper`, then `index min max` lines).
pub fn load_svm_scale_range(path: &Path, dim: usize) -> Result<FeatureRange, BrisqueError> {
    let text = read(path)?;
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    match lines.next() {
        Some((_, l)) if l.trim() == "x" => {}
        Some((i, _)) => {
            return Err(parse_err(
                path,
                i + 1,
                "an svm-scale range file starts with 'x'",
            ))
        }
        None => return Err(parse_err(path, 0, "empty range file")),
    }
    let (i, bounds) = lines
        .next()
        .ok_or_else(|| parse_err(path, 0, "missing 'lower upper' line"))?;
    let b: Vec<f32> = bounds
        .split_whitespace()
        .filter_map(|s| s.parse().ok())
        .collect();
    if b.len() != 2 {
        return Err(parse_err(path, i + 1, "expected 'lower upper'"));
    }
    let mut min = vec![0.0f32; dim];
    let mut max = vec![0.0f32; dim];
    for (i, line) in lines {
        let v: Vec<&str> = line.split_whitespace().collect();
        let parsed = (v.len() == 3)
            .then(|| {
                Some((
                    v[0].parse::<usize>().ok()?,
                    v[1].parse::<f32>().ok()?,
                    v[2].parse::<f32>().ok()?,
                ))
            })
            .flatten();
        let (idx, lo, hi) =
            parsed.ok_or_else(|| parse_err(path, i + 1, "expected 'index min max'"))?;
        if idx == 0 || idx > dim {
            return Err(parse_err(
                path,
                i + 1,
                format!("feature index {idx} outside 1..={dim}"),
            ));
        }
        min[idx - 1] = lo;
        max[idx - 1] = hi;
    }
    Ok(FeatureRange {
        min,
        max,
        lower: b[0],
        upper: b[1],
    })
}
