//! The gap diagnosis: its statistics against statsmodels and scipy (goldens
//! from tests/oracles/gap_oracle.py and tests/oracles/tobit_oracle.py), and a small matrix of the validation on
//! withheld effects: a planted effect is found where the truth put it, and a
//! clean season reports nothing.

use tirewear::gap::report::{Diagnosis, GapSettings};
use tirewear::gap::scoring::ScoringSettings;
use tirewear::gap::stats::{
    CensoredNormal, VarianceComponents, benjamini_hochberg, clustered_difference,
};
use tirewear::sim::{Effect, EffectKind};
use tirewear::validate::{Case, Planted, ValidateSettings, run_case};

#[derive(serde::Deserialize)]
struct Clustered {
    r: Vec<f64>,
    event: Vec<usize>,
    inside: Vec<bool>,
    difference: f64,
    ci: [f64; 2],
    p: f64,
}

#[derive(serde::Deserialize)]
struct Golden {
    p: Vec<f64>,
    p_bh: Vec<f64>,
    clustered: Vec<Clustered>,
}

#[test]
fn statistics_equal_statsmodels_and_scipy() {
    let g: Golden =
        serde_json::from_str(include_str!("golden/gap_stats.json")).expect("golden parses");
    for (got, want) in benjamini_hochberg(&g.p).iter().zip(&g.p_bh) {
        assert!((got - want).abs() < 1e-12, "BH {got} vs {want}");
    }
    for w in &g.clustered {
        let vc = VarianceComponents::estimate(&w.r, &w.event);
        let (d, ci, p) = clustered_difference(&w.inside, &w.r, &w.event, &vc);
        assert!((d - w.difference).abs() < 1e-12);
        assert!(
            (ci.0 - w.ci[0]).abs() < 1e-9 && (ci.1 - w.ci[1]).abs() < 1e-9,
            "{ci:?} vs {:?}",
            w.ci
        );
        assert!((p - w.p).abs() < 1e-9 * w.p.max(1e-3), "{p} vs {}", w.p);
    }
}

#[derive(serde::Deserialize)]
struct TobitCase {
    values: Vec<f64>,
    censored: Vec<bool>,
    mean: f64,
    sd: f64,
    at: Vec<f64>,
    mean_beyond: Vec<f64>,
    mean_exp_beyond: Vec<f64>,
}

#[derive(serde::Deserialize)]
struct TobitGolden {
    cases: Vec<TobitCase>,
}

/// The censored-normal fit that imputes worn-through tires on the log scale
/// (`--worn-through tobit`) against scipy's censored maximum likelihood, and
/// its tail means against scipy's truncated normal and a quadrature. The fit
/// is EM stopped at 1e-12 and scipy's a Nelder–Mead optimum (xatol 1e-12):
/// they agree to 1e-7; the tail means are closed forms of the fit, so they
/// are compared at the golden's parameters to 1e-9 relative.
#[test]
fn censored_normal_equals_scipy() {
    let g: TobitGolden =
        serde_json::from_str(include_str!("golden/tobit.json")).expect("golden parses");
    for (i, case) in g.cases.iter().enumerate() {
        let fit = CensoredNormal::fit(&case.values, &case.censored).expect("identified");
        assert!(
            (fit.mean - case.mean).abs() < 1e-7 && (fit.sd - case.sd).abs() < 1e-7,
            "case {i}: {fit:?} vs ({}, {})",
            case.mean,
            case.sd
        );
        let golden = CensoredNormal {
            mean: case.mean,
            sd: case.sd,
        };
        for (j, &c) in case.at.iter().enumerate() {
            let (b, e) = (golden.mean_beyond(c), golden.mean_exp_beyond(c));
            let (want_b, want_e) = (case.mean_beyond[j], case.mean_exp_beyond[j]);
            assert!(
                (b - want_b).abs() < 1e-9 * want_b.abs().max(1.0),
                "case {i} at {c}: {b} vs {want_b}"
            );
            assert!(
                (e - want_e).abs() < 1e-9 * want_e,
                "case {i} at {c}: {e} vs {want_e}"
            );
        }
    }
}

/// An effect at `magnitude` with its threshold moved off the default.
fn planted(kind: EffectKind, magnitude: f64, threshold: f64) -> Effect {
    Effect {
        threshold,
        ..Effect::with_defaults(kind, magnitude)
    }
}

fn settings(work: &std::path::Path) -> ValidateSettings {
    ValidateSettings {
        effects: vec![],
        magnitudes: vec![],
        seeds: vec![],
        clean_seeds: vec![],
        random: vec![],
        preset: tirewear::sim::Preset::Demo,
        scale: 1.0,
        tracks: None,
        rate_hz: 5.0,
        scatter: tirewear::sim::WearScatter::NONE,
        work: work.to_path_buf(),
        keep: false,
        reuse: false,
        gap: GapSettings {
            scoring: ScoringSettings {
                permutations: 999,
                seed: 2026,
                ..Default::default()
            },
            ..Default::default()
        },
        // Only the test of the true-wear measure pays for its second
        // diagnosis per season.
        against_truth: false,
        progress: false,
    }
}

