//! The paper's network method (section 4.1): select inputs by correlation,
//! split the training data 80/20 (seeded) into training and validation,
//! set the first hidden layer as wide as the inputs, loop over the second
//! layer's width in parallel keeping the lowest validation MSE, retrain the
//! best pair and keep whichever of the two is better.

use super::ffnn::{Ffnn, FfnnSettings};
use super::interval::{IntervalLevel, conformal_half_width};
use super::{Dataset, Fit, ModelError, Predict};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// Settings of the network method (paper table 6 and section 4.1).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NetworkSettings {
    /// Inputs need |correlation with the target| above this (paper: 0.15).
    pub min_target_corr: f64,
    /// Inputs are kept only if |correlation| with every kept input is at most this.
    pub max_mutual_corr: f64,
    /// Share of the training rows held out for validation (paper: 20 %).
    pub validation_fraction: f64,
    /// Widths of the second hidden layer to try; empty = 1 ..= inputs + 4
    /// (the paper's best network was 12–12–13–1).
    pub hidden2_candidates: Vec<usize>,
    pub max_epochs: usize,
    pub validation_checks: usize,
    pub seed: u64,
}

impl Default for NetworkSettings {
    fn default() -> Self {
        NetworkSettings {
            min_target_corr: 0.15,
            max_mutual_corr: 0.9,
            validation_fraction: 0.2,
            hidden2_candidates: Vec::new(),
            max_epochs: 100,
            validation_checks: 50,
            seed: 1,
        }
    }
}

impl NetworkSettings {
    /// Every setting in its range, or the first one that is not, named.
    pub fn check(&self) -> Result<(), ModelError> {
        let bad = |name, value: String, expected| {
            Err(ModelError::Setting {
                name,
                value,
                expected,
            })
        };
        let corr = |c: f64| (0.0..=1.0).contains(&c);
        if !corr(self.min_target_corr) {
            return bad(
                "network.min_target_corr",
                self.min_target_corr.to_string(),
                "a |correlation| in [0, 1]",
            );
        }
        if !corr(self.max_mutual_corr) {
            return bad(
                "network.max_mutual_corr",
                self.max_mutual_corr.to_string(),
                "a |correlation| in [0, 1]",
            );
        }
        if !(self.validation_fraction > 0.0 && self.validation_fraction < 1.0) {
            return bad(
                "network.validation_fraction",
                self.validation_fraction.to_string(),
                "a share of the training rows in (0, 1)",
            );
        }
        if self.hidden2_candidates.contains(&0) {
            return bad(
                "network.hidden2_candidates",
                format!("{:?}", self.hidden2_candidates),
                "layer widths of at least 1",
            );
        }
        if self.max_epochs == 0 || self.validation_checks == 0 {
            return bad(
                "network.max_epochs / validation_checks",
                format!("{} / {}", self.max_epochs, self.validation_checks),
                "at least 1 each",
            );
        }
        Ok(())
    }
}

/// One trial of the width loop.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WidthTrial {
    pub hidden2: usize,
    /// Validation MSE in normalised units.
    #[serde(deserialize_with = "super::nullable::f64_or_nan")]
    pub validation_mse: f64,
}

/// The chosen network and how it was chosen.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NetworkFit {
    pub net: Ffnn,
    pub trials: Vec<WidthTrial>,
    /// Whether the retrained best pair beat the first training.
    pub retrained_kept: bool,
    pub training_rows: usize,
    pub validation_rows: usize,
    /// |measured − predicted| wear (%) of the validation rows under the
    /// chosen network, ascending: the calibration scores of its
    /// split-conformal prediction interval ([`NetworkFit::prediction_interval`]).
    /// None in model files before 2026-12-03, which predict without one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub validation_abs_residuals: Option<Vec<f64>>,
}

impl NetworkFit {
    /// The `level` prediction interval of a new tire with inputs `x` (lower,
    /// upper bound in %): split conformal, ŷ ± q with q the ⌈(n + 1)·level⌉-th
    /// smallest of the n validation rows' |y − ŷ|
    /// ([`conformal_half_width`]). The validation rows chose the width and
    /// the epoch the training stopped at, so their errors run a little
    /// smaller than a new tire's (measured: docs/models.md). None without
    /// the scores (an older file), with too few validation rows for the
    /// level, or where the bounds are not finite.
    pub fn prediction_interval(&self, x: &[f64], level: IntervalLevel) -> Option<(f64, f64)> {
        let half = conformal_half_width(self.validation_abs_residuals.as_deref()?, level)?;
        let y = self.net.predict_one(x);
        (half.is_finite() && y.is_finite()).then_some((y - half, y + half))
    }
}

fn validation_mse(net: &Ffnn, x: &[Vec<f64>], y: &[f64]) -> f64 {
    let p = net.predict(x);
    let s2 = net.target_std.powi(2);
    p.iter().zip(y).map(|(p, y)| (p - y).powi(2)).sum::<f64>() / y.len() as f64 / s2
}

impl Fit for NetworkSettings {
    type Fitted = NetworkFit;
    /// The network method on rows of selected inputs and the target.
    fn fit(&self, data: Dataset<'_>) -> Result<NetworkFit, ModelError> {
        self.check()?;
        fit_network(data.x, data.y, self, &indicatif::ProgressBar::hidden())
    }
}

impl Predict for NetworkFit {
    fn predict_one(&self, x: &[f64]) -> f64 {
        self.net.predict_one(x)
    }
}

