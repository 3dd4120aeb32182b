//! The tables of `gap validate` (OUT/validate.md, docs/gap.md): per named
//! effect and magnitude, against the targets, the seasons that miss one,
//! the clean seasons' false discoveries and the generated effects.

use super::Case;
use crate::gap::candidates::significant;
use crate::model::metrics::median;
use crate::sim::generated::Form;
use std::collections::BTreeMap;
use std::fmt::Write;

/// The summary table (per effect and magnitude) and the clean seasons' false discoveries.
pub fn render(cases: &[Case]) -> String {
    let mut s = String::from(
        "| effect | magnitude | seasons | variance share (median) | hit rate | hit incl. axle | shrinkage / ideal (median) | within 20 % of ideal |\n|---|---|---|---|---|---|---|---|\n",
    );
    let mut groups: BTreeMap<(String, String), Vec<&Case>> = BTreeMap::new();
    for c in cases.iter().filter(|c| c.effect.is_some()) {
        let e = c.effect.as_ref().expect("planted");
        groups
            .entry((e.kind.name().to_string(), format!("{:.2}", e.magnitude)))
            .or_default()
            .push(c);
    }
    for ((kind, mag), g) in &groups {
        let n = g.len();
        let rate = |f: &dyn Fn(&Case) -> bool| {
            format!(
                "{}/{n} ({:.0} %)",
                g.iter().filter(|c| f(c)).count(),
                100.0 * g.iter().filter(|c| f(c)).count() as f64 / n as f64
            )
        };
        let _ = writeln!(
            s,
            "| {kind} | {mag} | {n} | {:.1} % | {} | {} | {:.2} | {} |",
            100.0 * median(g.iter().map(|c| c.variance_share).collect()),
            rate(&|c| c.hit),
            rate(&|c| c.hit_axle),
            median(g.iter().map(|c| c.shrinkage_ratio).collect()),
            rate(&|c| (c.shrinkage_ratio - 1.0).abs() <= 0.2),
        );
    }
    // The targets, over the seasons where the planted effect carries
    // at least 10 % of the wear variance (whatever the magnitude).
    let mut kinds: BTreeMap<String, Vec<&Case>> = BTreeMap::new();
    for c in cases.iter().filter(|c| c.error.is_none()) {
        if let Some(e) = &c.effect {
            kinds.entry(e.kind.name().to_string()).or_default().push(c);
        }
    }
    if !kinds.is_empty() {
        s.push_str(
            "\nTargets, over the seasons where the planted effect carries ≥ 10 % of the wear variance: hit rate ≥ 90 %, shrinkage within 20 % of the ideal.\n\n| effect | seasons ≥ 10 % | hit rate | hit incl. axle | shrinkage within 20 % |\n|---|---|---|---|---|\n",
        );
        for (kind, g) in &kinds {
            let big: Vec<&&Case> = g.iter().filter(|c| c.variance_share >= 0.1).collect();
            let n = big.len();
            let count = |f: &dyn Fn(&Case) -> bool| big.iter().filter(|c| f(c)).count();
            let pct = |k: usize| {
                if n == 0 {
                    "–".to_string()
                } else {
                    format!("{k}/{n} ({:.0} %)", 100.0 * k as f64 / n as f64)
                }
            };
            let _ = writeln!(
                s,
                "| {kind} | {n} | {} | {} | {} |",
                pct(count(&|c| c.hit)),
                pct(count(&|c| c.hit_axle)),
                pct(count(&|c| (c.shrinkage_ratio - 1.0).abs() <= 0.2)),
            );
        }
    }
    // Where it stops working, season by season: those at ≥ 10 % of the
    // variance that miss a target.
    let misses: Vec<&Case> = cases
        .iter()
        .filter(|c| c.error.is_none() && c.effect.is_some() && c.variance_share >= 0.1)
        .filter(|c| !c.hit_axle || (c.shrinkage_ratio - 1.0).abs() > 0.2)
        .collect();
    if !misses.is_empty() {
        s.push_str(
            "\nSeasons at ≥ 10 % of the variance that miss a target (testing RMSE in %):\n\n| effect (magnitude, threshold) | seed | variance share | first term | front share (truth) | RMSE baseline / diagnosed / ideal | shrinkage / ideal |\n|---|---|---|---|---|---|---|\n",
        );
        for c in misses {
            let e = c.effect.as_ref().expect("planted");
            let _ = writeln!(
                s,
                "| {} ({}, {}) | {} | {:.1} % | {} | {:.2} ({:.2}) | {:.3} / {:.3} / {:.3} | {:.3} |",
                e.kind.name(),
                e.magnitude,
                significant(e.threshold),
                c.seed,
                100.0 * c.variance_share,
                c.first_term.as_deref().unwrap_or("none"),
                c.first_front_share,
                c.truth_front_share,
                c.rmse_baseline_pct,
                c.rmse_diagnosed_pct,
                c.rmse_ideal_pct,
                c.shrinkage_ratio,
            );
        }
    }
    render_generated(&mut s, cases);
    render_against_truth(&mut s, cases);
    render_hypotheses(&mut s, cases);
    let clean: Vec<&Case> = cases
        .iter()
        .filter(|c| c.effect.is_none() && c.generated.is_none())
        .collect();
    if !clean.is_empty() {
        let fd = clean.iter().filter(|c| c.significant_terms > 0).count();
        let _ = writeln!(
            s,
            "\nClean seasons: {fd} of {} report a significant effect ({:.0} %).",
            clean.len(),
            100.0 * fd as f64 / clean.len() as f64
        );
        for c in clean.iter().filter(|c| c.significant_terms > 0) {
            let _ = writeln!(
                s,
                "- seed {}: {}",
                c.seed,
                c.first_term.as_deref().unwrap_or("?")
            );
        }
        let leads: Vec<&&Case> = clean.iter().filter(|c| c.leads_scope.is_some()).collect();
        let _ = writeln!(
            s,
            "\nClean seasons whose leads name the tires they share: {} of {}{}",
            leads.len(),
            clean.len(),
            leads
                .iter()
                .map(|c| format!(
                    "; seed {}: {}",
                    c.seed,
                    c.leads_scope.as_deref().unwrap_or("")
                ))
                .collect::<String>()
        );
    }
    let failed: Vec<&Case> = cases.iter().filter(|c| c.error.is_some()).collect();
    for c in failed {
        let _ = writeln!(
            s,
            "- failed: {:?} seed {}: {}",
            c.effect.as_ref().map(|e| e.to_string()),
            c.seed,
            c.error.as_deref().unwrap_or("")
        );
    }
    s
}

