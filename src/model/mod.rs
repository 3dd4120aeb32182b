//! Wear models (paper sections 2 and 4), fitted on the CPU with faer.
//! Building blocks (indicators, OLS, PCA, Levenberg–Marquardt, the network),
//! the three methods (network, PCA + regression, physical per axle), the
//! event split, saved models and `tirewear fit`. Definitions: docs/models.md.

pub mod data;
pub mod error;
pub mod ffnn;
pub mod fit;
pub mod lm;
pub mod metrics;
pub mod network;
pub mod ols;
pub mod pca;
pub mod physical;
pub mod saved;

pub use error::ModelError;

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
