//! Scoring one diagnosed season against its truth: the planted wear per
//! tire, the ideal diagnosis (the law calibrated on wear minus the planted
//! part), hit, shrinkage and the terms' correlation with the planted wear.

use super::{AgainstTruth, Case, HypothesisOutcome, Planted, ValidateError};
use crate::gap::report::{Baseline, Diagnosis, GapSettings, diagnose};
use crate::kpi::{KpiRow, TireRun};
use crate::sim::GeneratedEffect;
use std::collections::BTreeMap;
use std::path::Path;

/// What a season's truth says of each tire (`read_planted`).
#[derive(Debug)]
pub(crate) struct PlantedWear {
    /// Planted wear (%) per (run, wheel).
    pub wear: BTreeMap<TireRun, f64>,
    /// Each tire's wear scatter factor, already in `wear` (None for a
    /// season simulated before `truth/wear_truth.csv` had the column).
    pub scatter_factors: Option<BTreeMap<TireRun, f64>>,
    /// Each tire's true mean wear (%, `wear_total_pct`): without the
    /// gauge's error and not capped where the tread wore through (None
    /// for a truth without the column).
    pub true_wear: Option<BTreeMap<TireRun, f64>>,
}

/// Planted wear (%) per (run, wheel) from `truth/wear_truth.csv`: the
/// column `wear_<column>_pct` (None: zero); each tire's wear scatter
/// factor (`wear_scatter_factor`) and true wear (`wear_total_pct`) where
/// the file has them.
pub(super) fn read_planted(
    truth: &Path,
    column: Option<&str>,
) -> Result<PlantedWear, ValidateError> {
    let file = truth.display().to_string();
    let mut rd = csv::Reader::from_path(truth).map_err(|e| ValidateError::Truth {
        file: file.clone(),
        line: 0,
        message: e.to_string(),
    })?;
    let headers = rd
        .headers()
        .map_err(|e| ValidateError::Truth {
            file: file.clone(),
            line: 1,
            message: e.to_string(),
        })?
        .clone();
    let col = |name: &str| {
        headers
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| ValidateError::Truth {
                file: file.clone(),
                line: 1,
                message: format!("no column '{name}'"),
            })
    };
    let (run, wheel) = (col("run")?, col("wheel")?);
    let effect = match column {
        Some(k) => Some(col(&format!("wear_{}_pct", k.replace('-', "_")))?),
        None => None,
    };
    let factor_col = headers.iter().position(|h| h == "wear_scatter_factor");
    let total_col = headers.iter().position(|h| h == "wear_total_pct");
    let mut out = BTreeMap::new();
    let mut factors = BTreeMap::new();
    let mut totals = BTreeMap::new();
    for (i, rec) in rd.records().enumerate() {
        let rec = rec.map_err(|e| ValidateError::Truth {
            file: file.clone(),
            line: i + 2,
            message: e.to_string(),
        })?;
        let number = |c: usize| {
            rec[c].parse::<f64>().map_err(|_| ValidateError::Truth {
                file: file.clone(),
                line: i + 2,
                message: format!("{} '{}' is not a number", &headers[c], &rec[c]),
            })
        };
        let v = match effect {
            Some(c) => number(c)?,
            None => 0.0,
        };
        let w = rec[wheel].parse().map_err(|_| ValidateError::Truth {
            file: file.clone(),
            line: i + 2,
            message: format!("wheel '{}' is not FL, FR, RL or RR", &rec[wheel]),
        })?;
        if let Some(c) = factor_col {
            // Every planted wear is divided by it.
            let f = number(c)?;
            if !(f.is_finite() && f > 0.0) {
                return Err(ValidateError::Truth {
                    file: file.clone(),
                    line: i + 2,
                    message: format!("wear_scatter_factor {f} is not a positive number"),
                });
            }
            factors.insert((rec[run].to_string(), w), f);
        }
        if let Some(c) = total_col {
            totals.insert((rec[run].to_string(), w), number(c)?);
        }
        out.insert((rec[run].to_string(), w), v);
    }
    Ok(PlantedWear {
        wear: out,
        scatter_factors: factor_col.map(|_| factors),
        true_wear: total_col.map(|_| totals),
    })
}

fn variance(v: &[f64]) -> f64 {
    let m = v.iter().sum::<f64>() / v.len() as f64;
    v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() as f64 - 1.0)
}