/// Graining planted at magnitude 1 with its threshold moved off the default
/// (81 °C tread bulk): the first term forward selection adds is the graining
/// mechanism on the front axle (truth: fronts carry 5× the rear's graining),
/// and the testing-event gap shrinks close to the ideal.
#[test]
fn planted_graining_is_found_on_the_front_axle() {
    let dir = tempfile::tempdir().unwrap();
    let s = settings(dir.path());
    let e = planted(EffectKind::Graining, 1.0, 81.0);
    let (case, d) = run_case(&Planted::Named(e.clone()), 1, &s).unwrap();
    assert!(case.hit, "{case:?}\n{:?}", d.candidates.first());
    assert!(
        case.first_front_share > 0.7 && case.truth_front_share > 0.7,
        "{case:?}"
    );
    assert!(
        d.steps[1].p_adjusted <= 0.05 && d.steps[1].cv_gain > 0.0,
        "{:?}",
        d.steps[1]
    );
    assert!(case.rmse_diagnosed_pct < case.rmse_baseline_pct, "{case:?}");
    // The planted wear itself, its size fitted with the law on the training
    // events, is sized near the planted size (the simulator's truth) and
    // shrinks the testing gap about as far as the ideal, which knows it.
    assert!((case.oracle_size - 1.0).abs() <= 0.15, "{case:?}");
    assert!(case.oracle_shrinkage > 0.9, "{case:?}");
    // Without wear scatter every tire's factor is 1, so the planted shape
    // the telemetry predicts is the planted shape itself.
    assert_eq!(case.expected_size, case.oracle_size, "{case:?}");
    assert_eq!(case.expected_shrinkage, case.oracle_shrinkage, "{case:?}");
    // Step 3 measures each flagged slice on the very tires step 1 flagged
    // (quantile edges are not re-read from the slice's printed name).
    assert!(!d.slices.is_empty());
    for (slice, size) in d.slices.iter().zip(&d.steps[0].slices) {
        assert_eq!(slice.n, size.n, "{}", slice.name);
    }
}

/// Blistering planted at magnitude 1, threshold 125 °C inner liner: the
/// truth puts almost all of it on the rears; the blistering mechanism is
/// among the terms, the terms' wear follows the planted wear, and the
/// testing-event gap shrinks most of the way to the ideal.
///
/// Not necessarily first: on this season "lateral energy with
/// distance_since_start_m above θ, rear axle" (held-out gain 0.831) and
/// blistering (0.807) fit the left-out tracks alike, and since the runs'
/// scatter is estimated around each car's mean at the event (docs/gap.md,
/// "Set-up forms") the former enters first and blistering second: testing
/// RMSE 9.40 → 4.63 → 2.47 %, where blistering alone, first, had left
/// 2.62 %.
#[test]
fn planted_blistering_is_found() {
    let dir = tempfile::tempdir().unwrap();
    let e = planted(EffectKind::Blistering, 1.0, 125.0);
    let (case, d) = run_case(&Planted::Named(e.clone()), 3, &settings(dir.path())).unwrap();
    assert!(
        added(&d)
            .iter()
            .any(|a| a.starts_with("blistering (energy with a hot inner liner)")),
        "{:?}",
        added(&d)
    );
    assert!(case.truth_front_share < 0.2, "{case:?}");
    assert!(case.terms_correlation >= 0.8, "{case:?}");
    assert!(case.shrinkage_ratio > 0.8, "{case:?}");
}

/// A clean season: nothing is significant, so nothing is added.
#[test]
fn clean_season_reports_no_effect() {
    let dir = tempfile::tempdir().unwrap();
    let (case, d) = run_case(&Planted::Clean, 2, &settings(dir.path())).unwrap();
    assert_eq!(case.significant_terms, 0, "{:?}", d.steps);
    assert!(
        d.candidates
            .iter()
            .all(|c| c.p_adjusted > 0.05 || c.cv_gain <= 0.0)
    );
    // The physics law is calibrated: small bias on the training events.
    assert!(
        d.training.bias_pct.abs() < 0.5 * d.training.rmse_pct,
        "{:?}",
        d.training
    );
}

