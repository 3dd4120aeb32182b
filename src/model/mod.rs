//! Wear models (paper sections 2 and 4), fitted on the CPU with faer.
//! Building blocks (indicators, OLS, PCA, Levenberg–Marquardt, the network),
//! the three methods (network, PCA + regression, physical per axle), the
//! event split, saved models and `tirewear fit`. Definitions: docs/models.md.

pub mod data;
pub mod error;
pub mod ffnn;
pub mod fit;
pub mod interval;
pub mod lm;
pub mod metrics;
pub mod network;
mod nullable;
pub mod ols;
pub mod pca;
pub mod physical;
pub mod saved;

pub use error::ModelError;

/// Observations to fit on: rows of the named inputs (n × k) and the target
/// (n values; empty for a method without one, such as PCA).
#[derive(Debug, Clone, Copy)]
pub struct Dataset<'a> {
    pub x: &'a [Vec<f64>],
    pub y: &'a [f64],
    pub inputs: &'a [String],
}

impl<'a> Dataset<'a> {
    pub fn new(x: &'a [Vec<f64>], y: &'a [f64], inputs: &'a [String]) -> Self {
        Dataset { x, y, inputs }
    }
}

/// A method's settings, fitted on a dataset, give its fitted model (linfa's
/// `Fit`): `PcaSettings`, `OlsSettings`, `network::NetworkSettings`. The
/// settings are checked before anything is fitted.
pub trait Fit {
    type Fitted;
    fn fit(&self, data: Dataset<'_>) -> Result<Self::Fitted, ModelError>;
}

/// A fitted model's prediction for rows of its inputs.
pub trait Predict {
    fn predict_one(&self, x: &[f64]) -> f64;
    fn predict(&self, rows: &[Vec<f64>]) -> Vec<f64> {
        rows.iter().map(|r| self.predict_one(r)).collect()
    }
}

use faer::Mat;

/// Rows of observations (n × k) as a faer matrix, with a leading column of
/// ones when `intercept`.
pub(crate) fn design(rows: &[Vec<f64>], intercept: bool) -> Mat<f64> {
    let k = rows.first().map_or(0, Vec::len);
    let off = intercept as usize;
    Mat::from_fn(rows.len(), k + off, |i, j| {
        if intercept && j == 0 {
            1.0
        } else {
            rows[i][j - off]
        }
    })
}
