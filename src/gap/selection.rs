//! Step 3's rule for which candidate enters next. Each rule came from a
//! season where its absence let a term in that made the testing events'
//! gap worse (or kept out one that shrank it); the measurements are in
//! docs/gap.md ("Step 3").

use super::acts::acts_in;
use super::baseline::PhysicsBaseline;
use super::candidates::{Candidate, Feature, LawRow, NAMED_CONDITIONS};
use super::linear::weighted_fit;
use super::recalibrate::{Rows, Term, refit_law};
use super::scoring::{Problem, Score, relative_weights};
use crate::ingest::compound::Wlf;
use std::collections::BTreeMap;

/// Step 3's state between rounds: the design (the baseline's columns, then
/// one per term), what the law says about each row, the training rows'
/// weights, the terms in and the names entered or refused. One method per
/// thing a round does: [`Selection::problem`] (step 2's input),
/// [`Selection::acts_in`] (first round only), [`Selection::add`].
pub(super) struct Selection<'a> {
    pub data: Rows<'a>,
    /// The physics baseline as calibrated without terms (None: a model or
    /// predictions baseline, refitted by least squares).
    physics: Option<&'a PhysicsBaseline>,
    wlf: &'a BTreeMap<String, Wlf>,
    /// Design columns over every row: the baseline's, then one per term.
    pub base: Vec<Vec<f64>>,
    law: Vec<LawRow>,
    track_level: Vec<bool>,
    /// Training rows' weights (relative scale under the physics law).
    w: Vec<f64>,
    pub terms: Vec<Term>,
    pub used: Vec<String>,
    /// The law calibrated again around the terms.
    pub refitted_law: Option<PhysicsBaseline>,
    /// The final model's coefficients (of `base`) and its training weights.
    pub final_k: Vec<f64>,
    pub final_w: Vec<f64>,
}

impl<'a> Selection<'a> {
    pub fn new(
        data: Rows<'a>,
        physics: Option<&'a PhysicsBaseline>,
        wlf: &'a BTreeMap<String, Wlf>,
        base: Vec<Vec<f64>>,
        law: Vec<LawRow>,
        track_level: Vec<bool>,
    ) -> Self {
        let n_train = data.n_train;
        let w = if physics.is_some() {
            relative_weights(
                &base
                    .iter()
                    .map(|c| c[..n_train].to_vec())
                    .collect::<Vec<_>>(),
                &data.y[..n_train],
            )
        } else {
            vec![1.0; n_train]
        };
        Selection {
            data,
            physics,
            wlf,
            base,
            law,
            track_level,
            w,
            terms: Vec::new(),
            used: Vec::new(),
            refitted_law: None,
            final_k: Vec::new(),
            final_w: Vec::new(),
        }
    }

    fn train_idx(&self) -> Vec<usize> {
        (0..self.data.n_train).collect()
    }

