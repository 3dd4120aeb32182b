//! Model performance indicators (paper section 2.4).

use super::ModelError;

/// R², adjusted R², RMSE and MAE of predictions, with n and the number of regressors k.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Metrics {
    pub n: usize,
    /// Number of regressors (inputs), not counting the intercept.
    pub k: usize,
    /// R² = 1 − SSE/SST (eq. 11).
    #[serde(deserialize_with = "super::nullable::f64_or_nan")]
    pub r2: f64,
    /// Adjusted R² in the usual form with an intercept, 1 − (n−1)/(n−k−1)·(1−R²)
    /// (statsmodels, MATLAB fitlm). The paper's eq. 12 divides by n−k instead.
    /// `None` (null in a model file) when n ≤ k + 1, where it is undefined:
    /// a few testing tires do not sink a model with many inputs.
    pub r2_adj: Option<f64>,
    /// √(SSE/n) (eq. 13).
    #[serde(deserialize_with = "super::nullable::f64_or_nan")]
    pub rmse: f64,
    #[serde(deserialize_with = "super::nullable::f64_or_nan")]
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
    if n < 2 {
        return Err(ModelError::TooFewObservations {
            what: "R² (a spread of the observed wear)".into(),
            needed: 2,
            got: n,
        });
    }
    if let Some(i) = (0..n).find(|&i| !(observed[i].is_finite() && predicted[i].is_finite())) {
        return Err(ModelError::Invalid(format!(
            "metrics: row {i} is not finite (observed {}, predicted {})",
            observed[i], predicted[i]
        )));
    }
    let mean = observed.iter().sum::<f64>() / n as f64;
    let sst: f64 = observed.iter().map(|y| (y - mean).powi(2)).sum();
    // Identical values leave rounding residue in SST (1e-28 for twelve equal
    // rows): anything below a relative 1e-12 spread is a constant target.
    let scale = observed.iter().fold(0.0f64, |m, y| m.max(y.abs()));
    if sst <= n as f64 * (1e-12 * scale).powi(2) {
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
        r2_adj: (n > k + 1)
            .then(|| 1.0 - (n as f64 - 1.0) / (n as f64 - k as f64 - 1.0) * (1.0 - r2)),
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
        assert!((m.r2_adj.unwrap() - (1.0 - 4.0 / 3.0 * 0.2)).abs() < 1e-12);
        assert!((m.rmse - 0.4f64.sqrt()).abs() < 1e-12);
        assert!((m.mae - 0.4).abs() < 1e-12);
        assert!(metrics(&[1.0, 1.0, 1.0], &[1.0, 1.0, 1.0], 0).is_err());
        assert!(metrics(&[1.0], &[1.0], 0).is_err());
        // n ≤ k + 1 (k = 2: n = k + 1; k = 5: fewer rows than inputs): R²
        // by hand, adjusted R² undefined. y = (1, 2, 3), p = (1, 3, 3):
        // SSE = 1, SST = 2, R² = 0.5.
        for k in [2, 5] {
            let m = metrics(&[1.0, 2.0, 3.0], &[1.0, 3.0, 3.0], k).unwrap();
            assert!((m.r2 - 0.5).abs() < 1e-12);
            assert_eq!(m.r2_adj, None, "k = {k}");
        }
        // k = 1: 1 − 2/1·0.5 = 0.
        let m = metrics(&[1.0, 2.0, 3.0], &[1.0, 3.0, 3.0], 1).unwrap();
        assert!(m.r2_adj.unwrap().abs() < 1e-12);
    }

    #[test]
    fn identical_rows_are_a_constant_target_not_a_huge_negative_r2() {
        // 0.1 + 0.2 style residue: the mean of equal values is not exact.
        let y = vec![12.3; 12];
        let p: Vec<f64> = (0..12).map(|i| 12.0 + 0.05 * i as f64).collect();
        assert!(matches!(
            metrics(&y, &p, 1),
            Err(ModelError::ConstantTarget(_))
        ));
        let mut bad = p.clone();
        bad[3] = f64::INFINITY;
        let e = metrics(&p, &bad, 1).unwrap_err().to_string();
        assert!(e.contains("row 3"), "{e}");
    }
}
