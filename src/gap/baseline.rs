//! The physics baseline of the gap ("the simulation"): the frictional-energy
//! wear law
//!
//! wear = k_{c,a} · Σ_b E_b · φ_c(T_b) · exp(s·Sk)
//!
//! with a coefficient k per compound c and axle a (the paper fits the axles
//! apart: a steered front wears differently per joule), the friction energy
//! E_b of each surface-temperature bin b of the energy map weighted by the
//! compound's viscoelastic temperature factor φ_c, and the road's texture
//! factor exp(s·Sk) (negatively skewed, plateau-like surfaces abrade less).
//!
//! φ_c(T) = 10^(γ·(log a_T(60 °C) − log a_T(T))) through the compound's WLF
//! shift (Grosch: abrasion follows the rubber's reduced viscoelastic state)
//! when the compound files are given; otherwise exp(β·(T − 60 °C)), its
//! log-linear approximation. Calibrated on the training events by least
//! squares: γ (or β) and s on a grid, the k in closed form for each pair.
//! Without an energy map the factor uses the run's mean surface temperature.

use super::candidates::LawRow;
use super::stats::{CensoredNormal, KaplanMeier};
use crate::ingest::compound::Wlf;
use crate::kpi::KpiRow;
use crate::kpi::energy_maps::EnergyMaps;
use std::collections::BTreeMap;

/// Temperature of the law's reference state (°C).
pub(crate) const REFERENCE_C: f64 = 60.0;
const BETA_GRID: (f64, f64, usize) = (-0.05, 0.0025, 81); // −0.05 ..= 0.15 1/K
const GAMMA_GRID: (f64, f64, usize) = (-0.2, 0.005, 141); // −0.2 ..= 0.5
const SKEW_GRID: (f64, f64, usize) = (-0.5, 0.025, 41); // −0.5 ..= 0.5

/// The temperature factor φ of the law.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum TemperatureFactor {
    /// exp(β·(T − 60 °C)), β in 1/K.
    Exponential { beta_per_k: f64 },
    /// 10^(γ·(log a_T(60 °C) − log a_T(T))) with each compound's WLF constants.
    Wlf {
        gamma: f64,
        wlf: BTreeMap<String, Wlf>,
    },
}

impl TemperatureFactor {
    /// φ of `compound` at `t_c` (NaN for a compound without WLF constants).
    pub fn at(&self, compound: &str, t_c: f64) -> f64 {
        match self {
            TemperatureFactor::Exponential { beta_per_k } => {
                (beta_per_k * (t_c - REFERENCE_C)).exp()
            }
            TemperatureFactor::Wlf { gamma, wlf } => wlf.get(compound).map_or(f64::NAN, |w| {
                10f64.powf(gamma * (w.log10_shift(REFERENCE_C) - w.log10_shift(t_c)))
            }),
        }
    }

    /// ∂φ/∂(its parameter) of `compound` at `t_c` (γ for WLF, β for the exponential).
    pub(crate) fn derivative_at(&self, compound: &str, t_c: f64) -> f64 {
        match self {
            TemperatureFactor::Exponential { .. } => self.at(compound, t_c) * (t_c - REFERENCE_C),
            TemperatureFactor::Wlf { wlf, .. } => wlf.get(compound).map_or(f64::NAN, |w| {
                self.at(compound, t_c)
                    * std::f64::consts::LN_10
                    * (w.log10_shift(REFERENCE_C) - w.log10_shift(t_c))
            }),
        }
    }

    /// The calibrated parameter in words.
    pub(crate) fn describe(&self) -> String {
        match self {
            TemperatureFactor::Exponential { beta_per_k } => {
                format!("φ = exp(β(T − 60 °C)), β = {beta_per_k:.4} /K")
            }
            TemperatureFactor::Wlf { gamma, .. } => {
                format!(
                    "φ = (a_T(60 °C)/a_T(T))^γ by each compound's WLF constants, γ = {gamma:.3}"
                )
            }
        }
    }
}

/// A calibrated baseline.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PhysicsBaseline {
    /// % of tread per MJ of friction energy at the reference temperature on a
    /// road of zero skewness, per `compound/axle`.
    pub k_pct_per_mj: BTreeMap<String, f64>,
    pub temperature_factor: TemperatureFactor,
    /// s: the road factor is exp(s·skewness).
    pub skewness_coefficient: f64,
}