    /// Step 2's input this round: the training rows and the design so far.
    pub fn problem(&self) -> Problem<'_> {
        let n = self.data.n_train;
        Problem {
            rows: &self.data.rows[..n],
            maps: &self.data.maps[..n],
            y: &self.data.y[..n],
            base: self.base.iter().map(|c| c[..n].to_vec()).collect(),
            track_level: self.track_level.clone(),
            law: &self.law[..n],
            relative: self.physics.is_some(),
            between_tracks: self.terms.is_empty(),
        }
    }

    /// Where each of `candidates` acts over all rows: the flagged slices
    /// (`named`: name and members) whose mean gap (`residual`) the change
    /// in prediction follows most, the baseline and the term refitted as
    /// step 3 refits them (the baseline gives back what the term takes over).
    pub(crate) fn acts_in(
        &self,
        candidates: &mut [Score],
        lib: &[Candidate],
        named: &[(&str, Vec<bool>)],
        residual: &[f64],
    ) {
        let (y, train_idx) = (&self.data.y, self.train_idx());
        let before = weighted_fit(&self.base, &self.w, y, &train_idx).1;
        for c in candidates {
            if c.coefficient == 0.0 {
                continue;
            }
            let column = Term {
                candidate: c.resolve(lib),
                threshold: c.threshold,
                kpi_scale: c.kpi_scale,
            }
            .column(self.data.rows, self.data.maps, &self.law);
            if column.iter().any(|v| !v.is_finite()) {
                continue;
            }
            let mut with = self.base.clone();
            with.push(column);
            let change: Vec<f64> = weighted_fit(&with, &self.w, y, &train_idx)
                .1
                .iter()
                .zip(&before)
                .map(|(a, b)| a - b)
                .collect();
            c.acts_in = acts_in(&change, residual, named, 3);
        }
    }

    /// Adds `best` (found in `lib` by name) as a term: the baseline and the
    /// terms refitted together on the training events (relative scale for
    /// the physics law), without track scales — the model a user would run
    /// on a new event; the physics law calibrated again around the terms
    /// (`recalibrate`). Returns the term's score with its refitted
    /// coefficient and every row's residual, or None when it is refused: a
    /// mechanism that adds wear must keep a positive coefficient once
    /// refitted without track scales; if it turns negative it was fitting
    /// something else (a track-level effect, say). Either way its name is
    /// used.
    pub(crate) fn add(&mut self, best: &Score, lib: &[Candidate]) -> Option<(Score, Vec<f64>)> {
        let cand = Candidate {
            thresholds: vec![best.threshold],
            ..best.resolve(lib)
        };
        let term = Term {
            candidate: cand.clone(),
            threshold: best.threshold,
            kpi_scale: best.kpi_scale,
        };
        self.used.push(best.name.clone());
        // The wear before the term: a refused term leaves it as it was.
        let y_before = self.data.y.clone();
        // Under a statistical baseline the design with the term's column.
        let (k, fitted, law_refit, with) = match self.physics {
            Some(p) => {
                let with_term = [self.terms.as_slice(), std::slice::from_ref(&term)].concat();
                let start = self.refitted_law.as_ref().unwrap_or(p);
                let r = refit_law(start, &with_term, &mut self.data, self.wlf);
                (r.coefficients.clone(), r.fitted.clone(), Some(r), None)
            }
            None => {
                let mut with = self.base.clone();
                with.push(term.column(self.data.rows, self.data.maps, &self.law));
                let (k, fitted) = weighted_fit(&with, &self.w, &self.data.y, &self.train_idx());
                (k, fitted, None, Some(with))
            }
        };
        let coefficient = k[k.len() - 1];
        if cand.adds_wear_only() && coefficient <= 0.0 {
            self.data.y = y_before;
            tracing::info!(
                term = %best.name,
                coefficient,
                "refused: the refitted coefficient of a wear mechanism is not positive"
            );
            return None;
        }
        // The law calibrated again around the term must still abrade: a
        // term that drives a compound's abrasion per joule on an axle to
        // zero or below has taken the law's own energy, not an effect beside
        // it, and extrapolates as the term alone (docs/gap.md, "A term may
        // not take the law's place").
        if let Some((group, k)) = law_refit.as_ref().and_then(|r| not_abrading(&r.law)) {
            self.data.y = y_before;
            tracing::info!(
                term = %best.name,
                group = %group,
                k_pct_per_mj = k,
                "refused: with the term in, the law's abrasion per joule is not positive"
            );
            return None;
        }
        let residual: Vec<f64> = (self.data.y.iter())
            .zip(&fitted)
            .map(|(a, b)| a - b)
            .collect();
        self.track_level.push(cand.feature.track_level());
        if let Some(with) = with {
            self.base = with;
        }
        self.terms.push(term);
        self.final_k = k;
        match law_refit {
            Some(r) => {
                self.final_w = r.weights.clone();
                self.base = r.columns;
                self.law = r.law_rows;
                self.w = r.weights;
                self.refitted_law = Some(r.law);
            }
            None => self.final_w = self.w.clone(),
        }
        let mut refitted = best.clone();
        refitted.coefficient = coefficient;
        Some((refitted, residual))
    }
}

/// The first compound and axle whose abrasion per joule the law holds at
/// zero or below (or NaN), with that k.
fn not_abrading(law: &PhysicsBaseline) -> Option<(String, f64)> {
    law.k_pct_per_mj
        .iter()
        .find(|(_, k)| k.is_nan() || **k <= 0.0)
        .map(|(g, k)| (g.clone(), *k))
}

