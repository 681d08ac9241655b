//! The Fréchet distance between two Gaussians fitted to feature sets, in f64:
//!
//! `d^2 = |mu1 - mu2|^2 + tr(S1) + tr(S2) - 2 tr( (S1 S2)^(1/2) )`
//!
//! pytorch-fid evaluates the last term with `scipy.linalg.sqrtm(S1 @ S2)` (a Schur method on
//! a non-symmetric product, which can go complex and needs an `eps * I` retry). We use that
//! S1 S2 is similar to the symmetric positive semi-definite `M = S1^(1/2) S2 S1^(1/2)`, so
//! `tr((S1 S2)^(1/2)) = sum_i sqrt(max(lambda_i(M), 0))`, with `S1^(1/2)` from a symmetric
//! eigen-decomposition (negative round-off eigenvalues clipped to zero). No complex numbers,
//! no retries.
//!
//! With feature sets of `n1, n2` samples and `min(n1, n2) <= dim` (small evaluation sets),
//! `S_k = A_k^T A_k / (n_k - 1)` for the centred features `A_k`, and the non-zero
//! eigenvalues of `S1 S2` are the squared singular values of `A2 A1^T / sqrt((n1-1)(n2-1))`:
//! the trace term is that small matrix's nuclear norm, exact and far cheaper than a
//! `dim x dim` decomposition. [`frechet_distance_features`] picks that route itself.

use nalgebra::{DMatrix, DVector, SymmetricEigen};

use super::error::FidError;

/// Mean and covariance (unbiased, like `np.cov`) of a feature set.
#[derive(Debug, Clone)]
pub struct FeatureStats {
    /// Mean, `dim` values.
    pub mean: DVector<f64>,
    /// Covariance, `dim x dim`.
    pub cov: DMatrix<f64>,
    /// Samples the statistics came from.
    pub count: usize,
}

/// A feature set: `count` rows of `dim` values, row-major.
#[derive(Debug, Clone, Copy)]
pub struct FeatureSet<'a> {
    /// Row-major values.
    pub values: &'a [f32],
    /// Rows (images).
    pub count: usize,
    /// Columns (feature dimension).
    pub dim: usize,
    /// Name used in errors ("prediction", "ground truth").
    pub name: &'static str,
}

impl FeatureSet<'_> {
    fn validate(&self) -> Result<(), FidError> {
        if self.values.len() != self.count * self.dim {
            return Err(FidError::BadFeatures {
                got: self.values.len(),
                count: self.count,
                dim: self.dim,
            });
        }
        if self.count < 2 {
            return Err(FidError::TooFewImages {
                set: self.name,
                count: self.count,
            });
        }
        if self.values.iter().any(|v| !v.is_finite()) {
            return Err(FidError::NonFinite("features"));
        }
        Ok(())
    }

    /// The centred features in f64 (`count x dim`) and the mean.
    fn centred(&self) -> (DMatrix<f64>, DVector<f64>) {
        let a =
            DMatrix::from_row_iterator(self.count, self.dim, self.values.iter().map(|v| *v as f64));
        let mean = DVector::from_iterator(self.dim, a.column_iter().map(|c| c.mean()));
        let mut centred = a;
        for mut row in centred.row_iter_mut() {
            row -= mean.transpose();
        }
        (centred, mean)
    }

    /// Mean and unbiased covariance.
    pub fn stats(&self) -> Result<FeatureStats, FidError> {
        self.validate()?;
        let (a, mean) = self.centred();
        let cov = (a.transpose() * &a) / (self.count as f64 - 1.0);
        Ok(FeatureStats {
            mean,
            cov,
            count: self.count,
        })
    }
}

/// Fréchet distance between two Gaussians given by their statistics (the `dim x dim`
/// eigen-decomposition route; see the module docs).
pub fn frechet_distance_stats(a: &FeatureStats, b: &FeatureStats) -> Result<f64, FidError> {
    let d = a.mean.len();
    if b.mean.len() != d || a.cov.shape() != (d, d) || b.cov.shape() != (d, d) {
        return Err(FidError::DimensionMismatch {
            a: d,
            b: b.mean.len(),
        });
    }
    if a.mean
        .iter()
        .chain(b.mean.iter())
        .chain(a.cov.iter())
        .chain(b.cov.iter())
        .any(|v| !v.is_finite())
    {
        return Err(FidError::NonFinite("feature statistics"));
    }
    let mean_term = (&a.mean - &b.mean).norm_squared();
    let sym = |m: &DMatrix<f64>| (m + m.transpose()) * 0.5;
    let eig = SymmetricEigen::new(sym(&a.cov));
    let sqrt_vals = eig.eigenvalues.map(|l| l.max(0.0).sqrt());
    let v = &eig.eigenvectors;
    let sqrt_a = v * DMatrix::from_diagonal(&sqrt_vals) * v.transpose();
    let m = &sqrt_a * sym(&b.cov) * &sqrt_a;
    let tr_sqrt: f64 = sym(&m)
        .symmetric_eigenvalues()
        .iter()
        .map(|l| l.max(0.0).sqrt())
        .sum();
    Ok(mean_term + a.cov.trace() + b.cov.trace() - 2.0 * tr_sqrt)
}

