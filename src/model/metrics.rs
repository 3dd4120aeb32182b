//! Model performance indicators (paper section 2.4).

use super::ModelError;

/// R², adjusted R², RMSE and MAE of predictions, with n and the number of regressors k.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Metrics {
    pub n: usize,
    /// Number of regressors (inputs), not counting the intercept.
    pub k: usize,
    /// R² = 1 − SSE/SST (eq. 11).
    pub r2: f64,
    /// Adjusted R² in the usual form with an intercept, 1 − (n−1)/(n−k−1)·(1−R²)
    /// (statsmodels, MATLAB fitlm). The paper's eq. 12 divides by n−k instead.
    pub r2_adj: f64,
    /// √(SSE/n) (eq. 13).
    pub rmse: f64,
    pub mae: f64,
}

/// Median of the finite values of `v` (mean of the middle two for an even
/// count); NaN when there are none.
pub fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Indicators of `predicted` against `observed` for a model with `k` regressors.
pub fn metrics(observed: &[f64], predicted: &[f64], k: usize) -> Result<Metrics, ModelError> {
    let n = observed.len();
    if predicted.len() != n {
        return Err(ModelError::LengthMismatch("metrics".into()));
    }
    if n < k + 2 {
        return Err(ModelError::TooFewObservations {
            what: "adjusted R²".into(),
            needed: k + 1,
            got: n,
        });
    }
    let mean = observed.iter().sum::<f64>() / n as f64;
    let sst: f64 = observed.iter().map(|y| (y - mean).powi(2)).sum();
    if sst == 0.0 {
        return Err(ModelError::ConstantTarget("metrics".into()));
    }
    let sse: f64 = observed
        .iter()
        .zip(predicted)
        .map(|(y, p)| (y - p).powi(2))
        .sum();
    let mae = observed
        .iter()
        .zip(predicted)
        .map(|(y, p)| (y - p).abs())
        .sum::<f64>()
        / n as f64;
    let r2 = 1.0 - sse / sst;
    Ok(Metrics {
        n,
        k,
        r2,
        r2_adj: 1.0 - (n as f64 - 1.0) / (n as f64 - k as f64 - 1.0) * (1.0 - r2),
        rmse: (sse / n as f64).sqrt(),
        mae,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn indicators_by_hand() {
        // y = 1..5, predictions off by (0, 1, 0, -1, 0): SSE = 2, SST = 10, R² = 0.8,
        // adj (k = 1) = 1 - 4/3·0.2 = 0.733..., RMSE = √0.4, MAE = 0.4.
        let m = metrics(&[1.0, 2.0, 3.0, 4.0, 5.0], &[1.0, 1.0, 3.0, 5.0, 5.0], 1).unwrap();
        assert!((m.r2 - 0.8).abs() < 1e-12);
        assert!((m.r2_adj - (1.0 - 4.0 / 3.0 * 0.2)).abs() < 1e-12);
        assert!((m.rmse - 0.4f64.sqrt()).abs() < 1e-12);
        assert!((m.mae - 0.4).abs() < 1e-12);
        assert!(metrics(&[1.0, 1.0, 1.0], &[1.0, 1.0, 1.0], 0).is_err());
        assert!(metrics(&[1.0, 2.0], &[1.0, 2.0], 1).is_err());
    }
}