/// The candidate of `ranked` (this round's step 2, sorted by CV gain) that
/// enters next, if any. `first_round`: step 2 on the baseline alone;
/// `terms`: the terms already in; `used`: names already entered or refused.
///
/// - Significant (adjusted p ≤ `fdr`, CV gain > 0) now and on its own in
///   the first round: a candidate that only turns significant after another
///   entered is fitting that term's misfit, and does not carry to new
///   events. Except the mechanism already found, on another axle or at
///   another threshold: that refines the found effect's form (strong
///   front-axle graining hides the rears' share of it in the first round,
///   and cold testing tracks then lack the rears' graining).
/// - A held-out gain against the null without track scales
///   (`cv_gain_across` > 0): the model step 3 builds has none, and a
///   within-track gain alone can come from the held-out track's calibration.
/// - No generic KPI once a mechanism is in: a straight line in a KPI with no
///   physics behind it, which after a mechanism fits the misfit of the
///   mechanism's form (a hard threshold against a smooth onset) rather than
///   a new effect.
/// - Within-track and road (track-level) terms: the best of each kind by
///   its own CV gain, then the road term only if its gain on the common
///   footing (`cv_gain_across`) beats the within-track term's. A road term
///   rests on a handful of track means, which an unmodelled within-track
///   effect also moves, and its own CV gain counts the tracks' severities
///   that a within-track term's held-out calibration removes.
/// - A set-up of the same tires whose held-out gain is within one standard
///   error of the best within-track term's takes its place (the one-SE
///   rule: of the models the data cannot tell apart, the one with the
///   fewest choices made on it). A set-up scans four forms, a condition
///   a threshold grid on many scopes; where the two fit the held-out tracks
///   alike, a condition that holds about every joule of one direction of
///   sliding ("energy with accel_y_mps2 above 6 m/s², car1": 53 % of the
///   energy, nearly all of it lateral) is the lateral-energy set-up of
///   that car by another name (seed 340, docs/gap.md). A named mechanism
///   of the same tires likewise ([`fewest_choices`]): "longitudinal energy
///   with t_bulk_c above θ" where blistering (a hot inner liner) fits the
///   held-out tracks as well is blistering seen through a neighbouring
///   temperature.
pub(crate) fn next_term<'a>(
    ranked: &'a [Score],
    first_round: &[Score],
    terms: &[Term],
    used: &[String],
    fdr: f64,
) -> Option<&'a Score> {
    let mechanism_in = terms
        .iter()
        .any(|t| t.candidate.feature.mechanism().is_some());
    let significant = |s: &Score| s.significant(fdr);
    let eligible = |s: &&Score| {
        significant(s)
            && s.cv_gain_across > 0.0
            && !(mechanism_in && generic_kpi(s.feature))
            && !used.contains(&s.name)
            && (first_round
                .iter()
                .any(|c| c.candidate == s.candidate && significant(c))
                || found_before(s.feature, terms))
    };
    let within = ranked
        .iter()
        .filter(eligible)
        .find(|s| !s.feature.track_level())
        .map(|best| {
            if fewest_choices(best.feature) {
                return best;
            }
            // The same tires: the scope as the report names it.
            let tires = best.as_candidate().scope_description();
            let se = best.cv_gain_se();
            ranked
                .iter()
                .filter(eligible)
                .find(|s| {
                    fewest_choices(s.feature)
                        && s.cv_gain >= best.cv_gain - se
                        && s.as_candidate().scope_description() == tires
                })
                .inspect(|s| {
                    tracing::debug!(
                        "{} (CV gain {:.3}) enters in place of {} ({:.3}, standard error {:.3})",
                        s.name,
                        s.cv_gain,
                        best.name,
                        best.cv_gain,
                        se
                    )
                })
                .unwrap_or(best)
        });
    let road = ranked
        .iter()
        .filter(eligible)
        .find(|s| s.feature.track_level());
    match (within, road) {
        (Some(w), Some(r)) if r.cv_gain_across > w.cv_gain_across => Some(r),
        (Some(w), _) => Some(w),
        (None, r) => r,
    }
}

/// A set-up or a named per-sample mechanism (the registry
/// [`NAMED_CONDITIONS`]): the candidates the one-SE rule prefers to a
/// generated condition of the same tires, as they make the fewest choices
/// on the data (a set-up four forms, a named mechanism one condition and
/// component fixed by its physics, where a generated condition picks its
/// condition, direction and component too).
fn fewest_choices(f: Feature) -> bool {
    f == Feature::Group || NAMED_CONDITIONS.iter().any(|(_, _, named)| *named == f)
}

/// A generic KPI candidate (not a road index, which is road abrasion).
fn generic_kpi(f: Feature) -> bool {
    matches!(f, Feature::Kpi(_)) && f.mechanism().is_none()
}