/// The validation's second measure of the testing events: against every
/// testing tire's true wear (`truth/wear_truth.csv`, `wear_total_pct`),
/// worn-through tires included. At real-data scatter seed 6 wears three
/// testing tires through and six training ones (imputed here, Tobit).
/// Checked by a second route: the law the diagnosis calibrated, applied to
/// each testing tire by hand, against the truth file read here; the
/// diagnosis's own measure, the same law against the measured wear of the
/// tires not worn through; the imputed tires' error against the truth.
#[test]
fn the_testing_gap_is_also_measured_against_every_testing_tires_true_wear() {
    let dir = tempfile::tempdir().unwrap();
    let mut s = settings(dir.path());
    s.scatter = tirewear::sim::WearScatter::REALISTIC;
    s.gap.worn_through = tirewear::gap::report::WornThrough::Tobit;
    s.keep = true;
    s.against_truth = true;
    let (case, d) = run_case(&Planted::Clean, 6, &s).unwrap();
    let t = case
        .against_truth
        .clone()
        .expect("the truth has wear_total_pct");
    let season = dir.path().join("clean-s6");
    let kpis = season.join("kpis.parquet");
    let rows = tirewear::kpi::table::read_parquet(&kpis).unwrap();
    let maps = tirewear::kpi::energy_maps::read_tire_maps(&kpis).unwrap();
    let mut truth = std::collections::BTreeMap::new();
    for rec in csv::Reader::from_path(season.join("truth/wear_truth.csv"))
        .unwrap()
        .deserialize::<std::collections::HashMap<String, String>>()
    {
        let rec = rec.unwrap();
        let wear: f64 = rec["wear_total_pct"].parse().unwrap();
        truth.insert((rec["run"].clone(), rec["wheel"].clone()), wear);
    }
    let law = d.physics.as_ref().expect("the physics baseline");
    let testing: Vec<_> = rows
        .iter()
        .filter(|r| d.testing_events.contains(&r.event))
        .collect();
    let worn = testing
        .iter()
        .filter(|r| r.worn_through_readings > 0.0)
        .count();
    assert_eq!(t.testing_tires, testing.len());
    assert_eq!(t.testing_worn_through, worn);
    assert!(worn > 0, "the case needs a worn-through testing tire");
    let rmse = |pairs: Vec<(f64, f64)>| {
        (pairs.iter().map(|(y, p)| (y - p).powi(2)).sum::<f64>() / pairs.len() as f64).sqrt()
    };
    let predict = |r: &tirewear::kpi::KpiRow| law.predict(r, maps.get(&r.tire_run()));
    let against_truth = rmse(
        testing
            .iter()
            .map(|r| (truth[&(r.run.clone(), r.wheel.to_string())], predict(r)))
            .collect(),
    );
    let measured = rmse(
        testing
            .iter()
            .filter(|r| r.worn_through_readings <= 0.0)
            .map(|r| (r.wear_mean_pct, predict(r)))
            .collect(),
    );
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b;
    assert!(
        close(t.rmse_baseline_pct, against_truth),
        "{t:?} {against_truth}"
    );
    assert!(
        close(case.rmse_baseline_pct, measured),
        "{case:?} {measured}"
    );
    // Not the same measure: the worn-through tires are the season's most worn.
    assert!(
        (against_truth - measured).abs() > 0.05,
        "{against_truth} {measured}"
    );
    // Clean: nothing planted, so the ideal is the law itself, no term is
    // added on either measure and there is no expected shape.
    assert!(t.same_terms);
    assert_eq!(case.significant_terms, 0);
    assert_eq!(t.rmse_diagnosed_pct, t.rmse_baseline_pct);
    assert!(close(t.rmse_ideal_pct, t.rmse_baseline_pct), "{t:?}");
    assert!(t.rmse_expected_pct.is_nan());
    // The imputed training tires: every worn-through one of the training
    // events, each imputed above its measured lower bound.
    let worn_training: Vec<_> = rows
        .iter()
        .filter(|r| r.worn_through_readings > 0.0 && d.training_events.contains(&r.event))
        .collect();
    assert!(!worn_training.is_empty());
    assert_eq!(t.imputed_tires, worn_training.len());
    let mut errors = Vec::new();
    for r in &worn_training {
        let i = d
            .imputed
            .iter()
            .position(|n| *n == format!("{}/{}", r.run, r.wheel))
            .expect("imputed");
        assert!(d.imputed_wear_pct[i] > r.wear_mean_pct, "{}", d.imputed[i]);
        errors.push(d.imputed_wear_pct[i] - truth[&(r.run.clone(), r.wheel.to_string())]);
    }
    let bias = errors.iter().sum::<f64>() / errors.len() as f64;
    assert!(close(t.imputed_bias_pct.abs(), bias.abs()) && t.imputed_bias_pct * bias > 0.0);
}

/// The season preset at scale 0.5: 12 events on 12 tracks, 8 of them in
/// training (the validation matrix of docs/gap.md).
fn season_settings(work: &std::path::Path) -> ValidateSettings {
    let mut s = settings(work);
    s.preset = tirewear::sim::Preset::Season;
    s.scale = 0.5;
    // The tool's default draws: Benjamini–Hochberg over ~50 candidates needs
    // the first p ≤ 0.05/50 = 0.001, the smallest that 999 draws can give.
    s.gap.scoring.permutations = 1999;
    s
}

/// One season-preset season (`effect` planted, or clean) simulated,
/// extracted, diagnosed and scored in a temporary folder.
fn season_case(effect: Option<&Effect>, seed: u64) -> (Case, Diagnosis) {
    let dir = tempfile::tempdir().unwrap();
    let planted = effect.map_or(Planted::Clean, |e| Planted::Named(e.clone()));
    run_case(&planted, seed, &season_settings(dir.path())).unwrap()
}

/// The names of the terms step 3 added, the baseline first.
fn added(d: &Diagnosis) -> Vec<&str> {
    d.steps.iter().map(|s| s.added.as_str()).collect()
}

/// Road abrasion planted at magnitude 2 with its threshold at 0.035 mm
/// (extra wear 2·softplus((micro-texture rms − 0.035 mm)/0.01 mm) times the
/// base wear, a factor per track, about 10 % of the wear variance). Only the
/// eight training tracks can show it: the first term is a road-abrasion
/// term, found by the tracks' severities (the track-level F test), with the
/// truth's axle split (it scales the law's energy, a third of it on the
/// fronts), and the testing-event gap shrinks.
#[test]
fn planted_road_abrasion_is_found_across_tracks() {
    let e = planted(EffectKind::RoadAbrasion, 2.0, 0.035);
    let (case, d) = season_case(Some(&e), 3);
    let added = added(&d);
    assert!(case.hit && case.hit_axle, "{case:?}\n{added:?}");
    assert!(
        (case.truth_front_share - 0.32).abs() < 0.05,
        "the truth's split: {case:?}"
    );
    // On the law's energy the term splits as the truth does (on the raw
    // friction energy the fronts would carry about 0.38).
    assert!(
        (case.first_front_share - case.truth_front_share).abs() < 0.05,
        "{case:?}"
    );
    let first = &d.steps[1];
    assert!(
        first.p_adjusted <= 0.05,
        "{}: {}",
        first.added,
        first.p_adjusted
    );
    assert!(
        case.rmse_diagnosed_pct < 0.5 * case.rmse_baseline_pct,
        "{case:?}"
    );
}

