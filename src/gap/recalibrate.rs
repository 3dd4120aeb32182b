//! Step 3's refit of the physics law around the terms it selected.
//!
//! Scoring (step 2) needs the law as linear columns, so it linearises it
//! around its calibration: ∂/∂γ and ∂/∂s columns. That is exact enough for
//! ranking, not for predicting new events once a strong effect is in: the
//! calibration without the effect pulls γ and s far from where they belong
//! (planted blistering at magnitude 4 moved s from about 0 to −0.375), and
//! the tangent columns extrapolate badly to the testing tracks. So after a
//! term enters, the law is calibrated again, exactly as the baseline was
//! (γ and s on their grids, k in closed form), on the measured wear minus
//! the terms' wear; the terms are recomputed with that law (their charge is
//! the law's abrasion per joule) and refitted with its columns; and so on
//! until the calibration settles (backfitting). Measured on that season:
//! testing RMSE 4.61 % with the tangent columns, 2.86 % refitted (and one
//! term fewer), 2.0 % ideal.

use super::baseline::{CensoredTail, LawGrid, PhysicsBaseline, impute_wear};
use super::candidates::{Candidate, KpiScale, LawRow, candidate_feature};
use super::linear::weighted_fit;
use super::scoring::relative_weights;
use crate::ingest::compound::Wlf;
use crate::kpi::KpiRow;
use crate::kpi::energy_maps::EnergyMaps;
use std::collections::BTreeMap;

/// Most rounds of backfitting (the planted law of the unit test settles in
/// five).
const MAX_ROUNDS: usize = 10;

/// A term selected by step 3, at its threshold.
#[derive(Debug, Clone)]
pub(crate) struct Term {
    pub candidate: Candidate,
    pub threshold: f64,
    /// (mean, sd) standardising a generic KPI term.
    pub kpi_scale: KpiScale,
}

impl Term {
    /// The term's column over `rows` (`maps[i]`, `law[i]` belong to
    /// `rows[i]`): zero on the rows of the other axle.
    pub fn column(
        &self,
        rows: &[&KpiRow],
        maps: &[Option<&EnergyMaps>],
        law: &[LawRow],
    ) -> Vec<f64> {
        (0..rows.len())
            .map(|i| {
                candidate_feature(
                    &self.candidate,
                    rows[i],
                    maps[i],
                    self.threshold,
                    self.kpi_scale,
                    law[i],
                )
            })
            .collect()
    }
}

/// The rows of a diagnosis: training rows first, then testing rows.
pub struct Rows<'a> {
    pub rows: &'a [&'a KpiRow],
    pub maps: &'a [Option<&'a EnergyMaps>],
    /// Measured mean wear (%); a worn-through training tire's imputed.
    pub y: Vec<f64>,
    pub n_train: usize,
    /// The training rows' worn-through tires, imputed again from the model
    /// with its terms each round of [`refit_law`] (None: none imputed).
    pub censoring: Option<Censoring>,
}

/// Which training rows wore through and their lower bounds.
pub struct Censoring {
    /// Per training row: worn through (its wear imputed).
    pub worn: Vec<bool>,
    /// Per training row: the measured wear, a lower bound where worn.
    pub bound: Vec<f64>,
    pub tail: CensoredTail,
}

impl Rows<'_> {
    /// Buckley–James with the terms: the worn-through training rows' wear
    /// imputed again from `fitted` (the law and the terms), so that a tire
    /// an effect made wear through is imputed beyond the law's prediction
    /// for it, not from the law alone (docs/gap.md, "The named effects
    /// with tobit").
    fn impute_again(&mut self, fitted: &[f64]) {
        let Some(c) = &self.censoring else { return };
        let n = self.n_train;
        let y = impute_wear(&c.bound, &c.worn, &fitted[..n], c.tail);
        for (i, v) in y.into_iter().enumerate() {
            if c.worn[i] && v.is_finite() {
                self.y[i] = v;
            }
        }
    }
}

