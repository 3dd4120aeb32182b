//! Step 3's rule for which candidate enters next. Each rule came from a
//! season where its absence let a term in that made the testing events'
//! gap worse (or kept out one that shrank it); the measurements are in
//! docs/gap.md ("Step 3").

use super::candidates::Feature;
use super::recalibrate::Term;
use super::scoring::Score;

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
pub fn next_term<'a>(
    ranked: &'a [Score],
    first_round: &[Score],
    terms: &[Term],
    used: &[String],
    fdr: f64,
) -> Option<&'a Score> {
    let mechanism_in = terms
        .iter()
        .any(|t| t.candidate.feature.mechanism().is_some());
    let significant = |s: &Score| s.p_adjusted <= fdr && s.cv_gain > 0.0;
    let eligible = |s: &&Score| {
        significant(s)
            && s.cv_gain_across > 0.0
            && !(mechanism_in && generic_kpi(s.feature))
            && !used.contains(&s.name)
            && (first_round
                .iter()
                .any(|c| c.name == s.name && significant(c))
                || found_before(s.feature, terms))
    };
    let within = ranked
        .iter()
        .filter(eligible)
        .find(|s| !s.feature.track_level());
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
            feature,
            axle,
            threshold: 85.0,
            coefficient: 1.0,
            cv_gain: cv,
            cv_gain_across: cv,
            p: 0.001,
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
            },
            threshold: s.threshold,
            kpi_scale: KpiScale::NONE,
        }
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