/// A clean season of the season preset, where long stints wear some tires
/// through: those are left out (their readings at ≤ 5 % of the new depth),
/// and nothing is significant. Kept in, with readings of 0.0–0.2 mm where
/// the tread was gone, they made 8 of 10 clean seasons report a term.
#[test]
fn clean_season_preset_reports_no_effect() {
    let (case, d) = season_case(None, 4);
    assert!(
        !d.censored.is_empty(),
        "long stints wear some tires through"
    );
    let added = added(&d);
    assert_eq!(case.significant_terms, 0, "{added:?}");
}

/// Blistering planted strong (magnitude 4, onset at 119 °C inner liner, a
/// third of the wear variance) on the season preset: the calibration
/// without it is far off (s −0.375 against about 0 once the term is in), so
/// step 3 calibrates the law again around the terms. The testing-event gap
/// then shrinks within 20 % of the ideal (the target); with the law
/// only moved along its tangent it was 0.78 of the ideal.
#[test]
fn strong_blistering_shrinks_the_gap_within_20_percent_of_the_ideal() {
    let e = planted(EffectKind::Blistering, 4.0, 119.0);
    let (case, d) = season_case(Some(&e), 2);
    let added = added(&d);
    assert!(case.hit && case.hit_axle, "{case:?}\n{added:?}");
    assert!(case.variance_share > 0.25, "{case:?}");
    assert!(
        (case.shrinkage_ratio - 1.0).abs() <= 0.2,
        "{case:?}\n{added:?}"
    );
    let law = d.physics_with_terms.as_ref().expect("recalibrated law");
    let first = d.physics.as_ref().expect("physics baseline");
    assert!(
        (law.skewness_coefficient - first.skewness_coefficient).abs() > 0.2,
        "the law moved: {} → {}",
        first.skewness_coefficient,
        law.skewness_coefficient
    );
}

/// Graining planted strong (magnitude 4, onset at 84 °C tread bulk) on the
/// season preset, seed 5: the simulator's rears grain a fifth as much per
/// joule as the fronts, which the fronts' graining hides in step 2, and the
/// two coldest tracks (testing events) grain the rears most. The rear-axle
/// graining term may enter once the front-axle one is in (the mechanism
/// already found); no generic KPI follows it; the gap shrinks within 20 %
/// of the ideal (0.59 of it before both rules).
#[test]
fn strong_graining_takes_its_rear_axle_term_and_no_generic_kpi() {
    let e = planted(EffectKind::Graining, 4.0, 84.0);
    let (case, d) = season_case(Some(&e), 5);
    let added = added(&d);
    assert!(case.hit && case.hit_axle, "{case:?}\n{added:?}");
    assert!(
        added.contains(&"graining (lateral energy with a cold tread), rear axle"),
        "{added:?}"
    );
    assert!(added.iter().all(|a| !a.starts_with("KPI ")), "{added:?}");
    assert!(
        (case.shrinkage_ratio - 1.0).abs() <= 0.2,
        "{case:?}\n{added:?}"
    );
}