/// A row the law can be calibrated on: finite energy, temperature and skewness.
fn usable(r: &KpiRow) -> bool {
    r.friction_energy_j.is_finite() && r.t_surface_avg_c.is_finite() && r.skewness.is_finite()
}

/// Rounds of imputation and calibration in [`PhysicsBaseline::fit_censored`].
const BUCKLEY_JAMES_ROUNDS: usize = 5;

/// How a worn-through tire's wear beyond its lower bound is imputed from
/// the law's residuals (docs/gap.md, "Worn-through tires imputed").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CensoredTail {
    /// predicted · (1 + E[e | e > e_i]), the Kaplan–Meier mean of the
    /// relative residuals e = wear/predicted − 1 beyond the row's own: no
    /// assumption on their distribution, but no mass beyond the largest
    /// observed residual.
    KaplanMeier,
    /// predicted · E[exp r | r > r_i], r = ln(wear/predicted) normal with
    /// its mean and sd fitted by censored likelihood (a Tobit model of the
    /// log residuals): the scatter of wear as multiplicative, which reaches
    /// beyond the largest observed residual.
    LogNormal,
}

/// Each row's wear with the censored rows' imputed from `predicted` (%) as
/// `tail` says, from the residuals of every row (the censored ones as lower
/// bounds). One distribution for all rows, as Buckley–James assume: the
/// heavily worn tires, most of which wear through, show little beyond their
/// own lower bounds, so their tail is learnt from the rest (a window of the
/// rows nearest in predicted wear was tried: docs/gap.md, "Worn-through
/// tires imputed"). NaN where a censored row has no positive prediction.
pub fn impute_censored(
    rows: &[&KpiRow],
    censored: &[bool],
    predicted: &[f64],
    tail: CensoredTail,
) -> Vec<f64> {
    let wear: Vec<f64> = rows.iter().map(|r| r.wear_mean_pct).collect();
    impute_wear(&wear, censored, predicted, tail)
}

/// [`impute_censored`] on the rows' wear (%; a censored row's its lower
/// bound).
pub(crate) fn impute_wear(
    wear: &[f64],
    censored: &[bool],
    predicted: &[f64],
    tail: CensoredTail,
) -> Vec<f64> {
    let residual = |f: &dyn Fn(f64, f64) -> f64| -> Vec<f64> {
        wear.iter()
            .zip(predicted)
            .map(|(&y, &p)| if p > 0.0 { f(y, p) } else { f64::NAN })
            .collect()
    };
    // Each censored row's wear over its prediction, NaN where undefined.
    let tail_of = |x: &[f64], f: &dyn Fn(f64) -> f64| -> Vec<f64> {
        x.iter()
            .zip(censored)
            .map(|(&x, &c)| if c && x.is_finite() { f(x) } else { f64::NAN })
            .collect()
    };
    let factor = match tail {
        CensoredTail::LogNormal => {
            // ln of a non-positive wear is not finite: left out of the fit.
            let r = residual(&|y, p| (y / p).ln());
            match CensoredNormal::fit(&r, censored) {
                Some(d) => tail_of(&r, &|r| d.mean_exp_beyond(r)),
                None => {
                    return impute_wear(wear, censored, predicted, CensoredTail::KaplanMeier);
                }
            }
        }
        CensoredTail::KaplanMeier => {
            let e = residual(&|y, p| y / p - 1.0);
            let km = KaplanMeier::new(&e, censored);
            tail_of(&e, &|e| 1.0 + km.mean_beyond(e))
        }
    };
    wear.iter()
        .enumerate()
        .map(|(i, &y)| match censored[i] {
            false => y,
            true => Some(predicted[i] * factor[i])
                .filter(|v| v.is_finite())
                .unwrap_or(f64::NAN),
        })
        .collect()
}

/// The calibration group of a row: `compound/axle`.
pub fn group(r: &KpiRow) -> String {
    format!("{}/{}", r.compound, r.axle)
}

/// Temperature-weighted friction energy Σ E_b·φ(T_b) (MJ).
pub(crate) fn weighted_energy_mj(
    r: &KpiRow,
    maps: Option<&EnergyMaps>,
    phi: &TemperatureFactor,
) -> f64 {
    weighted_by(r, maps, &|t| phi.at(&r.compound, t))
}

