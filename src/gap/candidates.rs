//! Step 2 of the diagnosis, which unmodelled effect explains the gap: a
//! library of candidate effects, each a physical mechanism computed from the
//! energy maps or the KPIs with a threshold scanned inside the
//! cross-validation, plus every KPI the baseline does not use. Each candidate
//! is scored by leave-one-event-out cross-validation of
//! `residual ~ a + c·feature` against `residual ~ a`, with a one-sided t-test
//! of the per-event held-out gains and Benjamini–Hochberg over candidates.

use super::stats::benjamini_hochberg;
use crate::kpi::KpiRow;
use crate::kpi::energy_map::{EnergyMaps, SLIDING_SPEED_BINS, T_INNER_BINS, T_SURFACE_BINS};
use crate::model::data::candidate_inputs;
use statrs::distribution::{ContinuousCDF, StudentsT};

/// How a candidate's feature is computed for a row at threshold θ.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub enum Feature {
    /// Friction energy (MJ) with the surface below θ °C (graining: a cold tread).
    ColdSurfaceEnergy,
    /// Friction energy (MJ) with the inner liner above θ °C (blistering).
    HotInnerEnergy,
    /// Friction energy (MJ) with the surface above θ °C (thermal degradation).
    HotSurfaceEnergy,
    /// Friction energy (MJ) at sliding speeds above θ m/s.
    FastSlidingEnergy,
    /// Friction energy (MJ) on roads whose micro-texture Ra is above θ mm (road abrasion).
    RoughRoadEnergy,
    /// Total friction energy (MJ); with an axle, the mechanism is "extra wear
    /// on that axle per joule" (the paper's irregular front wear).
    Energy,
    /// A KPI's value (no threshold).
    Kpi(&'static str),
}

/// A named candidate with its threshold grid, acting on one axle or both.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Candidate {
    pub name: String,
    pub feature: Feature,
    pub thresholds: Vec<f64>,
    /// "front", "rear", or None for both axles.
    pub axle: Option<&'static str>,
}

/// The library: five mechanisms and every KPI the physics baseline does not use.
pub fn library(rows: &[&KpiRow]) -> Vec<Candidate> {
    let steps = |lo: f64, hi: f64, step: f64| -> Vec<f64> {
        (0..)
            .map(|i| lo + step * i as f64)
            .take_while(|v| *v <= hi + 1e-9)
            .collect()
    };
    let mut micro: Vec<f64> = rows
        .iter()
        .map(|r| r.ra_micro_mm)
        .filter(|v| v.is_finite())
        .collect();
    micro.sort_by(f64::total_cmp);
    micro.dedup();
    let mechanisms: Vec<(&str, Feature, Vec<f64>)> = vec![
        (
            "graining (energy with a cold surface)",
            Feature::ColdSurfaceEnergy,
            steps(40.0, 90.0, 5.0),
        ),
        (
            "blistering (energy with a hot inner liner)",
            Feature::HotInnerEnergy,
            steps(90.0, 140.0, 5.0),
        ),
        (
            "thermal degradation (energy with a hot surface)",
            Feature::HotSurfaceEnergy,
            steps(70.0, 120.0, 5.0),
        ),
        (
            "fast sliding (energy at high sliding speed)",
            Feature::FastSlidingEnergy,
            steps(0.5, 5.0, 0.5),
        ),
        (
            "road abrasion (energy on micro-rough roads)",
            Feature::RoughRoadEnergy,
            micro,
        ),
    ];
    let mut out = Vec::new();
    // Each mechanism on both axles and on each axle alone (the paper treats
    // the axles apart: steering, irregular front wear).
    for (name, feature, thresholds) in mechanisms {
        for axle in [None, Some("front"), Some("rear")] {
            out.push(Candidate {
                name: match axle {
                    None => name.to_string(),
                    Some(a) => format!("{name}, {a} axle"),
                },
                feature,
                thresholds: thresholds.clone(),
                axle,
            });
        }
    }
    for axle in ["front", "rear"] {
        out.push(Candidate {
            name: format!("extra wear per joule, {axle} axle (irregular wear)"),
            feature: Feature::Energy,
            thresholds: vec![f64::NAN],
            axle: Some(axle),
        });
    }
    for c in candidate_inputs() {
        if !matches!(c, "friction_energy_j" | "t_surface_avg_c") {
            out.push(Candidate {
                name: format!("KPI {c}"),
                feature: Feature::Kpi(c),
                thresholds: vec![f64::NAN],
                axle: None,
            });
        }
    }
    out
}