/// Scores a diagnosis of `rows` against the planted wear.
pub(crate) fn score_case(
    planted_kind: &Planted,
    seed: u64,
    rows: &[KpiRow],
    maps: &BTreeMap<TireRun, crate::kpi::energy_maps::EnergyMaps>,
    truth: &PlantedWear,
    d: &Diagnosis,
    gap: &GapSettings,
) -> Result<Case, ValidateError> {
    let planted = &truth.wear;
    let planted_of = |r: &KpiRow| planted.get(&r.tire_run()).copied().unwrap_or(0.0);
    let p: Vec<f64> = rows.iter().map(planted_of).collect();
    // The planted wear the telemetry predicts: without the tire's scatter
    // factor, which multiplies every part of its wear and no term can know.
    let expected: Option<Vec<f64>> = truth.scatter_factors.as_ref().and_then(|f| {
        rows.iter()
            .zip(&p)
            .map(|(r, v)| f.get(&r.tire_run()).map(|f| v / f))
            .collect()
    });
    // The variance share over the tires the diagnosis keeps: a worn-through
    // tire's measured wear is capped while its planted wear is not.
    let (p_kept, w_kept): (Vec<f64>, Vec<f64>) = rows
        .iter()
        .zip(&p)
        .filter(|(r, _)| r.worn_through_readings <= 0.0)
        .map(|(r, v)| (*v, r.wear_mean_pct))
        .unzip();
    let total: f64 = p.iter().sum();
    let front: f64 = rows
        .iter()
        .zip(&p)
        .filter(|(r, _)| r.axle == crate::Axle::Front)
        .map(|(_, v)| v)
        .sum();
    let law_alone = |y: &[f64]| law_alone(rows, y, maps, gap);
    // Ideal: the same baseline calibrated on wear minus the planted part,
    // the planted part then added back exactly.
    let cleaned: Vec<f64> = rows
        .iter()
        .zip(&p)
        .map(|(r, v)| r.wear_mean_pct - v)
        .collect();
    let (_, rmse_ideal) = law_alone(&cleaned)?;
    let (oracle_size, rmse_oracle) = if matches!(planted_kind, Planted::Clean) {
        (f64::NAN, f64::NAN)
    } else {
        exact_shape_sized(rows, &p, law_alone)?
    };
    let (expected_size, rmse_expected) = match &expected {
        Some(e) if !matches!(planted_kind, Planted::Clean) => {
            exact_shape_sized(rows, e, law_alone)?
        }
        _ => (f64::NAN, f64::NAN),
    };
    let rmse_base = d.testing.map_or(f64::NAN, |t| t.rmse_pct);
    let last = d.steps.last().expect("the baseline step");
    let rmse_diag = last.testing.map_or(f64::NAN, |t| t.rmse_pct);
    let first = d.steps.get(1);
    let first_score = first.and_then(|st| d.candidates.iter().find(|c| c.name == st.added));
    let first_mechanism = first_score
        .and_then(|c| c.feature.mechanism())
        .map(str::to_string);
    let first_front_share = first_score.map_or(f64::NAN, |c| c.front_share);
    let truth_front_share = front / total;
    let effect = match planted_kind {
        Planted::Named(e) => Some(e),
        _ => None,
    };
    let terms_correlation = terms_correlation(d, planted);
    let expected_sized = expected.as_deref().map(|e| (e, expected_size));
    let against_truth = against_truth(rows, maps, truth, &p, expected_sized, d, gap)?;
    let hit = match planted_kind {
        Planted::Named(e) => first_mechanism.as_deref() == Some(e.kind.name()),
        Planted::Generated(_) => terms_correlation >= 0.8,
        Planted::Clean => false,
    };
    Ok(Case {
        effect: effect.cloned(),
        generated: match planted_kind {
            Planted::Generated(g) => Some(g.clone()),
            _ => None,
        },
        seed,
        terms_correlation,
        variance_share: if !matches!(planted_kind, Planted::Clean) {
            variance(&p_kept) / variance(&w_kept)
        } else {
            0.0
        },
        truth_front_share,
        first_term: first.map(|s| s.added.clone()),
        first_set_up: first.is_some_and(|s| s.set_up),
        first_scope: first.and_then(|s| s.scope.clone()),
        leads_scope: crate::gap::render::leads_scope(d),
        first_mechanism,
        first_front_share,
        significant_terms: d.steps.len() - 1,
        hit,
        // A generated effect's scope is judged by the correlation itself.
        hit_axle: hit
            && (effect.is_none() || (first_front_share - truth_front_share).abs() <= 0.25),
        rmse_baseline_pct: rmse_base,
        rmse_diagnosed_pct: rmse_diag,
        rmse_ideal_pct: rmse_ideal,
        shrinkage_ratio: (rmse_base - rmse_diag) / (rmse_base - rmse_ideal),
        oracle_size,
        rmse_oracle_pct: rmse_oracle,
        oracle_shrinkage: (rmse_base - rmse_oracle) / (rmse_base - rmse_ideal),
        expected_size,
        rmse_expected_pct: rmse_expected,
        expected_shrinkage: (rmse_base - rmse_expected) / (rmse_base - rmse_ideal),
        against_truth,
        hypotheses: hypotheses(d, gap.fdr),
        error: None,
    })
}