/// The law and the terms fitted together.
#[derive(Debug, Clone)]
pub(crate) struct Refitted {
    /// The law recalibrated around the terms.
    pub law: PhysicsBaseline,
    /// What that law says about each row (the terms' charges).
    pub law_rows: Vec<LawRow>,
    /// The law's columns (`PhysicsBaseline::columns`), then one per term.
    pub columns: Vec<Vec<f64>>,
    /// Relative-scale row weights of the training rows.
    pub weights: Vec<f64>,
    /// Coefficients of `columns`, fitted on the training rows.
    pub coefficients: Vec<f64>,
    /// Fitted wear (%) of every row.
    pub fitted: Vec<f64>,
    /// SSE (%²) on the training rows: the law's own calibration criterion.
    sse: f64,
}

/// What `law` says about each row.
pub(crate) fn law_rows(law: &PhysicsBaseline, d: &Rows) -> Vec<LawRow> {
    d.rows
        .iter()
        .zip(d.maps)
        .map(|(r, m)| law.law_row(r, *m))
        .collect()
}

/// The terms and `law`'s columns fitted on the training rows, on the
/// relative scale (weights from the law's columns and the terms).
fn fit_terms(law: PhysicsBaseline, terms: &[Term], d: &Rows) -> Refitted {
    let law_rows = law_rows(&law, d);
    let mut columns = law.columns(d.rows, d.maps);
    for t in terms {
        columns.push(t.column(d.rows, d.maps, &law_rows));
    }
    let train: Vec<usize> = (0..d.n_train).collect();
    let weights = relative_weights(
        &columns
            .iter()
            .map(|c| c[..d.n_train].to_vec())
            .collect::<Vec<_>>(),
        &d.y[..d.n_train],
    );
    let (coefficients, fitted) = weighted_fit(&columns, &weights, &d.y, &train);
    let sse = train.iter().map(|&i| (d.y[i] - fitted[i]).powi(2)).sum();
    Refitted {
        law,
        law_rows,
        columns,
        weights,
        coefficients,
        fitted,
        sse,
    }
}

/// Same γ (or β) and s, and every k within a relative 1e-6: the terms'
/// charges (k·exp(s·Sk)) would not move.
fn settled(a: &PhysicsBaseline, b: &PhysicsBaseline) -> bool {
    a.temperature_factor == b.temperature_factor
        && a.skewness_coefficient == b.skewness_coefficient
        && a.k_pct_per_mj.iter().all(|(g, k)| {
            b.k_pct_per_mj
                .get(g)
                .is_some_and(|kb| (k - kb).abs() <= 1e-6 * k.abs())
        })
}

/// Backfitting from `start`: calibrate the law on the wear minus the
/// terms' wear, refit the terms with it, until the calibration settles.
/// The round with the smallest training SSE is kept (a law that hops
/// between two neighbouring grid points does not settle).
pub(crate) fn refit_law(
    start: &PhysicsBaseline,
    terms: &[Term],
    d: &mut Rows,
    wlf: &BTreeMap<String, Wlf>,
) -> Refitted {
    let mut current = fit_terms(start.clone(), terms, d);
    let mut best = current.clone();
    let n_law = current.columns.len() - terms.len();
    let (rows, maps) = (d.rows, d.maps);
    let train = &rows[..d.n_train];
    let grid = LawGrid::new(train, &maps[..d.n_train], wlf);
    if d.censoring.is_some() {
        // The wear moves with the model: iterate to the fixed point and
        // keep it (SSEs on different wear do not compare).
        for _ in 0..MAX_ROUNDS {
            d.impute_again(&current.fitted);
            let wear_less_terms = wear_less_terms(&current, n_law, d);
            let law = PhysicsBaseline::fit_grid(&grid, train, &wear_less_terms);
            let again = settled(&law, &current.law);
            current = fit_terms(law, terms, d);
            if again {
                break;
            }
        }
        return current;
    }
    for _ in 0..MAX_ROUNDS {
        let wear_less_terms = wear_less_terms(&current, n_law, d);
        let law = PhysicsBaseline::fit_grid(&grid, train, &wear_less_terms);
        if settled(&law, &current.law) {
            break;
        }
        current = fit_terms(law, terms, d);
        if current.sse < best.sse {
            best = current.clone();
        }
    }
    best
}

