//! Ordinary least squares with an intercept (paper section 2.3, eq. 8):
//! coefficients by a QR least-squares solve, standard errors from
//! σ²(XᵀX)⁻¹ by a Cholesky factorisation, two-sided t-test p-values.

use super::interval::IntervalLevel;
use super::{
    Dataset, Fit, ModelError, Predict, design,
    metrics::{Metrics, metrics},
};
use faer::Side;
use faer::linalg::solvers::{Solve, SolveLstsq};
use statrs::distribution::{ContinuousCDF, StudentsT};

/// A fitted linear model `y = β0 + Σ βj xj`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OlsFit {
    /// Input names, in the order of `coef[1..]`.
    pub inputs: Vec<String>,
    /// β0 (intercept) then β1..βk.
    pub coef: Vec<f64>,
    #[serde(deserialize_with = "super::nullable::f64s_or_nan")]
    pub std_err: Vec<f64>,
    #[serde(deserialize_with = "super::nullable::f64s_or_nan")]
    pub t_values: Vec<f64>,
    #[serde(deserialize_with = "super::nullable::f64s_or_nan")]
    pub p_values: Vec<f64>,
    /// Residual variance SSE/(n − k − 1).
    pub sigma2: f64,
    pub df_resid: usize,
    /// (XᵀX)⁻¹ of the design `[1, X]`, row-major, (k + 1)²: σ² times it is
    /// the coefficients' covariance (statsmodels' `normalized_cov_params`),
    /// and a prediction interval needs it. None in models saved before
    /// 2026-12-02, which predict without an interval.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub xtx_inverse: Option<Vec<f64>>,
    /// Indicators on the training data.
    pub train: Metrics,
}

/// Ordinary least squares with an intercept; no settings.
#[derive(Debug, Clone, Copy, Default)]
pub struct OlsSettings;

impl Fit for OlsSettings {
    type Fitted = OlsFit;
    fn fit(&self, data: Dataset<'_>) -> Result<OlsFit, ModelError> {
        OlsFit::fit_rows(data.x, data.y, data.inputs)
    }
}

impl Predict for OlsFit {
    fn predict_one(&self, x: &[f64]) -> f64 {
        OlsFit::predict_one(self, x)
    }
}

/// The two-sided p-value of a t statistic: NaN for a NaN statistic (0/0
/// where a table's target is constant down to denormals; statrs panics on
/// it) and 0 for an infinite one.
pub(crate) fn two_sided_p(dist: &StudentsT, t: f64) -> f64 {
    if t.is_nan() {
        f64::NAN
    } else if t.is_infinite() {
        0.0
    } else {
        2.0 * (1.0 - dist.cdf(t.abs()))
    }
}

impl OlsFit {
    /// Fits on rows of inputs (n × k) and the target.
    fn fit_rows(rows: &[Vec<f64>], y: &[f64], inputs: &[String]) -> Result<OlsFit, ModelError> {
        let n = rows.len();
        let k = inputs.len();
        if y.len() != n || rows.iter().any(|r| r.len() != k) {
            return Err(ModelError::LengthMismatch("OLS".into()));
        }
        if n <= k + 1 {
            return Err(ModelError::TooFewObservations {
                what: "OLS".into(),
                needed: k + 1,
                got: n,
            });
        }
        let x = design(rows, true);
        let rhs = faer::Mat::from_fn(n, 1, |i, _| y[i]);
        let beta = x.qr().solve_lstsq(&rhs);
        let coef: Vec<f64> = (0..=k).map(|j| beta[(j, 0)]).collect();
        let fitted = (0..n)
            .map(|i| (0..=k).map(|j| x[(i, j)] * coef[j]).sum::<f64>())
            .collect::<Vec<_>>();
        let sse: f64 = y.iter().zip(&fitted).map(|(a, b)| (a - b).powi(2)).sum();
        let df_resid = n - k - 1;
        let sigma2 = sse / df_resid as f64;
        let xtx = x.transpose() * &x;
        let llt = xtx
            .llt(Side::Lower)
            .map_err(|_| ModelError::Singular("OLS".into()))?;
        let inv = llt.solve(faer::Mat::<f64>::identity(k + 1, k + 1));
        let std_err: Vec<f64> = (0..=k).map(|j| (sigma2 * inv[(j, j)]).sqrt()).collect();
        if std_err.iter().any(|s| !s.is_finite()) {
            return Err(ModelError::Singular("OLS".into()));
        }
        let t_values: Vec<f64> = coef.iter().zip(&std_err).map(|(b, s)| b / s).collect();
        let dist = StudentsT::new(0.0, 1.0, df_resid as f64)
            .map_err(|e| ModelError::Invalid(e.to_string()))?;
        let p_values = t_values.iter().map(|&t| two_sided_p(&dist, t)).collect();
        Ok(OlsFit {
            inputs: inputs.to_vec(),
            coef,
            std_err,
            t_values,
            p_values,
            sigma2,
            df_resid,
            xtx_inverse: Some(
                (0..=k)
                    .flat_map(|i| (0..=k).map(move |j| (i, j)))
                    .map(|(i, j)| inv[(i, j)])
                    .collect(),
            ),
            train: metrics(y, &fitted, k)?,
        })
    }

    pub(crate) fn predict_one(&self, x: &[f64]) -> f64 {
        self.coef[0]
            + self.coef[1..]
                .iter()
                .zip(x)
                .map(|(b, v)| b * v)
                .sum::<f64>()
    }

    pub fn predict(&self, rows: &[Vec<f64>]) -> Vec<f64> {
        rows.iter().map(|r| self.predict_one(r)).collect()
    }