/// The user's hypotheses among the diagnosis's first-round candidates.
fn hypotheses(d: &Diagnosis, fdr: f64) -> Vec<HypothesisOutcome> {
    d.candidates
        .iter()
        .filter(|c| c.feature == crate::gap::candidates::Feature::User)
        .map(|c| HypothesisOutcome {
            name: c.name.clone(),
            cv_gain: c.cv_gain,
            p_adjusted: c.p_adjusted,
            significant: c.significant(fdr),
            added_as: d.steps.iter().position(|s| s.added == c.name),
        })
        .collect()
}

/// The law alone calibrated on wear `y` (per row of `rows`): its
/// (training, testing) RMSE (%).
fn law_alone(
    rows: &[KpiRow],
    y: &[f64],
    maps: &BTreeMap<TireRun, crate::kpi::energy_maps::EnergyMaps>,
    gap: &GapSettings,
) -> Result<(f64, f64), ValidateError> {
    let rows: Vec<KpiRow> = rows
        .iter()
        .zip(y)
        .map(|(r, v)| KpiRow {
            wear_mean_pct: *v,
            ..r.clone()
        })
        .collect();
    let fit = diagnose(
        &rows,
        maps,
        &Baseline::Physics,
        &GapSettings {
            max_terms: 0,
            ..gap.clone()
        },
    )?;
    Ok((
        fit.training.rmse_pct,
        fit.testing.map_or(f64::NAN, |t| t.rmse_pct),
    ))
}