/// A set-up effect no KPI shows: one car's rear tires wear 1.3 times what
/// their telemetry gives (toe, say), planted in the measured wear of a clean
/// season-preset season (wear is linear in the readings, so scaling
/// `wear_mean_pct` is scaling every reading's wear). The diagnosis adds the
/// set-up term of that car's rear axle first, with a factor near 1.3, and the
/// testing-event gap shrinks; the same season unplanted adds no set-up term.
#[test]
fn a_planted_set_up_effect_is_named_by_its_car_and_axle() {
    use tirewear::gap::report::{Baseline, diagnose};
    let dir = tempfile::tempdir().unwrap();
    let mut s = season_settings(dir.path());
    s.keep = true;
    let (_, clean) = run_case(&Planted::Clean, 9, &s).unwrap();
    assert!(
        !added(&clean).iter().any(|a| a.starts_with("set-up")),
        "{:?}",
        added(&clean)
    );
    let season = dir.path().join("clean-s9");
    let mut rows = tirewear::kpi::table::read_parquet(&season.join("kpis.parquet")).unwrap();
    let maps =
        tirewear::kpi::energy_maps::read_energy_maps(&season.join("kpis.energy_maps.parquet"))
            .unwrap();
    let mut cars: Vec<String> = rows.iter().map(|r| r.car.clone()).collect();
    cars.sort();
    cars.dedup();
    let car = cars[cars.len() / 2].clone();
    for r in rows
        .iter_mut()
        .filter(|r| r.car == car && r.axle == tirewear::Axle::Rear)
    {
        r.wear_mean_pct *= 1.3;
    }
    let gap = GapSettings {
        wlf: tirewear::ingest::compound::read_wlf(&season.join("compounds")).unwrap(),
        ..s.gap.clone()
    };
    let d = diagnose(&rows, &maps, &Baseline::Physics, &gap).unwrap();
    let want = format!("set-up: {car}, rear axle");
    assert_eq!(
        added(&d).get(1).copied(),
        Some(want.as_str()),
        "{:?}",
        added(&d)
    );
    assert!(d.steps[1].set_up);
    assert_eq!(d.steps[1].scope, Some(format!("{car}'s rear axle")));
    let factor = 1.0 + d.steps[1].coefficient;
    assert!((factor - 1.3).abs() < 0.1, "factor {factor}");
    // The final model's factor with its event-bootstrap interval.
    let f = &d.final_terms[0];
    assert!(
        f.ci95.0 <= f.coefficient && f.coefficient <= f.ci95.1,
        "{f:?}"
    );
    println!(
        "final factor {:.3}, 95 % interval {:.3} to {:.3} (planted 1.3)",
        1.0 + f.coefficient,
        1.0 + f.ci95.0,
        1.0 + f.ci95.1
    );
    let rmse = |i: usize| d.steps[i].testing.as_ref().unwrap().rmse_pct;
    println!(
        "set-up {car} rear × 1.3: terms {:?}, factor {factor:.3}, testing RMSE {:.3} -> {:.3} %",
        added(&d),
        rmse(0),
        rmse(1)
    );
    assert!(rmse(1) < 0.8 * rmse(0), "{} -> {}", rmse(0), rmse(1));
    assert!(
        tirewear::gap::report::render_markdown(&d, 12)
            .contains(&format!("Set-up effect: {car}, rear axle wears"))
    );
    // gap.json carries the same finding in words (what `tirewear report` shows).
    assert!(
        d.findings
            .first()
            .is_some_and(|l| l.starts_with(&format!("1. Set-up effect: {car}, rear axle wears"))),
        "{:?}",
        d.findings
    );
    // Without the effect the season's testing RMSE is the ideal.
    let ideal = clean.steps[0].testing.as_ref().unwrap().rmse_pct;
    let shrink = (rmse(0) - rmse(1)) / (rmse(0) - ideal);
    println!("ideal {ideal:.3} %: shrinkage {shrink:.2} of the ideal");
    assert!(shrink > 0.8, "{shrink}");

    // Another group and direction on the same season: one wheel of another
    // car wearing less (0.75×).
    let mut rows = tirewear::kpi::table::read_parquet(&season.join("kpis.parquet")).unwrap();
    for r in rows
        .iter_mut()
        .filter(|r| r.car == cars[0] && r.wheel == tirewear::Wheel::FR)
    {
        r.wear_mean_pct *= 0.75;
    }
    let d = diagnose(&rows, &maps, &Baseline::Physics, &gap).unwrap();
    println!(
        "set-up {} FR × 0.75: terms {:?}, factor {:.3}",
        cars[0],
        added(&d),
        1.0 + d.steps.get(1).map_or(f64::NAN, |s| s.coefficient)
    );
    assert_eq!(
        added(&d).get(1).copied(),
        Some(format!("set-up: {}, FR", cars[0]).as_str())
    );
    assert!((d.steps[1].coefficient + 0.25).abs() < 0.1);

    // A toe-like set-up: the last car's lateral sliding abrades more. Its
    // tires gain wear in proportion to their lateral friction energy (the
    // KPI, J), 30 % of their mean wear on average; the law's wear and the
    // total energy do not follow it.
    let car = cars.last().unwrap().clone();
    let mut rows = tirewear::kpi::table::read_parquet(&season.join("kpis.parquet")).unwrap();
    let of_car = |rows: &[tirewear::kpi::KpiRow], f: fn(&tirewear::kpi::KpiRow) -> f64| {
        let v: Vec<f64> = rows.iter().filter(|r| r.car == car).map(f).collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    let per_joule =
        0.3 * of_car(&rows, |r| r.wear_mean_pct) / of_car(&rows, |r| r.friction_energy_y_j);
    for r in rows.iter_mut().filter(|r| r.car == car) {
        r.wear_mean_pct += per_joule * r.friction_energy_y_j;
    }
    let d = diagnose(&rows, &maps, &Baseline::Physics, &gap).unwrap();
    println!(
        "set-up {car} lateral energy: terms {:?}, form {}",
        added(&d),
        d.steps.get(1).map_or(f64::NAN, |s| s.threshold)
    );
    assert_eq!(
        added(&d).get(1).copied(),
        Some(format!("set-up: {car}").as_str())
    );
    assert_eq!(d.steps[1].threshold, 3.0, "the lateral-energy form");
    assert!(d.steps[1].set_up);
    assert!(
        d.findings.first().is_some_and(|l| l.starts_with(&format!(
            "1. Set-up effect: the lateral energy of {car} abrades"
        ))),
        "{:?}",
        d.findings
    );
    let rmse = |i: usize| d.steps[i].testing.as_ref().unwrap().rmse_pct;
    let shrink = (rmse(0) - rmse(1)) / (rmse(0) - ideal);
    println!(
        "testing RMSE {:.3} -> {:.3} %, shrinkage {shrink:.2} of the ideal",
        rmse(0),
        rmse(1)
    );
    assert!(shrink > 0.8, "{shrink}");
}

/// `--baseline predictions.csv`: the "sim" side from any tool. Predictions of
/// a fitted model written to CSV give the same diagnosis as the model itself
/// (two routes to the same baseline); a malformed file is named by line.
#[test]
fn a_predictions_file_is_a_baseline_like_the_model_it_came_from() {
    use tirewear::gap::report::{Baseline, Predictions, diagnose};
    use tirewear::model::fit::{FitSettings, Method, fit_method, split};
    let dir = tempfile::tempdir().unwrap();
    let mut s = settings(dir.path());
    s.keep = true;
    s.gap.scoring.permutations = 199;
    run_case(&Planted::Clean, 4, &s).unwrap();
    let season = dir.path().join("clean-s4");
    let rows = tirewear::kpi::table::read_parquet(&season.join("kpis.parquet")).unwrap();
    let maps =
        tirewear::kpi::energy_maps::read_energy_maps(&season.join("kpis.energy_maps.parquet"))
            .unwrap();
    let sp = split(&rows, None).unwrap();
    let (model, _) = fit_method(Method::Physical, &sp, &FitSettings::default()).unwrap();
    let csv = season.join("predictions.csv");
    let mut text = String::from("run,wheel,predicted_wear_pct\n");
    for r in &rows {
        let p = model
            .predict_row(r)
            .map_or(String::new(), |p| p.to_string());
        text += &format!("{},{},{p}\n", r.run, r.wheel);
    }
    std::fs::write(&csv, &text).unwrap();
    let from_model = diagnose(&rows, &maps, &Baseline::Model(Box::new(model)), &s.gap).unwrap();
    let from_csv = diagnose(
        &rows,
        &maps,
        &Baseline::Predictions(Predictions::read(&csv).unwrap()),
        &s.gap,
    )
    .unwrap();
    assert_eq!(added(&from_model), added(&from_csv));
    for (a, b) in from_model.steps.iter().zip(&from_csv.steps) {
        assert_eq!(a.training.rmse_pct, b.training.rmse_pct);
        assert_eq!(
            a.testing.as_ref().map(|t| t.rmse_pct),
            b.testing.as_ref().map(|t| t.rmse_pct)
        );
    }
    assert!(from_csv.baseline.contains("predictions.csv"));

    // On the measured wear's scale, or refused: a fraction of the tread, a
    // wear 20 times too large, or predictions for other runs.
    let good = Predictions::read(&csv).unwrap();
    good.check_scale(&rows).unwrap();
    let scaled = |f: f64, prefix: &str| Predictions {
        source: good.source.clone(),
        wear_pct: good
            .wear_pct
            .iter()
            .map(|((run, w), p)| ((format!("{prefix}{run}"), *w), p * f))
            .collect(),
    };
    scaled(1.5, "").check_scale(&rows).unwrap();
    for f in [0.01, 20.0] {
        let e = scaled(f, "").check_scale(&rows).unwrap_err();
        assert!(
            e.contains("predictions.csv") && e.contains("median predicted wear"),
            "{f}: {e}"
        );
    }
    let e = scaled(1.0, "x-").check_scale(&rows).unwrap_err();
    assert!(e.contains("no prediction for a tire"), "{e}");
    // A prediction no wear in % can be is refused by line.
    std::fs::write(
        &csv,
        "run,wheel,predicted_wear_pct\nR1,FL,3.0\nR1,FR,1e308\n",
    )
    .unwrap();
    let err = Predictions::read(&csv).unwrap_err().to_string();
    assert!(
        err.contains("line 3") && err.contains("not a wear in % of the tread"),
        "{err}"
    );

    std::fs::write(&csv, "run,wheel,predicted_wear_pct\nR1,FL,3.0\nR1,XX,2.0\n").unwrap();
    let err = Predictions::read(&csv).unwrap_err().to_string();
    assert!(
        err.contains("predictions.csv") && err.contains("line 3"),
        "{err}"
    );
    std::fs::write(&csv, "run,wheel,predicted_wear_pct\nR1,FL,3.0\nR1,FL,2.0\n").unwrap();
    let err = Predictions::read(&csv).unwrap_err().to_string();
    assert!(
        err.contains("line 3") && err.contains("second prediction"),
        "{err}"
    );
}

/// An effect the tool was not written for, planted outside it: on a clean
/// season, each tire's wear gains a term proportional to the friction energy
/// it dissipated at combined slip (|v_s| / max(|v_x|, 1 m/s)) above 0.08 —
/// computed here from the raw telemetry with a plain f64 loop (time steps
/// from the timestamps), not from the condition maps — scaled to about a
/// quarter of the wear variance. No named mechanism covers it; the generated
/// condition candidates must name a slip condition first and shrink the
/// testing gap most of the way to the clean season's.
#[test]
fn an_unlisted_slip_effect_is_found_among_the_generated_candidates() {
    use tirewear::gap::report::{Baseline, diagnose};
    use tirewear::ingest::telemetry::read_telemetry;
    let dir = tempfile::tempdir().unwrap();
    let mut s = season_settings(dir.path());
    s.keep = true;
    let (_, clean) = run_case(&Planted::Clean, 11, &s).unwrap();
    let season_dir = dir.path().join("clean-s11");
    let season = tirewear::ingest::manifest::Season::open(&season_dir).unwrap();
    // Per tire: energy (MJ) at combined slip above 0.08.
    let mut extra = std::collections::HashMap::new();
    for run in &season.manifest.runs {
        let t = read_telemetry(&season.path(&run.telemetry)).unwrap();
        for (w, wheel) in t.wheels.iter().zip(tirewear::Wheel::ALL) {
            let mut e = 0.0;
            for i in 0..w.len().saturating_sub(1) {
                let dt = (w.time_ns[i + 1] - w.time_ns[i]) as f64 * 1e-9;
                if dt > 1.0 {
                    continue;
                }
                let f = |x: f32| x as f64;
                let v_sx = f(w.vx_mps[i]) - f(w.omega_radps[i]) * f(w.rolling_radius_m[i]);
                let v_sy = f(w.vy_mps[i]);
                let v_s = (v_sx * v_sx + v_sy * v_sy).sqrt();
                if v_s / f(w.vx_mps[i]).abs().max(1.0) > 0.08 {
                    e += (-f(w.fx_n[i]) * v_sx - f(w.fy_n[i]) * v_sy) * dt;
                }
            }
            extra.insert((run.id.clone(), wheel), e * 1e-6);
        }
    }
    let mut rows = tirewear::kpi::table::read_parquet(&season_dir.join("kpis.parquet")).unwrap();
    let var = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len() as f64
    };
    let wear: Vec<f64> = rows.iter().map(|r| r.wear_mean_pct).collect();
    let planted: Vec<f64> = rows.iter().map(|r| extra[&r.tire_run()]).collect();
    assert!(var(&planted) > 0.0, "the condition occurs");
    // a²·var(planted) = var(wear)/3: about a quarter of the new variance.
    let a = (var(&wear) / 3.0 / var(&planted)).sqrt();
    for (r, p) in rows.iter_mut().zip(&planted) {
        r.wear_mean_pct += a * p;
    }
    let maps =
        tirewear::kpi::energy_maps::read_tire_maps(&season_dir.join("kpis.parquet")).unwrap();
    assert!(maps.values().all(|m| m.conditions.is_some()));
    let gap = GapSettings {
        wlf: tirewear::ingest::compound::read_wlf(&season_dir.join("compounds")).unwrap(),
        ..s.gap.clone()
    };
    let d = diagnose(&rows, &maps, &Baseline::Physics, &gap).unwrap();
    let rmse = |d: &Diagnosis, i: usize| d.steps[i].testing.as_ref().unwrap().rmse_pct;
    let ideal = rmse(&clean, 0);
    let last = d.steps.len() - 1;
    let shrink = (rmse(&d, 0) - rmse(&d, last)) / (rmse(&d, 0) - ideal);
    println!(
        "combined slip > 0.08 planted (a = {a:.3} %/MJ): terms {:?} (θ = {}), testing RMSE {:.3} -> {:.3} %, ideal {ideal:.3} %: shrinkage {shrink:.2}",
        added(&d),
        d.steps.get(1).map_or(f64::NAN, |s| s.threshold),
        rmse(&d, 0),
        rmse(&d, last)
    );
    let first = added(&d).get(1).copied().unwrap_or("");
    assert!(first.contains("slip"), "{:?}", added(&d));
    if first.contains("(combined_slip,") {
        // A pair led by the planted condition, above its edge (the second
        // condition may be one that holds nearly everywhere, as relative
        // load above 0.7): the findings give the combined-slip edge first.
        let md = tirewear::gap::report::render_markdown(&d, 12);
        let line = md
            .lines()
            .find(|l| l.starts_with("1. Energy with (combined slip, "))
            .unwrap_or_else(|| panic!("{md}"));
        let (_, after) = line.split_once(" above/").expect("above the slip edge");
        let open = after.find('(').expect("the edges");
        let edge: f64 = after[open + 1..]
            .split(',')
            .next()
            .unwrap()
            .trim()
            .parse()
            .unwrap();
        assert!(
            (edge - 0.08).abs() <= 0.021,
            "combined-slip edge {edge}: {line}"
        );
    } else if first.contains("combined_slip") {
        let theta = d.steps[1].threshold;
        assert!((theta - 0.08).abs() <= 0.021, "θ = {theta}");
        // The findings say it in words, with the threshold in place of θ
        // (then the share of the energy it holds, then the factor).
        let md = tirewear::gap::report::render_markdown(&d, 12);
        let said = format!(
            "1. Energy with combined slip above {} (",
            tirewear::gap::candidates::significant(theta)
        );
        let line = md
            .lines()
            .find(|l| l.starts_with(&said))
            .unwrap_or_else(|| panic!("{md}"));
        assert!(line.contains(" abrades "), "{line}");
    }
    assert!(shrink > 0.6, "{shrink}");
}

