//! The demo season must show the paper's findings (section 4.3), measured on
//! what an analyst sees (spot readings) against the true friction energy:
//! per-track wear vs friction energy close to linear, slopes rising with
//! surface temperature, residuals following road skewness more on the rear
//! axle than on the front, and extra irregular wear on the fronts only.

use std::collections::HashMap;
use tirewear::Axle;
use tirewear::ingest::telemetry::Encoding;
use tirewear::ingest::wear::read_wear_csv;
use tirewear::model::data::correlation as corr;
use tirewear::sim::{Preset, SimOptions, simulate};

#[derive(serde::Deserialize)]
struct Truth {
    run: String,
    track: String,
    wheel: tirewear::Wheel,
    friction_energy_j: f64,
    mean_surface_c: f64,
    wear_irregular_pct: f64,
}

/// Least-squares line y = a + b x: (a, b, R²).
fn line(x: &[f64], y: &[f64]) -> (f64, f64, f64) {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx).powi(2)).sum();
    let b = sxy / sxx;
    let a = my - b * mx;
    let sse: f64 = x.iter().zip(y).map(|(u, v)| (v - a - b * u).powi(2)).sum();
    let sst: f64 = y.iter().map(|v| (v - my).powi(2)).sum();
    (a, b, 1.0 - sse / sst)
}

/// Statistics of one demo season: per axle (front, rear) the median per-track R²,
/// the correlation of per-track slopes with surface temperature, and the
/// correlation of residuals with skewness.
struct Findings {
    median_r2: [f64; 2],
    slope_vs_temperature: [f64; 2],
    residual_vs_skewness: [f64; 2],
}

#[test]
fn demo_season_shows_the_papers_findings() {
    // Eight tracks make a correlation across tracks noisy: judge the mean over three seeds.
    let f: Vec<Findings> = [7, 8, 9].into_iter().map(findings).collect();
    let mean = |g: fn(&Findings) -> f64| f.iter().map(g).sum::<f64>() / f.len() as f64;
    for (i, axle) in ["front", "rear"].into_iter().enumerate() {
        for s in &f {
            assert!(
                s.median_r2[i] > 0.75,
                "{axle}: per-track wear vs energy median R² {:.2}",
                s.median_r2[i]
            );
        }
        let c = match i {
            0 => mean(|s| s.slope_vs_temperature[0]),
            _ => mean(|s| s.slope_vs_temperature[1]),
        };
        assert!(
            c > 0.25,
            "{axle}: mean correlation of per-track slope with surface temperature {c:.2}"
        );
    }
    let (front, rear) = (
        mean(|s| s.residual_vs_skewness[0]),
        mean(|s| s.residual_vs_skewness[1]),
    );
    assert!(
        rear > 0.2 && rear > front,
        "residual vs skewness: front {front:.2}, rear {rear:.2}"
    );
}