/// Fits the network method on rows of selected inputs and the target.
/// `bar` counts the widths trained and the retrained pair.
pub(crate) fn fit_network(
    x: &[Vec<f64>],
    y: &[f64],
    s: &NetworkSettings,
    bar: &indicatif::ProgressBar,
) -> Result<NetworkFit, ModelError> {
    let d = x.first().map_or(0, Vec::len);
    if d == 0 {
        return Err(ModelError::Invalid(
            "network: no inputs were selected".into(),
        ));
    }
    let mut idx: Vec<usize> = (0..x.len()).collect();
    idx.shuffle(&mut ChaCha8Rng::seed_from_u64(s.seed));
    let n_val = ((x.len() as f64 * s.validation_fraction).round() as usize).max(1);
    if x.len() < n_val + 2 {
        return Err(ModelError::TooFewObservations {
            what: "network training".into(),
            needed: n_val + 2,
            got: x.len(),
        });
    }
    let (val, tr) = idx.split_at(n_val);
    let pick = |ids: &[usize]| -> (Vec<Vec<f64>>, Vec<f64>) {
        (
            ids.iter().map(|&i| x[i].clone()).collect(),
            ids.iter().map(|&i| y[i]).collect(),
        )
    };
    let ((xt, yt), (xv, yv)) = (pick(tr), pick(val));
    let candidates: Vec<usize> = if s.hidden2_candidates.is_empty() {
        (1..=d + 4).collect()
    } else {
        s.hidden2_candidates.clone()
    };
    let settings = |hidden2: usize, seed: u64| FfnnSettings {
        hidden1: d,
        hidden2,
        max_epochs: s.max_epochs,
        validation_checks: s.validation_checks,
        seed,
    };
    bar.set_length(candidates.len() as u64 + 1);
    let nets: Vec<Ffnn> = candidates
        .par_iter()
        .map(|&h2| {
            let net = Ffnn::fit(&xt, &yt, &xv, &yv, &settings(h2, s.seed));
            bar.inc(1);
            net
        })
        .collect::<Result<_, _>>()?;
    let trials: Vec<WidthTrial> = nets
        .iter()
        .map(|n| WidthTrial {
            hidden2: n.hidden2,
            validation_mse: validation_mse(n, &xv, &yv),
        })
        .collect();
    let best = (0..nets.len())
        .min_by(|&a, &b| {
            trials[a]
                .validation_mse
                .total_cmp(&trials[b].validation_mse)
        })
        .expect("at least one width");
    // Retrain the best pair from other initial weights; keep the better one.
    let again = Ffnn::fit(
        &xt,
        &yt,
        &xv,
        &yv,
        &settings(nets[best].hidden2, s.seed + 1),
    )?;
    bar.inc(1);
    let retrained_kept = validation_mse(&again, &xv, &yv) < trials[best].validation_mse;
    let net = if retrained_kept {
        again
    } else {
        nets[best].clone()
    };
    let mut scores: Vec<f64> = net
        .predict(&xv)
        .iter()
        .zip(&yv)
        .map(|(p, y)| (y - p).abs())
        .collect();
    scores.sort_by(f64::total_cmp);
    // A network that predicts a validation row as NaN has no interval (and
    // a file that reads back: the scores are checked finite on reading).
    let scores = scores.iter().all(|s| s.is_finite()).then_some(scores);
    Ok(NetworkFit {
        net,
        trials,
        retrained_kept,
        training_rows: xt.len(),
        validation_rows: xv.len(),
        validation_abs_residuals: scores,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn width_loop_picks_the_lowest_validation_error() {
        // y = x1 − 2·x2 + noise-free: every width fits; the chosen one has the minimum.
        let x: Vec<Vec<f64>> = (0..60)
            .map(|i| vec![(i as f64 * 0.37).sin(), (i as f64 * 0.91).cos()])
            .collect();
        let y: Vec<f64> = x.iter().map(|r| r[0] - 2.0 * r[1]).collect();
        let s = NetworkSettings {
            hidden2_candidates: vec![1, 2, 3],
            max_epochs: 30,
            ..Default::default()
        };
        let inputs = ["x1".to_string(), "x2".to_string()];
        let f = s.fit(Dataset::new(&x, &y, &inputs)).unwrap();
        assert_eq!(f.trials.len(), 3);
        assert_eq!((f.training_rows, f.validation_rows), (48, 12));
        let min = f
            .trials
            .iter()
            .map(|t| t.validation_mse)
            .fold(f64::MAX, f64::min);
        let best = f.trials.iter().find(|t| t.validation_mse == min).unwrap();
        assert_eq!(f.net.hidden1, 2);
        assert_eq!(f.net.hidden2, best.hidden2);
        assert!(min < 1e-3, "a linear target is easy: validation MSE {min}");
        // Same seed, same network.
        assert_eq!(s.fit(Dataset::new(&x, &y, &inputs)).unwrap(), f);
        // The conformal scores: the validation rows (the first 12 of the
        // seeded shuffle) and their errors, ascending.
        let mut idx: Vec<usize> = (0..60).collect();
        idx.shuffle(&mut ChaCha8Rng::seed_from_u64(s.seed));
        let mut want: Vec<f64> = idx[..12]
            .iter()
            .map(|&i| (y[i] - f.net.predict_one(&x[i])).abs())
            .collect();
        want.sort_by(f64::total_cmp);
        assert_eq!(f.validation_abs_residuals.as_deref(), Some(&want[..]));
        // At 90 %: ⌈13 · 0.9⌉ = ⌈11.7⌉ = 12, the largest of the 12; at 95 %
        // ⌈12.35⌉ = 13 of 12: none.
        let p = f.predict_one(&x[0]);
        let (lo, hi) = f
            .prediction_interval(&x[0], IntervalLevel::new(0.9).unwrap())
            .unwrap();
        assert_eq!((lo, hi), (p - want[11], p + want[11]));
        assert_eq!(f.prediction_interval(&x[0], IntervalLevel::P95), None);
        assert_eq!(f.predict_one(&x[0]), f.net.predict_one(&x[0]));
    }
}
