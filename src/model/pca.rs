//! Principal component analysis (paper section 2.2): inputs standardised,
//! components as eigenvectors of the correlation matrix (faer), proportions
//! of variance λ_i/Σλ (eq. 4), the fewest components that explain at least a
//! threshold of the variance.

use super::{Dataset, Fit, ModelError};
use faer::{Mat, Side};

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PcaFit {
    pub inputs: Vec<String>,
    pub means: Vec<f64>,
    /// Sample standard deviations (n − 1) used to standardise.
    pub stds: Vec<f64>,
    /// Eigenvalues of the correlation matrix, largest first.
    pub eigenvalues: Vec<f64>,
    /// Proportion of variance of each component (eq. 4).
    pub proportions: Vec<f64>,
    /// Loadings a_ij: `loadings[i]` is component i over the inputs (eq. 3).
    pub loadings: Vec<Vec<f64>>,
    /// Components kept (explaining at least the threshold).
    pub kept: usize,
}

/// Settings of a principal component analysis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PcaSettings {
    /// Share of the variance the kept components explain, in (0, 1] (paper: 0.99).
    pub threshold: f64,
}

impl Default for PcaSettings {
    fn default() -> Self {
        PcaSettings { threshold: 0.99 }
    }
}

impl PcaSettings {
    pub fn check(&self) -> Result<(), ModelError> {
        let t = self.threshold;
        if t > 0.0 && t <= 1.0 {
            Ok(())
        } else {
            Err(ModelError::Setting {
                name: "pca_threshold",
                value: t.to_string(),
                expected: "a share of variance in (0, 1]",
            })
        }
    }
}

impl Fit for PcaSettings {
    type Fitted = PcaFit;
    /// The target is not used.
    fn fit(&self, data: Dataset<'_>) -> Result<PcaFit, ModelError> {
        self.check()?;
        PcaFit::fit_rows(data.x, data.inputs, self.threshold)
    }
}

impl PcaFit {
    fn fit_rows(
        rows: &[Vec<f64>],
        inputs: &[String],
        threshold: f64,
    ) -> Result<PcaFit, ModelError> {
        let (n, k) = (rows.len(), inputs.len());
        if n < 2 || k == 0 {
            return Err(ModelError::TooFewObservations {
                what: "PCA".into(),
                needed: 1,
                got: n,
            });
        }
        let means: Vec<f64> = (0..k)
            .map(|j| rows.iter().map(|r| r[j]).sum::<f64>() / n as f64)
            .collect();
        let stds: Vec<f64> = (0..k)
            .map(|j| {
                (rows.iter().map(|r| (r[j] - means[j]).powi(2)).sum::<f64>() / (n - 1) as f64)
                    .sqrt()
            })
            .collect();
        if let Some(j) = stds.iter().position(|s| !s.is_finite()) {
            return Err(ModelError::Invalid(format!(
                "PCA: input '{}' overflows (values beyond ±1e150, or not finite): \
                 its spread is {}",
                inputs[j], stds[j]
            )));
        }
        if let Some(j) = stds.iter().position(|s| *s <= 0.0) {
            return Err(ModelError::Invalid(format!(
                "PCA: input '{}' is constant",
                inputs[j]
            )));
        }
        let z = Mat::from_fn(n, k, |i, j| (rows[i][j] - means[j]) / stds[j]);
        let corr = (z.transpose() * &z) * faer::Scale(1.0 / (n - 1) as f64);
        let evd = corr
            .self_adjoint_eigen(Side::Lower)
            .map_err(|_| ModelError::Singular("PCA".into()))?;
        let (u, s) = (evd.U(), evd.S().column_vector());
        // faer sorts eigenvalues ascending: reverse to largest first.
        let order: Vec<usize> = (0..k).rev().collect();
        let eigenvalues: Vec<f64> = order.iter().map(|&i| s[i].max(0.0)).collect();
        let total: f64 = eigenvalues.iter().sum();
        let proportions: Vec<f64> = eigenvalues.iter().map(|l| l / total).collect();
        let loadings = order
            .iter()
            .map(|&c| (0..k).map(|j| u[(j, c)]).collect())
            .collect();
        let mut cum = 0.0;
        let kept = proportions.iter().take_while(|p| {
            let before = cum;
            cum += **p;
            before < threshold
        });
        let kept = kept.count().max(1);
        Ok(PcaFit {
            inputs: inputs.to_vec(),
            means,
            stds,
            eigenvalues,
            proportions,
            loadings,
            kept,
        })
    }

    /// Scores y_i = Σ a_ij z_j of the kept components (eq. 3) for each row.
    pub(crate) fn transform(&self, rows: &[Vec<f64>]) -> Vec<Vec<f64>> {
        rows.iter()
            .map(|r| {
                (0..self.kept)
                    .map(|c| {
                        self.loadings[c]
                            .iter()
                            .enumerate()
                            .map(|(j, a)| a * (r[j] - self.means[j]) / self.stds[j])
                            .sum()
                    })
                    .collect()
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_perfectly_correlated_inputs_need_one_component() {
        // x2 = 2·x1 + 1: correlation 1, eigenvalues (2, 0), loadings ±(1, 1)/√2.
        let rows: Vec<Vec<f64>> = (0..10)
            .map(|i| vec![i as f64, 2.0 * i as f64 + 1.0])
            .collect();
        let inputs = ["a".to_string(), "b".to_string()];
        let data = Dataset {
            x: &rows,
            y: &[],
            inputs: &inputs,
        };
        let p = PcaSettings::default().fit(data).unwrap();
        assert!((p.eigenvalues[0] - 2.0).abs() < 1e-12 && p.eigenvalues[1].abs() < 1e-12);
        assert_eq!(p.kept, 1);
        let a = p.loadings[0][0].abs();
        assert!((a - 0.5f64.sqrt()).abs() < 1e-12);
        assert!((p.loadings[0][0] - p.loadings[0][1]).abs() < 1e-12);
    }
}
