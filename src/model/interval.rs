//! Prediction intervals: their level, the network's split-conformal width,
//! and how many measured wears the intervals hold (what `fit`, `predict`
//! and the report print). The regressions' classical interval is
//! `OlsFit::prediction_interval`. Definitions: docs/models.md,
//! "Prediction intervals".

use super::ModelError;

/// The coverage of a prediction interval, strictly between 0 and 1 (0.95:
/// a new tire's wear falls inside 95 % of the time, under the model's
/// assumptions).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntervalLevel(f64);

impl IntervalLevel {
    /// 95 %: the level `fit` and the report check their intervals at.
    pub const P95: IntervalLevel = IntervalLevel(0.95);

    pub fn new(level: f64) -> Result<IntervalLevel, ModelError> {
        if level > 0.0 && level < 1.0 {
            Ok(IntervalLevel(level))
        } else {
            Err(ModelError::Invalid(format!(
                "a prediction interval's level must be between 0 and 1 (0.95 for 95 %), got {level}"
            )))
        }
    }

    pub fn get(self) -> f64 {
        self.0
    }
}

/// The rank, 1-based, of the split-conformal quantile among `n`
/// calibration scores: ⌈(n + 1)·level⌉ (Vovk et al.; Lei et al. 2018,
/// "Distribution-free predictive inference for regression"). The product is
/// nudged down by 1e-9 before the ceiling so that a product that is whole
/// in decimals is not pushed one rank up by binary rounding (25 · 0.28 is
/// 7.000000000000001 in f64).
pub fn conformal_rank(n: usize, level: IntervalLevel) -> usize {
    (((n + 1) as f64 * level.get() - 1e-9).ceil() as usize).max(1)
}

/// The fewest calibration scores that give a `level` interval: the least
/// n with [`conformal_rank`] ≤ n, that is n ≥ (level − 1e-9)/(1 − level)
/// (19 for 95 %, 99 for 99 %).
pub fn conformal_rows_needed(level: IntervalLevel) -> usize {
    let l = level.get();
    let guess = (((l - 1e-9) / (1.0 - l)).ceil().max(1.0)) as usize;
    // The division may round across a whole number: settle on the exact rank test.
    (guess.saturating_sub(1).max(1)..=guess.saturating_add(1))
        .find(|&n| conformal_rank(n, level) <= n)
        .unwrap_or(guess)
}

/// The half-width of a split-conformal interval ŷ ± q: q is the
/// [`conformal_rank`]-th smallest of the calibration scores |y − ŷ|
/// (`scores`, ascending). A new observation exchangeable with the
/// calibration rows lies inside with probability at least `level`. None
/// when that rank exceeds the scores' count: too few rows for the level
/// (19 rows at least for 95 %).
pub fn conformal_half_width(scores: &[f64], level: IntervalLevel) -> Option<f64> {
    scores.get(conformal_rank(scores.len(), level) - 1).copied()
}

/// Of `of` measured wears that have a prediction interval, how many lie
/// inside it (bounds included).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Coverage {
    pub inside: usize,
    pub of: usize,
}

impl Coverage {
    /// Counts measured wears against their intervals; a wear without an
    /// interval is not counted.
    pub fn of(pairs: impl IntoIterator<Item = (f64, Option<(f64, f64)>)>) -> Coverage {
        let mut c = Coverage::default();
        for (measured, interval) in pairs {
            if let Some((low, high)) = interval {
                c.add(measured, low, high);
            }
        }
        c
    }

    /// One more measured wear and its interval.
    pub fn add(&mut self, measured: f64, low: f64, high: f64) {
        self.inside += usize::from((low..=high).contains(&measured));
        self.of += 1;
    }

    /// The share inside (0–1); None when no wear had an interval.
    pub fn share(self) -> Option<f64> {
        (self.of > 0).then(|| self.inside as f64 / self.of as f64)
    }
}

impl std::fmt::Display for Coverage {
    /// "96.5 % of 316".
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.share() {
            Some(s) => write!(f, "{:.1} % of {}", 100.0 * s, self.of),
            None => write!(f, "none of 0"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conformal_ranks_by_hand() {
        let l = |x| IntervalLevel::new(x).unwrap();
        // ⌈20 · 0.95⌉ = 19; ⌈25 · 0.28⌉ = 7, where 25 · 0.28 is
        // 7.000000000000001 in f64 (8 without the nudge).
        assert_eq!(conformal_rank(19, l(0.95)), 19);
        assert_eq!(conformal_rank(24, l(0.28)), 7);
        // ⌈46 · 0.95⌉ = ⌈43.7⌉ = 44.
        assert_eq!(conformal_rank(45, l(0.95)), 44);
        // ⌈10 · 0.5⌉ = 5, ⌈11 · 0.5⌉ = ⌈5.5⌉ = 6.
        assert_eq!(conformal_rank(9, l(0.5)), 5);
        assert_eq!(conformal_rank(10, l(0.5)), 6);
        // ⌈(n + 1) · 0.001⌉ is 1 for any n below 999.
        assert_eq!(conformal_rank(3, l(0.001)), 1);
        let scores: Vec<f64> = (1..=19).map(f64::from).collect();
        assert_eq!(conformal_half_width(&scores, l(0.95)), Some(19.0));
        assert_eq!(conformal_half_width(&scores, l(0.9)), Some(18.0));
        // 18 scores cannot certify 95 %: ⌈19 · 0.95⌉ = 19 > 18.
        assert_eq!(conformal_half_width(&scores[..18], l(0.95)), None);
        assert_eq!(conformal_half_width(&[], l(0.5)), None);
    }

    #[test]
    fn rows_needed_is_the_least_count_a_rank_fits_in() {
        let l = |x| IntervalLevel::new(x).unwrap();
        assert_eq!(conformal_rows_needed(l(0.95)), 19);
        assert_eq!(conformal_rows_needed(l(0.99)), 99);
        assert_eq!(conformal_rows_needed(l(0.5)), 1);
        for k in 1..1000 {
            let level = l(k as f64 / 1000.0);
            let brute = (1..).find(|&n| conformal_rank(n, level) <= n).unwrap();
            assert_eq!(conformal_rows_needed(level), brute, "{k}");
        }
        // Near 1 it is computed, not searched.
        assert!(conformal_rows_needed(l(1.0 - 1e-15)) > 1_000_000_000);
    }

    #[test]
    fn coverage_counts_bounds_as_inside_and_skips_rows_without_one() {
        let c = Coverage::of([
            (1.0, Some((1.0, 2.0))),
            (2.0, Some((1.0, 2.0))),
            (2.5, Some((1.0, 2.0))),
            (9.0, None),
        ]);
        assert_eq!(c, Coverage { inside: 2, of: 3 });
        assert_eq!(c.to_string(), "66.7 % of 3");
        assert_eq!(Coverage::default().share(), None);
    }
}