/// `tirewear bench --only gap` times the diagnosis of the demo season
/// (10 events × 2 cars × 4 runs × 4 wheels = 320 tire-runs) on one thread
/// and on all, and states each time against the 10 s target.
#[test]
fn bench_gap_lines_time_the_demo_diagnosis_against_its_target() {
    use tirewear::bench::{BenchOptions, BenchParts, run_bench};
    let r = run_bench(&BenchOptions {
        small: true,
        gpu: false,
        repeats: 1,
        parts: BenchParts::Gap,
        season: None,
    });
    assert!(r.notes.is_empty(), "{:?}", r.notes);
    let engines: Vec<&str> = r.lines.iter().map(|l| l.engine.as_str()).collect();
    assert_eq!(engines.len(), 2, "{engines:?}");
    assert_eq!(engines[0], "tirewear, 1 thread");
    for l in &r.lines {
        assert_eq!(
            (l.kernel.as_str(), l.size.as_str()),
            ("gap, demo", "320 tire-runs")
        );
        assert_eq!(l.reference, "target 10 s");
        assert!((l.vs_memory_pass * l.seconds - 10.0).abs() < 1e-9);
        assert!((l.items_per_s * l.seconds - 320.0).abs() < 1e-9);
    }
}

/// `gap validate --hypotheses FILE` reads the user's hypotheses before it
/// simulates anything: a file with an unknown variable is refused with its
/// name, the effect and the variable, exit code 1, and no season written.
#[test]
fn validate_refuses_a_bad_hypotheses_file_before_simulating() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("mine.toml");
    std::fs::write(
        &file,
        "[[effect]]\nname = \"hot\"\nexpression = \"t_surfce > 90\"\n",
    )
    .unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_tirewear"))
        .args(["--quiet", "gap", "validate", "--effects", "none"])
        .args(["--clean-seeds", "1", "--hypotheses"])
        .arg(&file)
        .arg("--out")
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    for part in [
        "mine.toml",
        "effect 1 ('hot')",
        "unknown variable 't_surfce'",
    ] {
        assert!(err.contains(part), "{part} not in {err}");
    }
    assert!(!dir.path().join("out").exists());
}