/// Σ E_b·f(T_b) over the surface-temperature bins (MJ).
fn weighted_by(r: &KpiRow, maps: Option<&EnergyMaps>, f: &dyn Fn(f64) -> f64) -> f64 {
    match maps {
        Some(m) => m.weighted_surface_inner(|ts, _| f(ts)) / 1e6,
        None => r.friction_energy_j / 1e6 * f(r.t_surface_avg_c),
    }
}

/// The law's temperature-weighted energies Σ E_b·φ(T_b) of a set of rows
/// for every temperature factor of the calibration grid: they depend on the
/// rows and their maps, not on the wear, so a calibration repeated on other
/// wear (step 3's backfitting) reuses them.
pub struct LawGrid {
    laws: Vec<TemperatureFactor>,
    /// `energy_mj[law][row]`.
    energy_mj: Vec<Vec<f64>>,
}

impl LawGrid {
    /// The grid for `rows` (`maps[i]` belongs to `rows[i]`): WLF factors when
    /// `wlf` has every compound of the rows, else the exponential.
    pub fn new(
        rows: &[&KpiRow],
        maps: &[Option<&EnergyMaps>],
        wlf: &BTreeMap<String, Wlf>,
    ) -> LawGrid {
        let use_wlf = !wlf.is_empty() && rows.iter().all(|r| wlf.contains_key(&r.compound));
        let laws: Vec<TemperatureFactor> = if use_wlf {
            (0..GAMMA_GRID.2)
                .map(|i| TemperatureFactor::Wlf {
                    gamma: GAMMA_GRID.0 + GAMMA_GRID.1 * i as f64,
                    wlf: wlf.clone(),
                })
                .collect()
        } else {
            (0..BETA_GRID.2)
                .map(|i| TemperatureFactor::Exponential {
                    beta_per_k: BETA_GRID.0 + BETA_GRID.1 * i as f64,
                })
                .collect()
        };
        let energy_mj = laws
            .iter()
            .map(|law| {
                rows.iter()
                    .zip(maps)
                    .map(|(r, m)| weighted_energy_mj(r, *m, law))
                    .collect()
            })
            .collect();
        LawGrid { laws, energy_mj }
    }
}

impl PhysicsBaseline {
    /// Calibrates on rows with finite wear, energy, temperature and skewness;
    /// `maps[i]` belongs to `rows[i]`. With WLF constants for every compound
    /// the factor is the WLF one, else the exponential.
    pub fn fit(
        rows: &[&KpiRow],
        maps: &[Option<&EnergyMaps>],
        wlf: &BTreeMap<String, Wlf>,
    ) -> PhysicsBaseline {
        let ok: Vec<usize> = (0..rows.len())
            .filter(|&i| rows[i].wear_mean_pct.is_finite() && usable(rows[i]))
            .collect();
        let ok_rows: Vec<&KpiRow> = ok.iter().map(|&i| rows[i]).collect();
        let ok_maps: Vec<Option<&EnergyMaps>> = ok.iter().map(|&i| maps[i]).collect();
        let grid = LawGrid::new(&ok_rows, &ok_maps, wlf);
        let y: Vec<f64> = ok_rows.iter().map(|r| r.wear_mean_pct).collect();
        PhysicsBaseline::fit_grid(&grid, &ok_rows, &y)
    }