/// The user's hypotheses (`--hypotheses`) over the seasons diagnosed, in
/// the file's order: in how many each was significant in the first round,
/// entered first or later, and its median held-out gain and adjusted p.
fn render_hypotheses(s: &mut String, cases: &[Case]) {
    let mut names: Vec<&str> = Vec::new();
    for h in cases.iter().flat_map(|c| &c.hypotheses) {
        if !names.contains(&h.name.as_str()) {
            names.push(&h.name);
        }
    }
    if names.is_empty() {
        return;
    }
    s.push_str(
        "\nYour hypotheses (`--hypotheses`), scored among every candidate of each season's first round:\n\n| hypothesis | seasons | significant | entered first | entered later | held-out gain (median) | adjusted p (median) |\n|---|---|---|---|---|---|---|\n",
    );
    for name in names {
        let of: Vec<&super::HypothesisOutcome> = cases
            .iter()
            .flat_map(|c| &c.hypotheses)
            .filter(|h| h.name == name)
            .collect();
        let count =
            |f: &dyn Fn(&super::HypothesisOutcome) -> bool| of.iter().filter(|h| f(h)).count();
        let _ = writeln!(
            s,
            "| {name} | {} | {} | {} | {} | {:.3} | {:.3} |",
            of.len(),
            count(&|h| h.significant),
            count(&|h| h.added_as == Some(1)),
            count(&|h| h.added_as.is_some_and(|k| k > 1)),
            median(of.iter().map(|h| h.cv_gain).collect()),
            median(of.iter().map(|h| h.p_adjusted).collect()),
        );
    }
}