/// Fréchet distance between two feature sets; uses the small Gram-matrix route when either
/// set has no more samples than dimensions, else the statistics route.
pub fn frechet_distance_features(a: FeatureSet, b: FeatureSet) -> Result<f64, FidError> {
    a.validate()?;
    b.validate()?;
    if a.dim != b.dim {
        return Err(FidError::DimensionMismatch { a: a.dim, b: b.dim });
    }
    if a.count.min(b.count) > a.dim {
        return frechet_distance_stats(&a.stats()?, &b.stats()?);
    }
    let (ca, mean_a) = a.centred();
    let (cb, mean_b) = b.centred();
    let (na, nb) = (a.count as f64 - 1.0, b.count as f64 - 1.0);
    let mean_term = (&mean_a - &mean_b).norm_squared();
    let tr_a = ca.norm_squared() / na;
    let tr_b = cb.norm_squared() / nb;
    let cross = (&cb * ca.transpose()) / (na * nb).sqrt();
    let nuclear: f64 = cross.singular_values().iter().sum();
    Ok(mean_term + tr_a + tr_b - 2.0 * nuclear)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(values: &[f32], count: usize, dim: usize) -> FeatureSet<'_> {
        FeatureSet {
            values,
            count,
            dim,
            name: "test",
        }
    }

    #[test]
    fn closed_form_for_diagonal_gaussians_and_both_routes_agree() {
        // Deterministic pseudo-random features, 40 x 3 and 35 x 3.
        let gen = |n: usize, seed: u64, scale: [f32; 3], shift: f32| -> Vec<f32> {
            let mut s = seed;
            (0..n * 3)
                .map(|i| {
                    s = s
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    ((s >> 33) as f32 / (1u64 << 31) as f32 - 0.5) * scale[i % 3] + shift
                })
                .collect()
        };
        let a = gen(40, 1, [1.0, 2.0, 0.5], 0.0);
        let b = gen(35, 2, [0.3, 1.0, 4.0], 1.0);
        let (sa, sb) = (
            set(&a, 40, 3).stats().unwrap(),
            set(&b, 35, 3).stats().unwrap(),
        );
        let via_stats = frechet_distance_stats(&sa, &sb).unwrap();
        let via_features = frechet_distance_features(set(&a, 40, 3), set(&b, 35, 3)).unwrap();
        assert!(
            (via_stats - via_features).abs() < 1e-9,
            "{via_stats} vs {via_features}"
        );
        // Gram route forced: the same sets seen as 3 samples of more dimensions are a
        // different problem, so check the Gram route on its own closed form instead:
        // identical sets give zero.
        let d0 = frechet_distance_features(set(&a[..30], 3, 10), set(&a[..30], 3, 10)).unwrap();
        assert!(d0.abs() < 1e-9, "{d0}");
        // Diagonal covariances: d = |dmu|^2 + sum (sqrt(s1) - sqrt(s2))^2.
        let mut s1 = DMatrix::zeros(2, 2);
        let mut s2 = DMatrix::zeros(2, 2);
        s1[(0, 0)] = 4.0;
        s1[(1, 1)] = 1.0;
        s2[(0, 0)] = 1.0;
        s2[(1, 1)] = 9.0;
        let ga = FeatureStats {
            mean: DVector::from_vec(vec![0.0, 1.0]),
            cov: s1,
            count: 10,
        };
        let gb = FeatureStats {
            mean: DVector::from_vec(vec![3.0, 1.0]),
            cov: s2,
            count: 10,
        };
        let d = frechet_distance_stats(&ga, &gb).unwrap();
        assert!((d - (9.0 + 1.0 + 4.0)).abs() < 1e-12, "{d}");
    }

    #[test]
    fn one_sample_is_a_clear_error() {
        let v = vec![0.5f32; 4];
        let err = frechet_distance_features(set(&v, 1, 4), set(&v, 1, 4)).unwrap_err();
        assert!(
            matches!(err, FidError::TooFewImages { count: 1, .. }),
            "{err}"
        );
        assert!(err.to_string().contains("covariance"), "{err}");
    }
}