/// The feature of one row at threshold θ.
pub fn feature(f: Feature, r: &KpiRow, maps: Option<&EnergyMaps>, theta: f64) -> f64 {
    let mj = 1e-6;
    let sum_surface_inner = |keep: &dyn Fn(f64, f64) -> bool| -> f64 {
        maps.map_or(f64::NAN, |m| {
            let mut s = 0.0;
            for i in 0..T_SURFACE_BINS.n {
                for j in 0..T_INNER_BINS.n {
                    if keep(T_SURFACE_BINS.lower_edge(i), T_INNER_BINS.lower_edge(j)) {
                        s += m.surface_inner[i * T_INNER_BINS.n + j];
                    }
                }
            }
            s * mj
        })
    };
    match f {
        Feature::ColdSurfaceEnergy => {
            sum_surface_inner(&|ts, _| ts + T_SURFACE_BINS.width <= theta)
        }
        Feature::HotInnerEnergy => sum_surface_inner(&|_, ti| ti >= theta),
        Feature::HotSurfaceEnergy => sum_surface_inner(&|ts, _| ts >= theta),
        Feature::FastSlidingEnergy => maps.map_or(f64::NAN, |m| {
            let mut s = 0.0;
            for v in 0..SLIDING_SPEED_BINS.n {
                if SLIDING_SPEED_BINS.lower_edge(v) >= theta {
                    s += m.speed_surface[v * T_SURFACE_BINS.n..(v + 1) * T_SURFACE_BINS.n]
                        .iter()
                        .sum::<f64>();
                }
            }
            s * mj
        }),
        Feature::RoughRoadEnergy => {
            if r.ra_micro_mm >= theta {
                r.friction_energy_j * mj
            } else {
                0.0
            }
        }
        Feature::Energy => r.friction_energy_j * mj,
        Feature::Kpi(c) => r.number(c).unwrap_or(f64::NAN),
    }
}

/// A candidate's feature for a row: zero on the other axle.
pub fn candidate_feature(c: &Candidate, r: &KpiRow, maps: Option<&EnergyMaps>, theta: f64) -> f64 {
    match c.axle {
        Some(a) if r.axle != a => 0.0,
        _ => feature(c.feature, r, maps, theta),
    }
}

/// Least squares of y on [1, x]: (a, c).
fn line(x: &[f64], y: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxx: f64 = x.iter().map(|v| (v - mx).powi(2)).sum();
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let c = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    (my - c * mx, c)
}

/// A candidate's fit: threshold θ and `residual ≈ a + c·feature`, chosen by SSE on `rows`.
pub fn fit_candidate(
    c: &Candidate,
    x: &[Vec<f64>],
    res: &[f64],
    rows: &[usize],
) -> (usize, f64, f64, f64) {
    let mut best = (0, 0.0, 0.0, f64::INFINITY);
    for t in 0..c.thresholds.len() {
        let xs: Vec<f64> = rows.iter().map(|&i| x[i][t]).collect();
        let ys: Vec<f64> = rows.iter().map(|&i| res[i]).collect();
        let (a, k) = line(&xs, &ys);
        let sse: f64 = xs
            .iter()
            .zip(&ys)
            .map(|(x, y)| (y - a - k * x).powi(2))
            .sum();
        if sse < best.3 {
            best = (t, a, k, sse);
        }
    }
    best
}

/// How a candidate scored.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Score {
    pub name: String,
    pub feature: Feature,
    pub axle: Option<&'static str>,
    /// Threshold chosen on all rows given (NaN for KPI candidates).
    pub threshold: f64,
    /// Coefficient c of `residual ≈ a + c·feature` (% per MJ, or % per KPI unit).
    pub coefficient: f64,
    /// 1 − held-out SSE(with)/held-out SSE(intercept only), over events left out in turn.
    pub cv_gain: f64,
    /// One-sided t-test of the per-event held-out SSE reductions.
    pub p: f64,
    /// Benjamini–Hochberg over the candidates.
    pub p_adjusted: f64,
}