/// Values a user can type that once panicked, aborted or silently did
/// nothing are refused before anything is read or simulated, with the
/// value named: a hypothesis nested past the stack (an abort), a string
/// function that panics inside "é", 2^64 - 1 permutations (a capacity
/// overflow), 2^64 - 1 generated seasons, a seed range past the largest.
#[test]
fn values_that_once_panicked_or_aborted_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let deep = dir.path().join("deep.toml");
    let nest = 30_000;
    std::fs::write(
        &deep,
        format!(
            "[[effect]]\nname = \"deep\"\nexpression = \"{}t_surface{}\"\n",
            "(".repeat(nest),
            ")".repeat(nest)
        ),
    )
    .unwrap();
    let utf = dir.path().join("utf.toml");
    std::fs::write(
        &utf,
        "[[effect]]\nname = \"utf\"\nexpression = \"t_surface * len(str::substring(\\\"é\\\", 0, 1))\"\n",
    )
    .unwrap();
    let out = dir.path().join("out");
    let (deep, utf, out) = (
        deep.to_str().unwrap(),
        utf.to_str().unwrap(),
        out.to_str().unwrap(),
    );
    let max = u64::MAX.to_string();
    let kpis = dir.path().join("none.parquet");
    let kpis = kpis.to_str().unwrap();
    for (args, code, said) in [
        (vec!["gap", kpis, "--effects", deep], 1, "60009 bytes long"),
        (
            vec!["gap", kpis, "--effects", utf],
            1,
            "unknown function 'len'",
        ),
        (
            vec!["gap", kpis, "--permutations", &max],
            1,
            "at most 10000",
        ),
        (
            vec!["gap", "validate", "--permutations", &max],
            1,
            "at most 10000",
        ),
        (
            vec!["gap", "validate", "--random", &max, "--random-from", "0"],
            2,
            "is not in 0..=100000",
        ),
        (
            vec!["gap", "validate", "--random", "2", "--random-from", &max],
            1,
            "passes the largest seed",
        ),
    ] {
        let run = std::process::Command::new(env!("CARGO_BIN_EXE_tirewear"))
            .arg("--quiet")
            .args(&args)
            .args(["--out", out])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(code), "{args:?}: {err}");
        assert!(err.contains(said), "{args:?}: {err}");
    }
    assert!(!dir.path().join("out").exists());
}