/// `f` is a built-in mechanism (not a KPI or a user hypothesis) of which a
/// term is already in.
fn found_before(f: Feature, terms: &[Term]) -> bool {
    !matches!(f, Feature::Kpi(_) | Feature::User)
        && f.mechanism().is_some()
        && terms
            .iter()
            .any(|t| t.candidate.feature.mechanism() == f.mechanism())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::candidates::{Candidate, KpiScale};

    fn score(name: &str, feature: Feature, axle: Option<crate::Axle>, cv: f64) -> Score {
        Score {
            name: name.into(),
            candidate: name.into(),
            feature,
            axle,
            group: None,
            threshold: 85.0,
            coefficient: 1.0,
            cv_gain: cv,
            cv_sse_by_fold: Vec::new(),
            cv_gain_across: cv,
            p: 0.001,
            p_between: f64::NAN,
            p_adjusted: 0.01,
            front_share: f64::NAN,
            kpi_scale: KpiScale::NONE,
            acts_in: Vec::new(),
        }
    }

    fn term(s: &Score) -> Term {
        Term {
            candidate: Candidate {
                name: s.name.clone(),
                feature: s.feature,
                thresholds: vec![s.threshold],
                axle: s.axle,
                user: None,
                group: None,
                scopes: Vec::new(),
            },
            threshold: s.threshold,
            kpi_scale: KpiScale::NONE,
        }
    }

    #[test]
    fn a_set_up_of_the_same_tires_within_one_standard_error_enters_instead() {
        use crate::gap::candidates::Group;
        let on = |car: &str, s: Score| Score {
            group: Some(Group {
                car: Some(car.into()),
                wheel: None,
            }),
            // Two left-out tracks, 0.01 and 0.02 of the SSE left with the
            // best term: its gain 0.97 has a standard error of 0.01.
            cv_sse_by_fold: vec![(0.5, 0.01), (0.5, 0.02)],
            ..s
        };
        let condition = on(
            "car1",
            score(
                "energy with accel_y_mps2 above θ, car1",
                Feature::Group,
                None,
                0.97,
            ),
        );
        let condition = Score {
            feature: Feature::ConditionEnergy {
                condition: 0,
                above: true,
                component: crate::kpi::cpu::condition_map::Component::Total,
            },
            ..condition
        };
        let set_up = |car: &str, cv: f64| {
            on(
                car,
                score(&format!("set-up: {car}"), Feature::Group, None, cv),
            )
        };
        let pick =
            |ranked: &[Score]| next_term(ranked, ranked, &[], &[], 0.05).map(|s| s.name.clone());
        // Within one standard error (0.965 ≥ 0.97 − 0.01): the set-up.
        let ranked = vec![condition.clone(), set_up("car1", 0.965)];
        assert_eq!(pick(&ranked).as_deref(), Some("set-up: car1"));
        // Beyond it, or another car's: the condition.
        let ranked = vec![condition.clone(), set_up("car1", 0.955)];
        assert_eq!(pick(&ranked).as_deref(), Some(condition.name.as_str()));
        let ranked = vec![condition.clone(), set_up("car2", 0.969)];
        assert_eq!(pick(&ranked).as_deref(), Some(condition.name.as_str()));
        // A set-up that is not significant may not take its place.
        let weak = Score {
            p_adjusted: 0.2,
            ..set_up("car1", 0.969)
        };
        let ranked = vec![condition.clone(), weak];
        assert_eq!(pick(&ranked).as_deref(), Some(condition.name.as_str()));
    }

    #[test]
    fn a_named_mechanism_of_the_same_tires_within_one_standard_error_enters_instead() {
        use crate::kpi::cpu::condition_map::Component;
        // Two left-out tracks, 0.01 and 0.02 of the SSE left with the best
        // term: its gain 0.97 has a standard error of 0.01 (the test above).
        let folds = |s: Score| Score {
            cv_sse_by_fold: vec![(0.5, 0.01), (0.5, 0.02)],
            ..s
        };
        let bulk = folds(score(
            "longitudinal energy with t_bulk_c above θ, rear axle",
            Feature::ConditionEnergy {
                condition: 11,
                above: true,
                component: Component::Longitudinal,
            },
            Some(crate::Axle::Rear),
            0.97,
        ));
        let blistering = |axle, cv| {
            score(
                "blistering (energy with a hot inner liner)",
                Feature::HotInnerEnergy,
                Some(axle),
                cv,
            )
        };
        let pick =
            |ranked: &[Score]| next_term(ranked, ranked, &[], &[], 0.05).map(|s| s.name.clone());
        let rear = crate::Axle::Rear;
        // Within one standard error, on the same axle: the mechanism.
        let ranked = vec![bulk.clone(), blistering(rear, 0.961)];
        assert_eq!(pick(&ranked), Some(blistering(rear, 0.0).name));
        // Beyond it, or on the other axle: the generated condition.
        let ranked = vec![bulk.clone(), blistering(rear, 0.959)];
        assert_eq!(pick(&ranked), Some(bulk.name.clone()));
        let ranked = vec![bulk.clone(), blistering(crate::Axle::Front, 0.969)];
        assert_eq!(pick(&ranked), Some(bulk.name.clone()));
        // A named mechanism that is the best already stays.
        let ranked = vec![folds(blistering(rear, 0.97)), bulk.clone()];
        assert_eq!(pick(&ranked), Some(blistering(rear, 0.0).name));
    }

    #[test]
    fn a_law_that_no_longer_abrades_is_named() {
        use crate::gap::baseline::TemperatureFactor;
        let law = |medium_rear: f64| PhysicsBaseline {
            k_pct_per_mj: [
                ("hard/front".to_string(), 2.7),
                ("hard/rear".to_string(), 7.9),
                ("medium/rear".to_string(), medium_rear),
            ]
            .into(),
            temperature_factor: TemperatureFactor::Exponential { beta_per_k: 0.0 },
            skewness_coefficient: -0.2,
        };
        // Seed 289 at real-data noise (docs/gap.md): medium/rear −0.27 %/MJ.
        assert_eq!(
            not_abrading(&law(-0.2672)),
            Some(("medium/rear".to_string(), -0.2672))
        );
        assert_eq!(
            not_abrading(&law(0.0)).map(|(g, _)| g).as_deref(),
            Some("medium/rear")
        );
        assert!(not_abrading(&law(f64::NAN)).is_some());
        assert_eq!(not_abrading(&law(1e-3)), None);
    }

    #[test]
    fn the_found_mechanism_may_return_and_generic_kpis_stop() {
        let front = score(
            "graining, front",
            Feature::ColdTreadLateralEnergy,
            Some(crate::Axle::Front),
            0.8,
        );
        let rear = score(
            "graining, rear",
            Feature::ColdTreadLateralEnergy,
            Some(crate::Axle::Rear),
            0.3,
        );
        let kpi = score("KPI distance_m", Feature::Kpi("distance_m"), None, 0.25);
        let hot = score("thermal", Feature::HotSurfaceEnergy, None, 0.2);
        // Round 1: the rear term was not significant on its own.
        let first = vec![
            front.clone(),
            Score {
                p_adjusted: 0.2,
                ..rear.clone()
            },
            kpi.clone(),
            hot.clone(),
        ];
        assert_eq!(
            next_term(&first, &first, &[], &[], 0.05).map(|s| s.name.as_str()),
            Some("graining, front")
        );
        // Round 2, graining in: its rear term may enter although it was
        // not significant in round 1; the KPI may not.
        let used = vec![front.name.clone()];
        let ranked = vec![kpi.clone(), rear.clone(), hot.clone()];
        let picked = next_term(&ranked, &first, &[term(&front)], &used, 0.05);
        assert_eq!(picked.map(|s| s.name.as_str()), Some("graining, rear"));
        // Another mechanism not significant in round 1 may not enter.
        let first_without_hot: Vec<Score> = first
            .iter()
            .filter(|s| s.name != "thermal")
            .cloned()
            .collect();
        let ranked = vec![kpi.clone(), hot.clone()];
        let picked = next_term(&ranked, &first_without_hot, &[term(&front)], &used, 0.05);
        assert!(picked.is_none(), "{picked:?}");
        // Without a mechanism in, a generic KPI enters; not with a
        // negative gain on the footing without track scales.
        assert_eq!(
            next_term(std::slice::from_ref(&kpi), &first, &[], &[], 0.05).map(|s| s.name.as_str()),
            Some("KPI distance_m")
        );
        let across = Score {
            cv_gain_across: -0.003,
            ..kpi
        };
        let alone = std::slice::from_ref(&across);
        assert!(next_term(alone, alone, &[], &[], 0.05).is_none());
    }
}