/// Scores every candidate on rows with residuals; `maps` per row (None: map candidates are NaN there).
pub fn rank(
    rows: &[&KpiRow],
    maps: &[Option<&EnergyMaps>],
    res: &[f64],
    library: &[Candidate],
) -> Vec<Score> {
    let mut events: Vec<&str> = rows.iter().map(|r| r.event.as_str()).collect();
    events.sort();
    events.dedup();
    let all: Vec<usize> = (0..rows.len()).collect();
    let mut scores: Vec<Score> = library
        .iter()
        .filter_map(|c| {
            let x: Vec<Vec<f64>> = rows
                .iter()
                .zip(maps)
                .map(|(r, m)| {
                    c.thresholds
                        .iter()
                        .map(|&t| candidate_feature(c, r, *m, t))
                        .collect()
                })
                .collect();
            if x.iter().flatten().any(|v| !v.is_finite()) {
                return None;
            }
            let (mut with, mut without, mut gains) = (0.0, 0.0, Vec::new());
            for e in &events {
                let (test, train): (Vec<usize>, Vec<usize>) =
                    all.iter().partition(|&&i| rows[i].event == *e);
                if test.is_empty() || train.len() < 10 {
                    continue;
                }
                let (t, a, k, _) = fit_candidate(c, &x, res, &train);
                let a0 = train.iter().map(|&i| res[i]).sum::<f64>() / train.len() as f64;
                let sse_with: f64 = test
                    .iter()
                    .map(|&i| (res[i] - a - k * x[i][t]).powi(2))
                    .sum();
                let sse_without: f64 = test.iter().map(|&i| (res[i] - a0).powi(2)).sum();
                with += sse_with;
                without += sse_without;
                gains.push((sse_without - sse_with) / test.len() as f64);
            }
            let n = gains.len() as f64;
            let m = gains.iter().sum::<f64>() / n;
            let sd = (gains.iter().map(|g| (g - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            let p = if sd > 0.0 && n > 2.0 {
                1.0 - StudentsT::new(0.0, 1.0, n - 1.0)
                    .expect("df")
                    .cdf(m / (sd / n.sqrt()))
            } else {
                1.0
            };
            let (t, _, k, _) = fit_candidate(c, &x, res, &all);
            Some(Score {
                name: c.name.clone(),
                feature: c.feature,
                axle: c.axle,
                threshold: c.thresholds[t],
                coefficient: k,
                cv_gain: 1.0 - with / without,
                p,
                p_adjusted: f64::NAN,
            })
        })
        .collect();
    let adj = benjamini_hochberg(&scores.iter().map(|s| s.p).collect::<Vec<_>>());
    for (s, a) in scores.iter_mut().zip(adj) {
        s.p_adjusted = a;
    }
    scores.sort_by(|a, b| b.cv_gain.total_cmp(&a.cv_gain));
    scores
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_planted_cold_surface_term_ranks_first_with_its_threshold() {
        // 10 events × 12 tires. Each tire's map puts energy at surface temperatures
        // 42.5 … 97.5 °C in varying amounts; the residual is 0.5 %/MJ of the energy
        // with the surface below 60 °C, plus a small deterministic wobble.
        let mut rows = Vec::new();
        let mut maps = Vec::new();
        for e in 0..10 {
            for t in 0..12 {
                let k = e * 12 + t;
                let mut m = EnergyMaps::new();
                let mut cold = 0.0;
                for (b, ts) in (4..16).zip((0..).map(|i| 42.5 + 5.0 * i as f64)) {
                    let mj = 1.0 + ((k * 7 + b * 3) % 11) as f64;
                    m.add(ts, 100.0, 1.0, mj * 1e6);
                    if ts < 60.0 {
                        cold += mj;
                    }
                }
                rows.push(KpiRow {
                    event: format!("E{e:02}"),
                    run: format!("R{k}"),
                    friction_energy_j: m.total(),
                    ra_micro_mm: 0.1,
                    wear_mean_pct: 0.5 * cold + 0.01 * ((k * 13) % 5) as f64,
                    ..Default::default()
                });
                maps.push(m);
            }
        }
        let refs: Vec<&KpiRow> = rows.iter().collect();
        let mref: Vec<Option<&EnergyMaps>> = maps.iter().map(Some).collect();
        let res: Vec<f64> = rows.iter().map(|r| r.wear_mean_pct).collect();
        let lib: Vec<Candidate> = library(&refs).into_iter().take(15).collect();
        let s = rank(&refs, &mref, &res, &lib);
        assert!(matches!(s[0].feature, Feature::ColdSurfaceEnergy), "{s:?}");
        assert_eq!(s[0].threshold, 60.0);
        assert!(
            (s[0].coefficient - 0.5).abs() < 0.01,
            "{}",
            s[0].coefficient
        );
        assert!(s[0].cv_gain > 0.95 && s[0].p_adjusted < 0.01, "{:?}", s[0]);
    }
}