/// `gap validate --hypotheses FILE` scores the user's hypotheses in every
/// season and reports how each fared: on the demo season with blistering
/// planted (seed 3, magnitude 1) a hypothesis restating it (energy with the
/// inner liner above θ on the rear axle, where the truth puts nearly all
/// of it) is significant in the first round; on a clean season (seed 2) it
/// is not, and neither is the law's own energy offered again.
#[test]
fn validate_scores_the_users_hypotheses_in_every_season() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("mine.toml");
    std::fs::write(
        &file,
        "[[effect]]\nname = \"hot liner\"\nexpression = \"t_inner > theta\"\n\
         thresholds = [110, 115, 120, 125, 130, 135]\naxle = \"rear\"\n\n\
         [[effect]]\nname = \"all energy\"\nexpression = \"1\"\n",
    )
    .unwrap();
    let out = dir.path().join("out");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_tirewear"))
        .args(["--quiet", "gap", "validate", "--preset", "demo"])
        .args([
            "--effects",
            "blistering",
            "--magnitudes",
            "1",
            "--seeds",
            "3",
        ])
        .args([
            "--clean-seeds",
            "2",
            "--permutations",
            "999",
            "--hypotheses",
        ])
        .arg(&file)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("validate.json")).unwrap()).unwrap();
    let seasons = json.as_array().unwrap();
    assert_eq!(seasons.len(), 2);
    let outcome = |season: &serde_json::Value, name: &str| {
        season["hypotheses"]
            .as_array()
            .unwrap()
            .iter()
            .find(|h| h["name"] == name)
            .unwrap_or_else(|| panic!("{name} not scored in {season}"))
            .clone()
    };
    let (planted, clean) = (&seasons[0], &seasons[1]);
    assert_eq!(planted["seed"], 3);
    assert_eq!(clean["first_term"], serde_json::Value::Null);
    let hot = outcome(planted, "user: hot liner");
    assert_eq!(hot["significant"], true, "{hot}");
    assert!(hot["p_adjusted"].as_f64().unwrap() <= 0.05, "{hot}");
    assert!(hot["cv_gain"].as_f64().unwrap() > 0.0, "{hot}");
    for name in ["user: hot liner", "user: all energy"] {
        let h = outcome(clean, name);
        assert_eq!(h["significant"], false, "{h}");
        assert_eq!(h["added_as"], serde_json::Value::Null, "{h}");
    }
    // The report's table counts them over both seasons.
    let md = std::fs::read_to_string(out.join("validate.md")).unwrap();
    let row = md
        .lines()
        .find(|l| l.starts_with("| user: hot liner | 2 | 1 | "))
        .unwrap_or_else(|| panic!("{md}"));
    assert!(md.contains("| user: all energy | 2 | "), "{md}");
    let added_first = (planted["hypotheses"][0]["added_as"] == 1) as usize;
    assert!(
        row.starts_with(&format!("| user: hot liner | 2 | 1 | {added_first} | ")),
        "{row}"
    );
}