/// The training rows' wear less the terms' wear (%): what the law is
/// calibrated on.
fn wear_less_terms(current: &Refitted, n_law: usize, d: &Rows) -> Vec<f64> {
    (0..d.n_train)
        .map(|i| {
            let terms_wear: f64 = (n_law..current.columns.len())
                .map(|j| current.coefficients[j] * current.columns[j][i])
                .sum();
            d.y[i] - terms_wear
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::baseline::TemperatureFactor;
    use crate::gap::candidates::library;

    #[test]
    fn recovers_a_planted_law_and_term_from_a_wrong_calibration() {
        // wear = k·exp(s·Sk)·[Σ_b E_b·exp(β(T_b − 60)) + c·E_hot] with
        // β = 0.03 /K, s = 0.2, c = 0.5, k = 1.5 (soft front) and 0.8 (hard
        // rear); E_hot is the energy with the surface above 80 °C. The law
        // calibrated without the term is off; backfitting returns to the
        // planted law and c exactly (β and s on their grids).
        let (beta, s, c) = (BETA, SKEWNESS, 0.5);
        let (rows, maps, _) = planted_season(48, c, 0.0, f64::INFINITY);
        let refs: Vec<&KpiRow> = rows.iter().collect();
        let map_refs: Vec<Option<&EnergyMaps>> = maps.iter().map(Some).collect();
        let y: Vec<f64> = rows.iter().map(|r| r.wear_mean_pct).collect();
        let no_wlf = BTreeMap::new();
        let start = PhysicsBaseline::fit(&refs, &map_refs, &no_wlf);
        assert_ne!(
            start.temperature_factor,
            TemperatureFactor::Exponential { beta_per_k: beta }
        );
        let terms = [thermal_term(&refs)];
        let mut d = Rows {
            rows: &refs,
            maps: &map_refs,
            y,
            n_train: refs.len(),
            censoring: None,
        };
        let r = refit_law(&start, &terms, &mut d, &no_wlf);
        assert_eq!(
            r.law.temperature_factor,
            TemperatureFactor::Exponential { beta_per_k: beta }
        );
        assert!((r.law.skewness_coefficient - s).abs() < 1e-9);
        assert!((r.law.k_pct_per_mj["soft/front"] - 1.5).abs() < 1e-6);
        let term_c = r.coefficients[r.coefficients.len() - 1];
        assert!((term_c - c).abs() < 1e-6, "{term_c}");
        let worst = (0..d.y.len())
            .map(|i| (d.y[i] - r.fitted[i]).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-6, "{worst}");
    }

    /// The planted law's β (/K) and s.
    const BETA: f64 = 0.03;
    const SKEWNESS: f64 = 0.2;

    /// `n` rows whose wear is the planted law (β, s; k = 1.5 soft front,
    /// 0.8 hard rear) and thermal term c·E_hot, times a log-normal scatter
    /// (sd `scatter`, seeded), each row's hot energy 0–3 MJ; wear above
    /// `limit` reads as the limit (worn through, flagged).
    fn planted_season(
        n: usize,
        c: f64,
        scatter: f64,
        limit: f64,
    ) -> (Vec<KpiRow>, Vec<EnergyMaps>, Vec<bool>) {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let (mut rows, mut maps, mut worn) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..n {
            let (compound, axle, k) = if i % 2 == 0 {
                ("soft", crate::Axle::Front, 1.5)
            } else {
                ("hard", crate::Axle::Rear, 0.8)
            };
            let cool_mj = 4.0 + (i % 5) as f64;
            let warm_mj = 1.0 + (i % 4) as f64;
            let hot_mj = 0.5 * (i % 7) as f64;
            let sk = -1.0 + 0.1 * (i % 9) as f64;
            let mut m = EnergyMaps::new();
            m.add(61.0, 90.0, 1.0, cool_mj * 1e6); // surface bin 60–65 °C
            m.add(76.0, 100.0, 1.0, warm_mj * 1e6); // surface bin 75–80 °C
            m.add(91.0, 110.0, 1.0, hot_mj * 1e6); // surface bin 90–95 °C
            let phi = |t: f64| (BETA * (t - 60.0)).exp();
            let law = cool_mj * phi(62.5) + warm_mj * phi(77.5) + hot_mj * phi(92.5);
            let z: f64 = StandardNormal.sample(&mut rng);
            let wear = k * (SKEWNESS * sk).exp() * (law + c * hot_mj) * (scatter * z).exp();
            worn.push(wear > limit);
            rows.push(KpiRow {
                compound: compound.into(),
                axle,
                track: format!("t{}", i % 6),
                friction_energy_j: (cool_mj + warm_mj + hot_mj) * 1e6,
                t_surface_avg_c: 70.0,
                skewness: sk,
                wear_mean_pct: wear.min(limit),
                ..Default::default()
            });
            maps.push(m);
        }
        (rows, maps, worn)
    }

    /// Thermal degradation at 80 °C, the planted term.
    fn thermal_term(rows: &[&KpiRow]) -> Term {
        let thermal = library(rows)
            .into_iter()
            .find(|c| c.name == "thermal degradation (energy with a hot surface)")
            .expect("thermal candidate");
        Term {
            candidate: thermal,
            threshold: 80.0,
            kpi_scale: KpiScale::NONE,
        }
    }

    #[test]
    fn worn_through_tires_are_imputed_again_with_the_terms() {
        // The hot tires wear most and wear through most (a third of the
        // tires here). The reference is the term fitted on the same tires
        // read without a limit (2.36 on this sample where 2 is planted: β
        // and s lie on grids and the scatter is drawn). Imputed once from
        // the law alone (what step 3 kept before) the term comes out 15 %
        // low, left out 13 % low; imputed again from the law and the term
        // each round (Buckley–James with the term) within 1 %.
        let (c, limit) = (2.0, 20.0);
        let (rows, maps, worn) = planted_season(400, c, 0.15, limit);
        let share = worn.iter().filter(|&&w| w).count() as f64 / worn.len() as f64;
        assert!((0.15..0.5).contains(&share), "{share}");
        let refs: Vec<&KpiRow> = rows.iter().collect();
        let map_refs: Vec<Option<&EnergyMaps>> = maps.iter().map(Some).collect();
        let no_wlf = BTreeMap::new();
        let tail = CensoredTail::LogNormal;
        let (law, y) = PhysicsBaseline::fit_censored(&refs, &map_refs, &no_wlf, &worn, tail);
        let terms = [thermal_term(&refs)];
        let term_c = |censoring: Option<Censoring>| {
            let mut d = Rows {
                rows: &refs,
                maps: &map_refs,
                y: y.clone(),
                n_train: refs.len(),
                censoring,
            };
            let r = refit_law(&law, &terms, &mut d, &no_wlf);
            r.coefficients[r.coefficients.len() - 1]
        };
        let once = term_c(None);
        let again = term_c(Some(Censoring {
            worn: worn.clone(),
            bound: rows.iter().map(|r| r.wear_mean_pct).collect(),
            tail,
        }));
        // The term fitted with the law on measured wear, on a selection.
        let uncensored = |rows: &[KpiRow], maps: &[EnergyMaps], keep: &dyn Fn(usize) -> bool| {
            let kept: Vec<usize> = (0..rows.len()).filter(|&i| keep(i)).collect();
            let refs: Vec<&KpiRow> = kept.iter().map(|&i| &rows[i]).collect();
            let map_refs: Vec<Option<&EnergyMaps>> = kept.iter().map(|&i| Some(&maps[i])).collect();
            let law = PhysicsBaseline::fit(&refs, &map_refs, &no_wlf);
            let mut d = Rows {
                rows: &refs,
                maps: &map_refs,
                y: refs.iter().map(|r| r.wear_mean_pct).collect(),
                n_train: refs.len(),
                censoring: None,
            };
            let r = refit_law(&law, &terms, &mut d, &no_wlf);
            r.coefficients[r.coefficients.len() - 1]
        };
        let full = {
            let (rows, maps, _) = planted_season(400, c, 0.15, f64::INFINITY);
            uncensored(&rows, &maps, &|_| true)
        };
        let left_out = uncensored(&rows, &maps, &|i| !worn[i]);
        let off = |x: f64| (x / full - 1.0).abs();
        assert!(
            off(again) < 0.02,
            "imputed again: {again}, without a limit: {full}"
        );
        assert!(
            off(once) > 0.1,
            "imputed once: {once}, without a limit: {full}"
        );
        assert!(
            off(left_out) > 0.1,
            "left out: {left_out}, without a limit: {full}"
        );
    }
}