/// The testing events measured against every testing tire's true wear
/// (`AgainstTruth`), beside the diagnosis's own measure, per group of
/// seasons.
fn render_against_truth(s: &mut String, cases: &[Case]) {
    let with: Vec<&Case> = cases
        .iter()
        .filter(|c| c.error.is_none() && c.against_truth.is_some())
        .collect();
    if with.is_empty() {
        return;
    }
    s.push_str(
        "\nAgainst the true wear of every testing tire (the simulator's `wear_total_pct`: no gauge error, and the worn-through tires, which the diagnosis's measure leaves out, at their uncapped wear; the same terms, the ideal and the expected shape recomputed on it):\n\n| seasons | n | testing tires worn through (median) | shrinkage / ideal (median): measured tires | against the true wear | expected shape, against the true wear | RMSE diagnosed, against the true wear (median, %) | terms differ | imputed training tires: n, mean error (median, %) |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    let line = |s: &mut String, label: &str, g: &[&Case]| {
        if g.is_empty() {
            return;
        }
        fn t(c: &Case) -> &super::AgainstTruth {
            c.against_truth.as_ref().expect("filtered")
        }
        let _ = writeln!(
            s,
            "| {label} | {} | {:.1} % | {:.2} | {:.2} | {:.2} | {:.3} | {} | {}, {:+.2} |",
            g.len(),
            100.0
                * median(
                    g.iter()
                        .map(|c| t(c).testing_worn_through as f64 / t(c).testing_tires as f64)
                        .collect()
                ),
            median(g.iter().map(|c| c.shrinkage_ratio).collect()),
            median(g.iter().map(|c| t(c).shrinkage_ratio).collect()),
            median(g.iter().map(|c| t(c).expected_shrinkage).collect()),
            median(g.iter().map(|c| t(c).rmse_diagnosed_pct).collect()),
            g.iter().filter(|c| !t(c).same_terms).count(),
            g.iter().map(|c| t(c).imputed_tires).sum::<usize>(),
            median(g.iter().map(|c| t(c).imputed_bias_pct).collect()),
        );
    };
    let of = |f: &dyn Fn(&Case) -> bool| -> Vec<&Case> {
        with.iter().copied().filter(|c| f(c)).collect()
    };
    line(s, "named effects", &of(&|c| c.effect.is_some()));
    line(
        s,
        "generated, ≥ 10 % of the variance",
        &of(&|c| c.generated.is_some() && c.variance_share >= 0.1),
    );
    line(
        s,
        "clean",
        &of(&|c| c.effect.is_none() && c.generated.is_none()),
    );
}