fn findings(seed: u64) -> Findings {
    let dir = tempfile::tempdir().unwrap();
    simulate(&SimOptions {
        preset: Preset::Demo,
        scale: 1.0,
        tracks: None,
        seed,
        effects: vec![],
        generated: None,
        scatter: tirewear::sim::WearScatter::NONE,
        encoding: Encoding::Block,
        rate_hz: Some(5.0), // the findings do not need 20 Hz; keeps the test quick
        out: dir.path().to_path_buf(),
        sensor_noise: true,
        logger_export: None,
        progress: false,
    })
    .unwrap();
    let truth: Vec<Truth> = csv::Reader::from_path(dir.path().join("truth/wear_truth.csv"))
        .unwrap()
        .deserialize()
        .map(Result::unwrap)
        .collect();
    assert!(truth.len() >= 280);
    let settings: toml::Value =
        toml::from_str(&std::fs::read_to_string(dir.path().join("truth/settings.toml")).unwrap())
            .unwrap();
    let skew: HashMap<String, f64> = settings["tracks"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| {
            (
                t["id"].as_str().unwrap().to_string(),
                t["road"]["skewness"].as_float().unwrap(),
            )
        })
        .collect();
    // Measured mean wear: all readings of a tire, in % of the new depth.
    let mut measured: HashMap<(String, tirewear::Wheel), (f64, f64)> = HashMap::new();
    for r in read_wear_csv(&dir.path().join("wear/readings.csv")).unwrap() {
        let e = measured.entry((r.run.clone(), r.wheel)).or_default();
        e.0 += 100.0 * (r.new_depth_mm - r.depth_mm) / r.new_depth_mm;
        e.1 += 1.0;
    }
    let wear = |t: &Truth| {
        let (s, n) = measured[&(t.run.clone(), t.wheel)];
        s / n
    };
    let mut tracks: Vec<&str> = truth.iter().map(|t| t.track.as_str()).collect();
    tracks.sort();
    tracks.dedup();
    let mut out = Findings {
        median_r2: [0.0; 2],
        slope_vs_temperature: [0.0; 2],
        residual_vs_skewness: [0.0; 2],
    };
    for (i, axle) in [Axle::Front, Axle::Rear].into_iter().enumerate() {
        let rows: Vec<&Truth> = truth.iter().filter(|t| t.wheel.axle() == axle).collect();
        let (mut slopes, mut temps, mut r2s) = (vec![], vec![], vec![]);
        for tr in &tracks {
            let sub: Vec<&&Truth> = rows.iter().filter(|t| t.track == *tr).collect();
            let e: Vec<f64> = sub.iter().map(|t| t.friction_energy_j / 1e6).collect();
            let w: Vec<f64> = sub.iter().map(|t| wear(t)).collect();
            let (_, b, r2) = line(&e, &w);
            slopes.push(b);
            r2s.push(r2);
            temps.push(sub.iter().map(|t| t.mean_surface_c).sum::<f64>() / sub.len() as f64);
        }
        r2s.sort_by(f64::total_cmp);
        out.median_r2[i] = r2s[r2s.len() / 2];
        out.slope_vs_temperature[i] = corr(&slopes, &temps);
        // Residuals of wear ~ E + E·T (energy with its temperature factor) against skewness.
        let e: Vec<f64> = rows.iter().map(|t| t.friction_energy_j / 1e6).collect();
        let et: Vec<f64> = rows
            .iter()
            .map(|t| t.friction_energy_j / 1e6 * t.mean_surface_c)
            .collect();
        let w: Vec<f64> = rows.iter().map(|t| wear(t)).collect();
        let res = residuals2(&e, &et, &w);
        let sk: Vec<f64> = rows.iter().map(|t| skew[&t.track]).collect();
        out.residual_vs_skewness[i] = corr(&res, &sk);
        let irregular: f64 = rows.iter().map(|t| t.wear_irregular_pct).sum();
        assert_eq!(
            irregular > 0.0,
            axle == Axle::Front,
            "irregular wear on the fronts only"
        );
    }
    out
}

/// Residuals of y on [1, x1, x2] by the normal equations (3x3, Cramer's rule).
fn residuals2(x1: &[f64], x2: &[f64], y: &[f64]) -> Vec<f64> {
    let cols = [vec![1.0; y.len()], x1.to_vec(), x2.to_vec()];
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(u, v)| u * v).sum::<f64>();
    let m: Vec<Vec<f64>> = (0..3)
        .map(|i| (0..3).map(|j| dot(&cols[i], &cols[j])).collect())
        .collect();
    let rhs: Vec<f64> = (0..3).map(|i| dot(&cols[i], y)).collect();
    let det3 = |a: &Vec<Vec<f64>>| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let d = det3(&m);
    let beta: Vec<f64> = (0..3)
        .map(|k| {
            let mut mk = m.clone();
            for i in 0..3 {
                mk[i][k] = rhs[i];
            }
            det3(&mk) / d
        })
        .collect();
    (0..y.len())
        .map(|i| y[i] - (beta[0] + beta[1] * x1[i] + beta[2] * x2[i]))
        .collect()
}