    /// Calibrates on rows some of whose wear is censored (`censored[i]`: the
    /// tire wore through, so its wear is at least `wear_mean_pct`), by
    /// Buckley–James regression on the law's scale: calibrated on the
    /// measured rows, each censored row's wear is imputed as the law's
    /// prediction times the mean of the residuals' distribution beyond its
    /// own lower bound ([`impute_censored`] with `tail`), and the law is
    /// calibrated again on every row, [`BUCKLEY_JAMES_ROUNDS`] times. Leaving worn-through tires
    /// out selects on the residual: the tires that wore most for their
    /// energy go, which biases wear per joule down where wear is high and
    /// hides an effect's strongest tires. Returns the law and each row's wear
    /// (the censored ones imputed; NaN where the law has no prediction).
    pub fn fit_censored(
        rows: &[&KpiRow],
        maps: &[Option<&EnergyMaps>],
        wlf: &BTreeMap<String, Wlf>,
        censored: &[bool],
        tail: CensoredTail,
    ) -> (PhysicsBaseline, Vec<f64>) {
        // The rows `fit` would calibrate on, and the censored ones beside.
        let ok: Vec<usize> = (0..rows.len())
            .filter(|&i| (censored[i] || rows[i].wear_mean_pct.is_finite()) && usable(rows[i]))
            .collect();
        let ok_rows: Vec<&KpiRow> = ok.iter().map(|&i| rows[i]).collect();
        let ok_maps: Vec<Option<&EnergyMaps>> = ok.iter().map(|&i| maps[i]).collect();
        let ok_censored: Vec<bool> = ok.iter().map(|&i| censored[i]).collect();
        let grid = LawGrid::new(&ok_rows, &ok_maps, wlf);
        let mut y: Vec<f64> = ok_rows
            .iter()
            .zip(&ok_censored)
            .map(|(r, &c)| if c { f64::NAN } else { r.wear_mean_pct })
            .collect();
        let mut law = PhysicsBaseline::fit_grid(&grid, &ok_rows, &y);
        if ok_censored.contains(&true) {
            for _ in 0..BUCKLEY_JAMES_ROUNDS {
                let predicted: Vec<f64> = ok_rows
                    .iter()
                    .zip(&ok_maps)
                    .map(|(r, m)| law.predict(r, *m))
                    .collect();
                y = impute_censored(&ok_rows, &ok_censored, &predicted, tail);
                law = PhysicsBaseline::fit_grid(&grid, &ok_rows, &y);
            }
        }
        let mut wear: Vec<f64> = rows
            .iter()
            .zip(censored)
            .map(|(r, &c)| if c { f64::NAN } else { r.wear_mean_pct })
            .collect();
        for (&i, v) in ok.iter().zip(&y) {
            wear[i] = *v;
        }
        (law, wear)
    }

    /// Calibrates on `y` (% per row) with the precomputed [`LawGrid`] of the
    /// same `rows`: γ (or β) and s on their grids, the k per group in closed
    /// form. Rows with a non-finite wear, energy, temperature or skewness are
    /// left out.
    pub(crate) fn fit_grid(grid: &LawGrid, rows: &[&KpiRow], y: &[f64]) -> PhysicsBaseline {
        let ok: Vec<usize> = (0..rows.len())
            .filter(|&i| y[i].is_finite() && usable(rows[i]))
            .collect();
        let names: Vec<String> = ok.iter().map(|&i| group(rows[i])).collect();
        let mut levels = names.clone();
        levels.sort();
        levels.dedup();
        let of: Vec<usize> = names
            .iter()
            .map(|g| levels.binary_search(g).expect("listed"))
            .collect();
        // exp(s·Sk) of each row for each s of the grid.
        let road: Vec<Vec<f64>> = (0..SKEW_GRID.2)
            .map(|si| {
                let s = SKEW_GRID.0 + SKEW_GRID.1 * si as f64;
                ok.iter().map(|&i| (s * rows[i].skewness).exp()).collect()
            })
            .collect();
        // (SSE, k per group, law index, s index)
        let mut best = (f64::INFINITY, Vec::new(), 0, 0);
        let mut sums = vec![(0.0, 0.0, 0.0); levels.len()];
        for (li, energy) in grid.energy_mj.iter().enumerate() {
            for (si, road) in road.iter().enumerate() {
                sums.fill((0.0, 0.0, 0.0));
                for ((&i, &g), f) in ok.iter().zip(&of).zip(road) {
                    let x = energy[i] * f;
                    let e = &mut sums[g];
                    e.0 += x * y[i];
                    e.1 += x * x;
                    e.2 += y[i] * y[i];
                }
                // SSE of the closed-form k per group: Σy² − (Σxy)²/Σx².
                let sse: f64 = sums.iter().map(|(xy, xx, yy)| yy - xy * xy / xx).sum();
                if sse < best.0 {
                    let k = sums.iter().map(|(xy, xx, _)| xy / xx).collect();
                    best = (sse, k, li, si);
                }
            }
        }
        PhysicsBaseline {
            k_pct_per_mj: levels.into_iter().zip(best.1).collect(),
            temperature_factor: grid.laws[best.2].clone(),
            skewness_coefficient: SKEW_GRID.0 + SKEW_GRID.1 * best.3 as f64,
        }
    }

    /// The law's energy term of a row, before its group's k (MJ).
    pub(crate) fn energy_term(&self, r: &KpiRow, maps: Option<&EnergyMaps>) -> f64 {
        weighted_energy_mj(r, maps, &self.temperature_factor)
            * (self.skewness_coefficient * r.skewness).exp()
    }