/// The generated effects: the targets over those at ≥ 10 % of the
/// variance (median shrinkage ≥ 0.8 of the ideal, hit ≥ 80 %), by form and
/// scope, then season by season.
fn render_generated(s: &mut String, cases: &[Case]) {
    let generated: Vec<&Case> = cases
        .iter()
        .filter(|c| c.generated.is_some() && c.error.is_none())
        .collect();
    if generated.is_empty() {
        return;
    }
    let big: Vec<&Case> = generated
        .iter()
        .copied()
        .filter(|c| c.variance_share >= 0.1)
        .collect();
    let line = |s: &mut String, label: &str, g: &[&Case]| {
        let n = g.len();
        if n == 0 {
            return;
        }
        let hits = g.iter().filter(|c| c.hit).count();
        let _ = writeln!(
            s,
            "| {label} | {n} | {hits}/{n} ({:.0} %) | {:.2} | {:.2} | {:.2} | {:.2} | {} |",
            100.0 * hits as f64 / n as f64,
            median(g.iter().map(|c| c.terms_correlation).collect()),
            median(g.iter().map(|c| c.shrinkage_ratio).collect()),
            median(g.iter().map(|c| c.oracle_shrinkage).collect()),
            median(g.iter().map(|c| c.expected_shrinkage).collect()),
            g.iter().filter(|c| c.significant_terms == 0).count(),
        );
    };
    s.push_str(
        "\nGenerated effects (targets over those at ≥ 10 % of the wear variance: hit ≥ 80 %, median shrinkage ≥ 0.8 of the ideal; hit: the terms' wear correlates ≥ 0.8 with the planted wear; exact shape, sized: the planted wear itself as the term, its size fitted with the law on the training events; expected shape: the same without each tire's wear scatter factor, which the ideal and the exact shape carry and no term can know, so what a term of the right form can reach):\n\n| seasons | n | hit | correlation (median) | shrinkage / ideal (median) | exact shape, sized: shrinkage (median) | expected shape, sized: shrinkage (median) | no term |\n|---|---|---|---|---|---|---|---|\n",
    );
    line(s, "all generated", &generated);
    line(s, "≥ 10 % of the variance", &big);
    // By form, then by scope.
    for part in 0..2 {
        let mut groups: BTreeMap<String, Vec<&Case>> = BTreeMap::new();
        for c in &big {
            let g = c.generated.as_ref().expect("generated");
            let (form, scope) = g.kind_label();
            let key = if part == 0 { form } else { scope };
            groups.entry(key.to_string()).or_default().push(c);
        }
        for (label, g) in &groups {
            line(s, &format!("≥ 10 %: {label}"), g);
        }
    }
    // Set-up effects: reported as one, on their own tires?
    let set_ups: Vec<&&Case> = big
        .iter()
        .filter(|c| matches!(c.generated.as_ref().map(|g| g.form), Some(Form::SetUp)))
        .collect();
    if !set_ups.is_empty() {
        let named = set_ups
            .iter()
            .filter(|c| {
                let planted = c.generated.as_ref().map(|g| g.scope.describe());
                c.first_set_up && c.first_scope == planted
            })
            .count();
        let _ = writeln!(
            s,
            "\nSet-up effects at ≥ 10 % of the variance: {named} of {} reported first as a set-up effect of the planted tires.",
            set_ups.len()
        );
    }
    // Without a term: do the leads name the planted tires?
    let no_term: Vec<&&Case> = big.iter().filter(|c| c.significant_terms == 0).collect();
    if !no_term.is_empty() {
        let named: Vec<&&&Case> = no_term.iter().filter(|c| c.leads_scope.is_some()).collect();
        let right = named
            .iter()
            .filter(|c| c.leads_scope == c.generated.as_ref().map(|g| g.scope.describe()))
            .count();
        let _ = writeln!(
            s,
            "\nWithout a term at ≥ 10 % of the variance: {} season{}; their leads name the tires they share in {}, the planted ones in {right}.",
            no_term.len(),
            if no_term.len() == 1 { "" } else { "s" },
            named.len()
        );
    }
    s.push_str(
        "\n| effect | variance share | terms | correlation | RMSE baseline / diagnosed / ideal | shrinkage / ideal | exact shape: size, shrinkage | expected shape: size, shrinkage | against the true wear: worn through, RMSE baseline / diagnosed / ideal, shrinkage |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for c in &generated {
        let g = c.generated.as_ref().expect("generated");
        let _ = writeln!(
            s,
            "| {g} | {:.1} % | {} | {:.2} | {:.3} / {:.3} / {:.3} | {:.2} | {:.3}, {:.2} | {:.3}, {:.2} | {} |",
            100.0 * c.variance_share,
            c.first_term.as_deref().map_or(
                c.leads_scope
                    .as_ref()
                    .map_or("none".to_string(), |l| format!("none (leads: {l})")),
                |t| format!(
                    "{}{} (of {})",
                    t,
                    if c.first_set_up { " [set-up]" } else { "" },
                    c.significant_terms
                )
            ),
            c.terms_correlation,
            c.rmse_baseline_pct,
            c.rmse_diagnosed_pct,
            c.rmse_ideal_pct,
            c.shrinkage_ratio,
            c.oracle_size,
            c.oracle_shrinkage,
            c.expected_size,
            c.expected_shrinkage,
            c.against_truth
                .as_ref()
                .map_or("–".to_string(), |t| format!(
                    "{}/{}, {:.3} / {:.3} / {:.3}, {:.2}{}",
                    t.testing_worn_through,
                    t.testing_tires,
                    t.rmse_baseline_pct,
                    t.rmse_diagnosed_pct,
                    t.rmse_ideal_pct,
                    t.shrinkage_ratio,
                    if t.same_terms { "" } else { " (terms differ)" }
                )),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{Effect, EffectKind};

    fn case(kind: EffectKind, seed: u64, share: f64, shrinkage: f64) -> Case {
        Case {
            effect: Some(Effect::with_defaults(kind, 2.0)),
            seed,
            variance_share: share,
            truth_front_share: 0.32,
            first_term: Some("road abrasion (energy × squared micro-roughness)".into()),
            first_set_up: false,
            first_scope: None,
            leads_scope: None,
            first_mechanism: Some(kind.name().into()),
            first_front_share: 0.35,
            significant_terms: 1,
            hit: true,
            hit_axle: true,
            rmse_baseline_pct: 9.0,
            rmse_diagnosed_pct: 9.0 - shrinkage * 7.0,
            rmse_ideal_pct: 2.0,
            shrinkage_ratio: shrinkage,
            oracle_size: f64::NAN,
            rmse_oracle_pct: f64::NAN,
            oracle_shrinkage: f64::NAN,
            expected_size: f64::NAN,
            rmse_expected_pct: f64::NAN,
            expected_shrinkage: f64::NAN,
            terms_correlation: f64::NAN,
            generated: None,
            against_truth: None,
            hypotheses: Vec::new(),
            error: None,
        }
    }

    #[test]
    fn the_seasons_that_miss_a_target_are_listed() {
        let cases = [
            case(EffectKind::RoadAbrasion, 1, 0.184, 0.799),
            case(EffectKind::RoadAbrasion, 2, 0.254, 0.95),
            // Under 10 % of the variance: no target, not listed.
            case(EffectKind::RoadAbrasion, 3, 0.05, 0.3),
        ];
        let md = render(&cases);
        assert!(
            md.contains("| road-abrasion (2, 0.03000) | 1 | 18.4 % |"),
            "{md}"
        );
        assert!(md.contains("| 9.000 / 3.407 / 2.000 | 0.799 |"), "{md}");
        assert!(!md.contains("| road-abrasion (2, 0.03000) | 2 |"), "{md}");
        assert!(!md.contains("| road-abrasion (2, 0.03000) | 3 |"), "{md}");
        assert!(md.contains("| road-abrasion | 2 | 2/2 (100 %) | 2/2 (100 %) | 1/2 (50 %) |"));
    }

    /// The second measure's table: medians over the generated seasons at
    /// ≥ 10 % of the variance, beside the measured tires' shrinkage.
    #[test]
    fn the_gap_against_the_true_wear_is_tabled_beside_the_measured_one() {
        use super::super::AgainstTruth;
        let generated = |seed: u64, measured: f64, worn: usize, truth: f64, same: bool| {
            let t = AgainstTruth {
                testing_tires: 100,
                testing_worn_through: worn,
                rmse_baseline_pct: 14.0,
                rmse_diagnosed_pct: 8.0 + 4.0 * truth,
                rmse_ideal_pct: 6.0,
                rmse_expected_pct: 9.0,
                shrinkage_ratio: truth,
                expected_shrinkage: 2.0 * truth,
                same_terms: same,
                imputed_tires: seed as usize,
                imputed_bias_pct: if seed == 1 { -1.0 } else { 2.0 },
                imputed_rmse_pct: 3.0,
            };
            Case {
                effect: None,
                generated: Some(crate::sim::generated::GeneratedEffect::draw(seed)),
                against_truth: Some(t),
                ..case(EffectKind::Graining, seed, 0.2, measured)
            }
        };
        let cases = [
            generated(1, 0.5, 10, 0.2, true),
            generated(2, 0.7, 30, 0.4, false),
        ];
        let md = render(&cases);
        assert!(
            md.contains(
                "| generated, ≥ 10 % of the variance | 2 | 20.0 % | 0.60 | 0.30 | 0.60 | 9.200 | 1 | 3, +0.50 |"
            ),
            "{md}"
        );
        assert!(
            md.contains("| 30/100, 14.000 / 9.600 / 6.000, 0.40 (terms differ) |"),
            "{md}"
        );
    }

    /// The user's hypotheses: counted over the seasons in the file's order,
    /// medians of three seasons' gains and p-values by hand.
    #[test]
    fn the_users_hypotheses_are_counted_over_the_seasons() {
        use super::super::HypothesisOutcome;
        let h = |name: &str, cv_gain: f64, p_adjusted: f64, added_as: Option<usize>| {
            HypothesisOutcome {
                name: name.into(),
                cv_gain,
                p_adjusted,
                significant: p_adjusted <= 0.05 && cv_gain > 0.0,
                added_as,
            }
        };
        let with = |seed: u64, hypotheses: Vec<HypothesisOutcome>| Case {
            hypotheses,
            ..case(EffectKind::Blistering, seed, 0.2, 0.9)
        };
        let cases = [
            with(
                1,
                vec![
                    h("user: b", 0.2, 0.01, Some(1)),
                    h("user: a", 0.0, 1.0, None),
                ],
            ),
            with(
                2,
                vec![
                    h("user: b", 0.1, 0.04, Some(2)),
                    h("user: a", -0.1, 0.5, None),
                ],
            ),
            with(
                3,
                vec![h("user: b", 0.3, 0.2, None), h("user: a", 0.05, 0.03, None)],
            ),
            // A season that failed scores none.
            with(4, vec![]),
        ];
        let md = render(&cases);
        let b = md.find("| user: b | 3 | 2 | 1 | 1 | 0.200 | 0.040 |");
        let a = md.find("| user: a | 3 | 1 | 0 | 0 | 0.000 | 0.500 |");
        assert!(b.is_some() && a.is_some() && b < a, "{md}");
        // Without hypotheses, no table.
        assert!(!render(&cases[3..]).contains("Your hypotheses"));
    }

    /// Seasons without a term: the tires their leads share are counted
    /// against the planted tires; clean seasons' leads are listed.
    #[test]
    fn the_leads_of_seasons_without_a_term_are_scored_against_the_planted_tires() {
        use crate::Axle;
        use crate::sim::generated::{GeneratedEffect, Scope};
        let no_term = |seed: u64, planted: Option<Scope>, leads: Option<&str>| {
            let generated = planted.map(|scope| {
                let mut g = GeneratedEffect::draw(seed);
                g.scope = scope;
                g
            });
            Case {
                effect: None,
                generated,
                first_term: None,
                first_mechanism: None,
                significant_terms: 0,
                hit: false,
                leads_scope: leads.map(String::from),
                ..case(EffectKind::Graining, seed, 0.2, 0.0)
            }
        };
        let rear = Scope::Axle { axle: Axle::Rear };
        let cases = [
            no_term(1, Some(rear), Some("the rear axle")),
            no_term(2, Some(Scope::All), Some("the rear axle")),
            no_term(3, Some(rear), None),
            no_term(4, None, None),
            no_term(5, None, Some("every tire")),
        ];
        let md = render(&cases);
        assert!(
            md.contains("Without a term at ≥ 10 % of the variance: 3 seasons; their leads name the tires they share in 2, the planted ones in 1."),
            "{md}"
        );
        assert!(md.contains("| none (leads: the rear axle) |"), "{md}");
        assert!(
            md.contains(
                "Clean seasons whose leads name the tires they share: 1 of 2; seed 5: every tire"
            ),
            "{md}"
        );
        let one = render(&cases[2..]);
        assert!(
            one.contains("Without a term at ≥ 10 % of the variance: 1 season; their leads name the tires they share in 0, the planted ones in 0."),
            "{one}"
        );
    }
}