    /// The `level` prediction interval of a new observation at `x`, its
    /// lower and upper bound (statsmodels' `obs_ci_lower`, `obs_ci_upper`):
    /// ŷ ± t · √(σ² (1 + x₀ᵀ(XᵀX)⁻¹x₀)), x₀ = [1, x], t the (1 + level)/2
    /// quantile of Student's t with n − k − 1 degrees of freedom. None for
    /// a model saved without (XᵀX)⁻¹, or one whose bounds are not finite.
    pub fn prediction_interval(&self, x: &[f64], level: IntervalLevel) -> Option<(f64, f64)> {
        let inv = self.xtx_inverse.as_ref()?;
        let x0: Vec<f64> = std::iter::once(1.0).chain(x.iter().copied()).collect();
        let k1 = x0.len();
        if inv.len() != k1 * k1 || self.df_resid == 0 {
            return None;
        }
        let quadratic: f64 = (0..k1)
            .map(|i| x0[i] * (0..k1).map(|j| inv[i * k1 + j] * x0[j]).sum::<f64>())
            .sum();
        let t = StudentsT::new(0.0, 1.0, self.df_resid as f64)
            .ok()?
            .inverse_cdf(0.5 + 0.5 * level.get());
        let half = t * (self.sigma2 * (1.0 + quadratic)).sqrt();
        let y = self.predict_one(x);
        (half.is_finite() && y.is_finite()).then_some((y - half, y + half))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A target constant down to denormals (every wear 5e-324, from a
    /// damaged table) is refused as constant; it panicked in statrs on the
    /// 0/0 t-values. The p-value of a NaN or infinite t by hand.
    #[test]
    fn a_denormal_constant_target_is_refused_not_a_panic() {
        let rows: Vec<Vec<f64>> = (0..8).map(|i| vec![i as f64, (i * i) as f64]).collect();
        let y = vec![5e-324; 8];
        let two = ["a".to_string(), "b".to_string()];
        let e = OlsSettings.fit(Dataset::new(&rows, &y, &two));
        assert!(matches!(e, Err(ModelError::ConstantTarget(_))), "{e:?}");
        let t = StudentsT::new(0.0, 1.0, 5.0).unwrap();
        assert!(two_sided_p(&t, f64::NAN).is_nan());
        assert_eq!(two_sided_p(&t, f64::INFINITY), 0.0);
        assert_eq!(two_sided_p(&t, 0.0), 1.0);
    }

    /// A straight line's prediction interval in closed form:
    /// ŷ ± t · s · √(1 + 1/n + (x₀ − x̄)²/Sxx), with t₀.₉₇₅ on 4 degrees of
    /// freedom 2.7764451051977987 (scipy.stats.t.ppf(0.975, 4)); a model
    /// saved without (XᵀX)⁻¹ has none; a level outside (0, 1) is refused.
    #[test]
    fn a_lines_prediction_interval_in_closed_form() {
        let xs = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0];
        let y = [2.1, 4.9, 8.2, 10.8, 14.1, 17.2];
        let rows: Vec<Vec<f64>> = xs.iter().map(|&x| vec![x]).collect();
        let f = OlsSettings
            .fit(Dataset::new(&rows, &y, &["x".into()]))
            .unwrap();
        let n = xs.len() as f64;
        let mean = xs.iter().sum::<f64>() / n;
        let sxx: f64 = xs.iter().map(|x| (x - mean).powi(2)).sum();
        let b = xs.iter().zip(&y).map(|(x, y)| (x - mean) * y).sum::<f64>() / sxx;
        let a = y.iter().sum::<f64>() / n - b * mean;
        let s2 = xs
            .iter()
            .zip(&y)
            .map(|(x, y)| (y - a - b * x).powi(2))
            .sum::<f64>()
            / (n - 2.0);
        let t = 2.7764451051977987;
        let level = IntervalLevel::new(0.95).unwrap();
        for x0 in [-2.0, 0.0, 2.5, 7.0] {
            let half = t * (s2 * (1.0 + 1.0 / n + (x0 - mean).powi(2) / sxx)).sqrt();
            let (lo, hi) = f.prediction_interval(&[x0], level).unwrap();
            let centre = a + b * x0;
            assert!((lo - (centre - half)).abs() < 1e-10, "{x0}: {lo}");
            assert!((hi - (centre + half)).abs() < 1e-10, "{x0}: {hi}");
        }
        let old = OlsFit {
            xtx_inverse: None,
            ..f
        };
        assert_eq!(old.prediction_interval(&[1.0], level), None);
        for bad in [0.0, 1.0, -0.5, 95.0, f64::NAN] {
            assert!(IntervalLevel::new(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn exact_line_by_hand() {
        // y = 2 + 3x exactly: coefficients exact, zero residual variance.
        let rows: Vec<Vec<f64>> = (0..6).map(|i| vec![i as f64]).collect();
        let y: Vec<f64> = (0..6).map(|i| 2.0 + 3.0 * i as f64).collect();
        let f = OlsSettings
            .fit(Dataset::new(&rows, &y, &["x".into()]))
            .unwrap();
        assert!((f.coef[0] - 2.0).abs() < 1e-12 && (f.coef[1] - 3.0).abs() < 1e-12);
        assert!(f.sigma2 < 1e-20);
        // Collinear inputs are refused.
        let rows2: Vec<Vec<f64>> = (0..6).map(|i| vec![i as f64, 2.0 * i as f64]).collect();
        let two = ["a".to_string(), "b".to_string()];
        assert!(OlsSettings.fit(Dataset::new(&rows2, &y, &two)).is_err());
    }
}
