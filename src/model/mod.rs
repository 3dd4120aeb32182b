//! Wear models (paper sections 2 and 4), fitted on the CPU with faer.
//! So far: the performance indicators, ordinary least squares with
//! inference, principal component analysis, the Levenberg–Marquardt solver
//! and the feed-forward network it trains (the physical method, the data
//! split and `tirewear fit` follow).

pub mod data;
pub mod error;
pub mod ffnn;
pub mod lm;
pub mod metrics;
pub mod ols;
pub mod pca;

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