    /// The law's abrasion per joule of a row at the reference temperature,
    /// k_{c,a}·exp(s·Sk) (% per MJ); NaN for a group not seen in calibration.
    pub fn abrasion(&self, r: &KpiRow) -> f64 {
        self.k_pct_per_mj.get(&group(r)).map_or(f64::NAN, |k| {
            k * (self.skewness_coefficient * r.skewness).exp()
        })
    }

    /// What the law says about one row, each part computed once.
    pub(crate) fn law_row(&self, r: &KpiRow, maps: Option<&EnergyMaps>) -> LawRow {
        let energy_mj = self.energy_term(r, maps);
        let k = self
            .k_pct_per_mj
            .get(&group(r))
            .copied()
            .unwrap_or(f64::NAN);
        LawRow {
            abrasion: k * (self.skewness_coefficient * r.skewness).exp(),
            energy_mj,
            wear_pct: k * energy_mj,
        }
    }

    /// Predicted mean wear (%); NaN for a compound and axle not seen in calibration.
    pub fn predict(&self, r: &KpiRow, maps: Option<&EnergyMaps>) -> f64 {
        self.k_pct_per_mj
            .get(&group(r))
            .map_or(f64::NAN, |k| k * self.energy_term(r, maps))
    }

    /// The law as design columns, one per calibration group (the term in its
    /// group's column, zero elsewhere), then its derivatives with respect to
    /// the temperature parameter and s times the k's (the law linearised
    /// around its calibration), so later steps refit the k's, γ and s
    /// together with candidate terms: an effect the calibration soaked into
    /// γ or s is given back when its own term is present.
    pub fn columns(&self, rows: &[&KpiRow], maps: &[Option<&EnergyMaps>]) -> Vec<Vec<f64>> {
        let groups: Vec<&String> = self.k_pct_per_mj.keys().collect();
        let mut cols = vec![vec![0.0; rows.len()]; groups.len() + 2];
        let phi = &self.temperature_factor;
        for (i, r) in rows.iter().enumerate() {
            let g = group(r);
            if let Some(j) = groups.iter().position(|k| **k == g) {
                let road = (self.skewness_coefficient * r.skewness).exp();
                let term = self.energy_term(r, maps[i]);
                let k = self.k_pct_per_mj[&g];
                cols[j][i] = term;
                cols[groups.len()][i] =
                    k * road * weighted_by(r, maps[i], &|t| phi.derivative_at(&r.compound, t));
                cols[groups.len() + 1][i] = k * term * r.skewness;
            }
        }
        cols
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Axle;

    #[test]
    fn recovers_a_planted_law() {
        // wear = k·E·exp(0.03(T − 60))·exp(0.2·Sk), k = 1.5 (soft front), 0.8
        // (hard rear): exact recovery, β and s on their grids.
        let rows: Vec<KpiRow> = (0..40)
            .map(|i| {
                let (c, a, k) = if i % 2 == 0 {
                    ("soft", Axle::Front, 1.5)
                } else {
                    ("hard", Axle::Rear, 0.8)
                };
                let e = 5.0 + i as f64;
                let t = 50.0 + (i % 7) as f64 * 6.0;
                let sk = -1.0 + 0.1 * (i % 9) as f64;
                KpiRow {
                    compound: c.into(),
                    axle: a,
                    friction_energy_j: e * 1e6,
                    t_surface_avg_c: t,
                    skewness: sk,
                    wear_mean_pct: k * e * (0.03 * (t - 60.0)).exp() * (0.2 * sk).exp(),
                    ..Default::default()
                }
            })
            .collect();
        let refs: Vec<&KpiRow> = rows.iter().collect();
        let b = PhysicsBaseline::fit(&refs, &vec![None; refs.len()], &BTreeMap::new());
        assert_eq!(
            b.temperature_factor,
            TemperatureFactor::Exponential { beta_per_k: 0.03 }
        );
        assert!((b.skewness_coefficient - 0.2).abs() < 1e-9);
        assert!((b.k_pct_per_mj["soft/front"] - 1.5).abs() < 1e-9);
        assert!((b.k_pct_per_mj["hard/rear"] - 0.8).abs() < 1e-9);
    }

    #[test]
    fn worn_through_tires_imputed_remove_the_selection_bias() {
        // wear = E·(1 + ε) (k = 1 %/MJ), ε the 200 normal quantiles of sd
        // 0.2 in a scrambled order; a tire above 20 % reads 20 % and is
        // censored, 44 of 200. Left out, they take the tires that wore most
        // for their energy and k falls to 0.95; imputed, k is 1 within 1 %
        // with the Kaplan–Meier tail and within 1.5 % with the log-normal
        // one, whose upper tail is heavier than 1 + ε's (1.012).
        let (rows, censored) = censored_rows(|eps| 1.0 + eps, 20.0);
        assert_eq!(censored.iter().filter(|c| **c).count(), 44);
        let k_left_out = k_with(&rows, &censored, None);
        assert!(k_left_out < 0.96, "{k_left_out}");
        for (tail, tolerance) in [
            (CensoredTail::KaplanMeier, 0.01),
            (CensoredTail::LogNormal, 0.015),
        ] {
            let k = k_with(&rows, &censored, Some(tail));
            assert!((k - 1.0).abs() < tolerance, "{tail:?}: {k}");
        }
        // Log-normal scatter, exp(ε − σ²/2) (mean 1), read at 15 %: 90 of
        // 200 censored. Left out, k falls to 0.90; imputed, within 0.5 %
        // with either tail.
        let (rows, censored) = censored_rows(|eps| (eps - 0.02).exp(), 15.0);
        assert_eq!(censored.iter().filter(|c| **c).count(), 90);
        let k_left_out = k_with(&rows, &censored, None);
        assert!(k_left_out < 0.91, "{k_left_out}");
        for tail in [CensoredTail::KaplanMeier, CensoredTail::LogNormal] {
            let k = k_with(&rows, &censored, Some(tail));
            assert!((k - 1.0).abs() < 0.005, "{tail:?}: {k}");
        }
    }

    /// 200 rows of energy 5–24 MJ with wear = E·scatter(ε), ε the normal
    /// quantiles of sd 0.2 in a scrambled order, read at most `limit` %
    /// (and censored there).
    fn censored_rows(scatter: impl Fn(f64) -> f64, limit: f64) -> (Vec<KpiRow>, Vec<bool>) {
        let normal = statrs::distribution::Normal::new(0.0, 0.2).unwrap();
        let n = 200;
        let rows: Vec<KpiRow> = (0..n)
            .map(|i| {
                let q = (((i * 7) % n) as f64 + 0.5) / n as f64;
                let eps = statrs::distribution::ContinuousCDF::inverse_cdf(&normal, q);
                let e = 5.0 + (i % 20) as f64;
                KpiRow {
                    compound: "soft".into(),
                    axle: Axle::Front,
                    friction_energy_j: e * 1e6,
                    t_surface_avg_c: 60.0,
                    skewness: 0.0,
                    wear_mean_pct: (e * scatter(eps)).min(limit),
                    ..Default::default()
                }
            })
            .collect();
        let censored = rows.iter().map(|r| r.wear_mean_pct >= limit).collect();
        (rows, censored)
    }

    /// The law's k (%/MJ) with the censored rows left out (`None`) or
    /// imputed with `tail`; each imputed wear must lie beyond its reading.
    fn k_with(rows: &[KpiRow], censored: &[bool], tail: Option<CensoredTail>) -> f64 {
        let refs: Vec<&KpiRow> = rows.iter().collect();
        let maps = vec![None; rows.len()];
        let Some(tail) = tail else {
            let measured: Vec<&KpiRow> = refs
                .iter()
                .zip(censored)
                .filter(|(_, c)| !**c)
                .map(|(r, _)| *r)
                .collect();
            let law = PhysicsBaseline::fit(&measured, &maps[..measured.len()], &BTreeMap::new());
            return law.k_pct_per_mj["soft/front"];
        };
        let (law, wear) =
            PhysicsBaseline::fit_censored(&refs, &maps, &BTreeMap::new(), censored, tail);
        for ((r, w), c) in rows.iter().zip(&wear).zip(censored) {
            if *c {
                // Kaplan–Meier: the reading itself beyond the largest
                // measured residual.
                let beyond = *w > r.wear_mean_pct
                    || (tail == CensoredTail::KaplanMeier && *w == r.wear_mean_pct);
                assert!(beyond, "{tail:?}: {w}");
            } else {
                assert_eq!(*w, r.wear_mean_pct);
            }
        }
        law.k_pct_per_mj["soft/front"]
    }

    #[test]
    fn energy_map_weights_each_temperature_bin() {
        // 2 MJ at 62.5 °C and 1 MJ at 82.5 °C (bin midpoints), β = 0.01:
        // 2·e^0.025 + e^0.225 by hand.
        let mut m = EnergyMaps::new();
        m.add(61.0, 100.0, 1.0, 2e6);
        m.add(84.0, 100.0, 1.0, 1e6);
        let r = KpiRow::default();
        let phi = TemperatureFactor::Exponential { beta_per_k: 0.01 };
        let w = weighted_energy_mj(&r, Some(&m), &phi);
        assert!(
            (w - (2.0 * 0.025f64.exp() + 0.225f64.exp())).abs() < 1e-12,
            "{w}"
        );
    }

    #[test]
    fn wlf_factor_recovers_gamma() {
        // wear = 2·E·(a_T(60)/a_T(T))^0.17 with C1 8.86, C2 101.6 K, T_ref 50 °C:
        // the WLF law is chosen and γ found on its grid.
        let w = Wlf {
            c1: 8.86,
            c2_k: 101.6,
            t_ref_c: 50.0,
        };
        let rows: Vec<KpiRow> = (0..30)
            .map(|i| {
                let t = 40.0 + 3.0 * i as f64;
                let e = 4.0 + (i % 5) as f64;
                KpiRow {
                    compound: "soft".into(),
                    axle: Axle::Rear,
                    friction_energy_j: e * 1e6,
                    t_surface_avg_c: t,
                    wear_mean_pct: 2.0
                        * e
                        * 10f64.powf(0.17 * (w.log10_shift(60.0) - w.log10_shift(t))),
                    ..Default::default()
                }
            })
            .collect();
        let refs: Vec<&KpiRow> = rows.iter().collect();
        let wlf = BTreeMap::from([("soft".to_string(), w)]);
        let b = PhysicsBaseline::fit(&refs, &vec![None; refs.len()], &wlf);
        match &b.temperature_factor {
            TemperatureFactor::Wlf { gamma, .. } => assert!((gamma - 0.17).abs() < 1e-9),
            other => panic!("{other:?}"),
        }
        assert!((b.k_pct_per_mj["soft/rear"] - 2.0).abs() < 1e-9);
    }

    #[test]
    fn derivative_columns_match_finite_differences() {
        // The γ and s columns are k·∂term/∂γ and k·∂term/∂s: central differences agree.
        let w = Wlf {
            c1: 8.86,
            c2_k: 101.6,
            t_ref_c: 50.0,
        };
        let mut m = EnergyMaps::new();
        m.add(52.0, 90.0, 1.0, 2e6);
        m.add(88.0, 110.0, 1.0, 1e6);
        let r = KpiRow {
            compound: "soft".into(),
            axle: Axle::Front,
            skewness: -0.7,
            ..Default::default()
        };
        let wlf = BTreeMap::from([("soft".to_string(), w)]);
        let at = |gamma: f64, s: f64| PhysicsBaseline {
            k_pct_per_mj: BTreeMap::from([("soft/front".to_string(), 1.7)]),
            temperature_factor: TemperatureFactor::Wlf {
                gamma,
                wlf: wlf.clone(),
            },
            skewness_coefficient: s,
        };
        let b = at(0.17, 0.15);
        let cols = b.columns(&[&r], &[Some(&m)]);
        let h = 1e-6;
        let d_gamma = (at(0.17 + h, 0.15).predict(&r, Some(&m))
            - at(0.17 - h, 0.15).predict(&r, Some(&m)))
            / (2.0 * h);
        let d_s = (at(0.17, 0.15 + h).predict(&r, Some(&m))
            - at(0.17, 0.15 - h).predict(&r, Some(&m)))
            / (2.0 * h);
        assert!(
            (cols[1][0] - d_gamma).abs() < 1e-6 * d_gamma.abs(),
            "{} {d_gamma}",
            cols[1][0]
        );
        assert!(
            (cols[2][0] - d_s).abs() < 1e-6 * d_s.abs(),
            "{} {d_s}",
            cols[2][0]
        );
        assert!((1.7 * cols[0][0] - b.predict(&r, Some(&m))).abs() < 1e-12);
    }
}