/// The testing events measured against every testing tire's true wear
/// (`PlantedWear::true_wear`), worn-through ones included (None where the
/// truth has no true wear or the diagnosis no testing events).
///
/// The diagnosis measures the testing events on the tires it can measure:
/// a worn-through tire's reading is only a lower bound, so it is left out,
/// and that measure favours a law biased low; it also carries the gauge's
/// error. Here the season is diagnosed again with each testing tire's wear
/// set to its true wear (the testing events fixed to the diagnosis's).
/// The training rows are untouched and the testing rows never enter a fit
/// or a choice, so the same terms are chosen (`same_terms` checks it) and
/// only the measure changes. The ideal and the expected shape are the
/// law's alone on the same rows, the latter (`expected`: the expected
/// shape per row and the size the training events chose for it,
/// `exact_shape_sized`) at that size.
fn against_truth(
    rows: &[KpiRow],
    maps: &BTreeMap<TireRun, crate::kpi::energy_maps::EnergyMaps>,
    truth: &PlantedWear,
    planted: &[f64],
    expected: Option<(&[f64], f64)>,
    d: &Diagnosis,
    gap: &GapSettings,
) -> Result<Option<AgainstTruth>, ValidateError> {
    let Some(true_wear) = &truth.true_wear else {
        return Ok(None);
    };
    if d.testing_events.is_empty() {
        return Ok(None);
    }
    let testing = |r: &KpiRow| d.testing_events.contains(&r.event);
    let (mut tires, mut worn) = (0, 0);
    let mut true_rows = Vec::with_capacity(rows.len());
    for r in rows {
        if !testing(r) {
            true_rows.push(r.clone());
            continue;
        }
        let wear = true_wear
            .get(&r.tire_run())
            .ok_or_else(|| ValidateError::Truth {
                file: "truth/wear_truth.csv".into(),
                line: 0,
                message: format!("no true wear of testing tire {}/{}", r.run, r.wheel),
            })?;
        tires += 1;
        worn += usize::from(r.worn_through_readings > 0.0);
        true_rows.push(KpiRow {
            wear_mean_pct: *wear,
            worn_through_readings: 0.0,
            ..r.clone()
        });
    }
    let gap = GapSettings {
        test_events: Some(d.testing_events.clone()),
        ..gap.clone()
    };
    let again = diagnose(&true_rows, maps, &Baseline::Physics, &gap)?;
    let added =
        |d: &Diagnosis| -> Vec<String> { d.steps.iter().map(|s| s.added.clone()).collect() };
    let rmse_base = again.testing.map_or(f64::NAN, |t| t.rmse_pct);
    let rmse_diag = again
        .steps
        .last()
        .and_then(|s| s.testing)
        .map_or(f64::NAN, |t| t.rmse_pct);
    // The law on the true wear less `c` times the planted part, which is
    // then added back.
    let law_at = |c: f64, part: &[f64]| -> Result<f64, ValidateError> {
        let y: Vec<f64> = true_rows
            .iter()
            .zip(part)
            .map(|(r, p)| r.wear_mean_pct - c * p)
            .collect();
        Ok(law_alone(&true_rows, &y, maps, &gap)?.1)
    };
    let rmse_ideal = law_at(1.0, planted)?;
    let rmse_expected = match expected {
        Some((e, size)) if size.is_finite() => law_at(size, e)?,
        _ => f64::NAN,
    };
    // The training events' worn-through tires as the baseline imputed them.
    let names: BTreeMap<String, TireRun> = rows
        .iter()
        .filter(|r| r.worn_through_readings > 0.0)
        .map(|r| (format!("{}/{}", r.run, r.wheel), r.tire_run()))
        .collect();
    let imputed_error: Vec<f64> = d
        .imputed
        .iter()
        .zip(&d.imputed_wear_pct)
        .filter_map(|(name, y)| Some(y - true_wear.get(names.get(name)?)?))
        .collect();
    let n = imputed_error.len() as f64;
    Ok(Some(AgainstTruth {
        imputed_tires: imputed_error.len(),
        imputed_bias_pct: imputed_error.iter().sum::<f64>() / n,
        imputed_rmse_pct: (imputed_error.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
        testing_tires: tires,
        testing_worn_through: worn,
        rmse_baseline_pct: rmse_base,
        rmse_diagnosed_pct: rmse_diag,
        rmse_ideal_pct: rmse_ideal,
        rmse_expected_pct: rmse_expected,
        shrinkage_ratio: (rmse_base - rmse_diag) / (rmse_base - rmse_ideal),
        expected_shrinkage: (rmse_base - rmse_expected) / (rmse_base - rmse_ideal),
        same_terms: added(&again) == added(d),
    }))
}

/// The best any term of the planted effect's exact shape can do when its
/// size is estimated, as a diagnosis must estimate it: the law calibrated
/// on the measured wear less c times the planted wear, c chosen by the
/// training events' RMSE (a grid of 0.25 on 0…3, then 0.025 within ±0.125
/// of the best), the planted wear then added back at that size. `fit(y)`:
/// the law calibrated on wear `y`, its (training, testing) RMSE (%).
/// Returns (c, testing RMSE). The ideal is this at c = 1, the size no
/// diagnosis can know; between the two lies what estimating the size costs,
/// between this and the diagnosis what the term's shape costs.
fn exact_shape_sized(
    rows: &[KpiRow],
    planted: &[f64],
    fit: impl Fn(&[f64]) -> Result<(f64, f64), ValidateError>,
) -> Result<(f64, f64), ValidateError> {
    let at = |c: f64| -> Result<(f64, f64), ValidateError> {
        let y: Vec<f64> = rows
            .iter()
            .zip(planted)
            .map(|(r, p)| r.wear_mean_pct - c * p)
            .collect();
        fit(&y)
    };
    let mut best = (0.0, at(0.0)?);
    // The coarse grid puts the best within ±0.125 of its step's best.
    for (step, reach) in [(0.25, 12), (0.025, 5)] {
        let centre = best.0;
        for i in -reach..=reach {
            let c = centre + step * i as f64;
            if !(0.0..=3.0).contains(&c) || i == 0 {
                continue;
            }
            let r = at(c)?;
            if r.0 < best.1.0 {
                best = (c, r);
            }
        }
    }
    Ok((best.0, best.1.1))
}

/// Pearson correlation of the wear the diagnosis's terms add with the
/// planted wear, over the tires diagnosed (0 without terms or without
/// variation in either).
fn terms_correlation(d: &Diagnosis, planted: &BTreeMap<TireRun, f64>) -> f64 {
    let (terms, truth): (Vec<f64>, Vec<f64>) = d
        .terms_wear
        .iter()
        .map(|t| {
            let p = planted
                .get(&(t.run.clone(), t.wheel))
                .copied()
                .unwrap_or(0.0);
            (t.wear_pct, p)
        })
        .unzip();
    // Too few tires or a constant side (no terms entered) is no match.
    let constant = |v: &[f64]| v.iter().all(|x| *x == v[0]);
    if terms.len() < 3 || constant(&terms) || constant(&truth) {
        return 0.0;
    }
    crate::model::data::correlation(&terms, &truth)
}

/// The generated effect as the simulator resolved it (`truth/settings.toml`).
pub(super) fn read_generated(settings: &Path) -> Result<GeneratedEffect, ValidateError> {
    let truth = |message: String| ValidateError::Truth {
        file: settings.display().to_string(),
        line: 0,
        message,
    };
    let text = std::fs::read_to_string(settings).map_err(|e| truth(e.to_string()))?;
    #[derive(serde::Deserialize)]
    struct Settings {
        generated: Option<GeneratedEffect>,
    }
    let s: Settings = toml::from_str(&text).map_err(|e| truth(e.to_string()))?;
    s.generated
        .ok_or_else(|| truth("no [generated] effect".into()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Wear = 3 % + 1.6 × planted: a "law" that fits a constant leaves a
    /// training RMSE of |1.6 − c| × sd(planted), smallest at c = 1.6, which
    /// the fine grid holds (1.5 + 4 × 0.025).
    #[test]
    fn the_exact_shape_is_sized_where_the_training_fit_is_best() {
        let planted = [0.0, 2.0, 5.0, 1.0, 4.0, 3.0];
        let rows: Vec<KpiRow> = planted
            .iter()
            .map(|p| KpiRow {
                wear_mean_pct: 3.0 + 1.6 * p,
                ..Default::default()
            })
            .collect();
        let sd = |y: &[f64]| {
            let m = y.iter().sum::<f64>() / y.len() as f64;
            (y.iter().map(|v| (v - m).powi(2)).sum::<f64>() / y.len() as f64).sqrt()
        };
        // Training: the first four rows; testing: the rest.
        let (c, testing) =
            exact_shape_sized(&rows, &planted, |y| Ok((sd(&y[..4]), sd(&y[4..])))).unwrap();
        assert!((c - 1.6).abs() < 1e-9, "{c}");
        assert!(testing < 1e-9, "{testing}");
        // Without the planted shape in the wear, the size found is 0.
        let flat: Vec<KpiRow> = rows
            .iter()
            .map(|r| KpiRow {
                wear_mean_pct: 3.0,
                ..r.clone()
            })
            .collect();
        let (c, _) =
            exact_shape_sized(&flat, &planted, |y| Ok((sd(&y[..4]), sd(&y[4..])))).unwrap();
        assert_eq!(c, 0.0);
    }

    /// The planted column, the scatter factors and the true wear, by run
    /// and wheel; a truth without those columns (an older season) gives
    /// none.
    #[test]
    fn planted_wear_and_scatter_factors_are_read_by_tire() {
        let dir = tempfile::tempdir().unwrap();
        let with = dir.path().join("with.csv");
        std::fs::write(
            &with,
            "run,wheel,wear_generated_pct,wear_total_pct,wear_scatter_factor\n\
             R1,FL,2.5,40,1.25\nR1,RR,0,30,0.8\n",
        )
        .unwrap();
        let truth = read_planted(&with, Some("generated")).unwrap();
        let key = |w: crate::Wheel| ("R1".to_string(), w);
        assert_eq!(truth.wear[&key(crate::Wheel::FL)], 2.5);
        assert_eq!(truth.wear[&key(crate::Wheel::RR)], 0.0);
        let factors = truth.scatter_factors.unwrap();
        assert_eq!(factors[&key(crate::Wheel::FL)], 1.25);
        assert_eq!(factors[&key(crate::Wheel::RR)], 0.8);
        let true_wear = truth.true_wear.unwrap();
        assert_eq!(true_wear[&key(crate::Wheel::FL)], 40.0);
        assert_eq!(true_wear[&key(crate::Wheel::RR)], 30.0);

        let without = dir.path().join("without.csv");
        std::fs::write(&without, "run,wheel,wear_generated_pct\nR1,FL,2.5\n").unwrap();
        let truth = read_planted(&without, Some("generated")).unwrap();
        assert_eq!(truth.wear.len(), 1);
        assert!(truth.scatter_factors.is_none());
        assert!(truth.true_wear.is_none());

        let bad = dir.path().join("bad.csv");
        std::fs::write(
            &bad,
            "run,wheel,wear_generated_pct,wear_scatter_factor\nR1,FL,2.5,x\n",
        )
        .unwrap();
        let e = read_planted(&bad, Some("generated"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("bad.csv, line 2:"), "{e}");
        assert!(e.contains("wear_scatter_factor"), "{e}");
        for f in ["0", "-1.2", "NaN", "inf"] {
            std::fs::write(
                &bad,
                format!(
                    "run,wheel,wear_generated_pct,wear_scatter_factor\nR1,FL,2.5,1\nR1,FR,1,{f}\n"
                ),
            )
            .unwrap();
            let e = read_planted(&bad, Some("generated"))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("bad.csv, line 3:") && e.contains("not a positive number"),
                "{e}"
            );
        }
    }
}
