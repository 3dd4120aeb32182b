//! The gap diagnosis, started (issue 6): its statistics against statsmodels
//! and scipy (goldens from tests/oracles/gap_oracle.py), and step 1 on the
//! demo season, where the truth says the fronts carry irregular wear that the
//! frictional-energy law does not model.

mod common;

use tirewear::gap::report::{Baseline, diagnose};
use tirewear::gap::stats::{benjamini_hochberg, welch};

#[derive(serde::Deserialize)]
struct Welch {
    a: Vec<f64>,
    b: Vec<f64>,
    difference: f64,
    ci: [f64; 2],
    p: f64,
}

#[derive(serde::Deserialize)]
struct Golden {
    p: Vec<f64>,
    p_bh: Vec<f64>,
    welch: Vec<Welch>,
}

#[test]
fn statistics_equal_statsmodels_and_scipy() {
    let g: Golden =
        serde_json::from_str(include_str!("golden/gap_stats.json")).expect("golden parses");
    for (got, want) in benjamini_hochberg(&g.p).iter().zip(&g.p_bh) {
        assert!((got - want).abs() < 1e-12, "BH {got} vs {want}");
    }
    for w in &g.welch {
        let (d, ci, p) = welch(&w.a, &w.b);
        assert!((d - w.difference).abs() < 1e-12);
        assert!(
            (ci.0 - w.ci[0]).abs() < 1e-9 && (ci.1 - w.ci[1]).abs() < 1e-9,
            "{ci:?} vs {:?}",
            w.ci
        );
        assert!((p - w.p).abs() < 1e-9 * w.p.max(1e-3), "{p} vs {}", w.p);
    }
}

#[test]
fn demo_gap_lies_on_the_front_axle() {
    let dir = tempfile::tempdir().unwrap();
    let rows = common::demo_kpis(dir.path());
    let maps =
        tirewear::kpi::energy_map::read_energy_maps(&dir.path().join("kpis.energy_maps.parquet"))
            .unwrap();
    let d = diagnose(&rows, &maps, &Baseline::Physics, None, 0.05).unwrap();
    // Truth: irregular wear adds 5–45 % of base wear on the fronts only.
    let front = d
        .slices
        .iter()
        .find(|s| s.name == "axle = front")
        .expect("front axle flagged");
    assert!(
        front.mean_residual_pct > 0.0 && front.ci_pct.0 > 0.0,
        "{front:?}"
    );
    assert!(d.slices.iter().all(|s| s.p_adjusted <= 0.05));
    assert!(
        d.slices
            .iter()
            .all(|s| s.name != "axle = rear" || s.mean_residual_pct < 0.0)
    );
    // The physics law is calibrated: small bias on the training events.
    assert!(
        d.training.bias_pct.abs() < 0.5 * d.training.rmse_pct,
        "{:?}",
        d.training
    );
}
