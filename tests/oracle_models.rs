//! OLS against statsmodels and PCA against scikit-learn on a committed table
//! (tests/oracles/models_oracle.py), the network's conformal interval width
//! against numpy (tests/oracles/conformal_oracle.py, exact: it picks one
//! of its inputs). Tolerances: relative 1e-8 on
//! coefficients, standard errors and R² (QR versus statsmodels' pinv: both
//! f64, the design is well conditioned after nothing but an intercept);
//! p-values absolute 1e-9 (they are down to ~1e-200, where only the
//! magnitude matters; the golden regenerated with another numpy build moved
//! one of 0.108 by 2.3e-10); loadings up to sign. Predictions and their interval
//! bounds: absolute 1e-6 % of the tread (a prediction of 6 % sums an
//! intercept of −109 % and terms as large, so the coefficients' 1e-9
//! relative differences come out near 1e-7 %; Student's t quantile by
//! statrs' inverse regularised beta against scipy's).

use serde_json::Value;
use std::path::PathBuf;
use tirewear::model::interval::{IntervalLevel, conformal_half_width};
use tirewear::model::lm::{LeastSquares, LmSettings, levenberg_marquardt};
use tirewear::model::ols::OlsSettings;
use tirewear::model::pca::PcaSettings;
use tirewear::model::{Dataset, Fit, Predict};

#[derive(serde::Deserialize)]
struct Row {
    axle: String,
    skewness: f64,
    kurtosis: f64,
    t_surface_avg_c: f64,
    friction_energy_j: f64,
    contact_patch_mm2: f64,
    loss_factor: f64,
    fz_avg_n: f64,
    pressure_avg_pa: f64,
    sliding_distance_m: f64,
    t_inner_avg_c: f64,
    hurst: f64,
    wear_mean_pct: f64,
}

fn table() -> Vec<Row> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/model_table.csv");
    csv::Reader::from_path(p)
        .unwrap()
        .deserialize()
        .map(Result::unwrap)
        .collect()
}

fn golden() -> Value {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden/models.json");
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn strings(v: &Value) -> Vec<String> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_str().unwrap().to_string())
        .collect()
}

fn close(what: &str, got: f64, want: f64, rtol: f64) {
    assert!(
        (got - want).abs() <= rtol * want.abs() + 1e-12,
        "{what}: {got} vs {want}"
    );
}

/// The six inputs of table 10, in the oracle's order.
fn ols_inputs(r: &Row) -> Vec<f64> {
    vec![
        r.skewness,
        r.kurtosis,
        r.t_surface_avg_c,
        r.friction_energy_j,
        r.contact_patch_mm2,
        r.loss_factor,
    ]
}

#[test]
fn ols_matches_statsmodels() {
    let g = &golden()["ols"];
    let rear: Vec<Row> = table().into_iter().filter(|r| r.axle == "rear").collect();
    let rows: Vec<Vec<f64>> = rear.iter().map(ols_inputs).collect();
    let y: Vec<f64> = rear.iter().map(|r| r.wear_mean_pct).collect();
    let names = strings(&g["inputs"]);
    let f = OlsSettings.fit(Dataset::new(&rows, &y, &names)).unwrap();
    assert_eq!(f.train.n as u64, g["n"].as_u64().unwrap());
    for (name, got, want) in [
        ("coef", &f.coef, floats(&g["coef"])),
        ("std_err", &f.std_err, floats(&g["std_err"])),
        ("t", &f.t_values, floats(&g["t_values"])),
    ] {
        for (j, (a, b)) in got.iter().zip(&want).enumerate() {
            close(&format!("{name}[{j}]"), *a, *b, 1e-8);
        }
    }
    for (j, (a, b)) in f.p_values.iter().zip(floats(&g["p_values"])).enumerate() {
        assert!((a - b).abs() < 1e-9, "p[{j}]: {a} vs {b}");
    }
    close("R²", f.train.r2, g["r2"].as_f64().unwrap(), 1e-10);
    close(
        "adjusted R²",
        f.train.r2_adj.unwrap(),
        g["r2_adj"].as_f64().unwrap(),
        1e-10,
    );
    close("σ²", f.sigma2, g["sigma2"].as_f64().unwrap(), 1e-8);

    // The front rows as new tires for the rear fit: statsmodels'
    // `get_prediction(...).summary_frame(alpha)` obs_ci bounds.
    let front: Vec<Vec<f64>> = table()
        .iter()
        .filter(|r| r.axle == "front")
        .map(ols_inputs)
        .collect();
    for level in [0.95, 0.8] {
        let want = &g["front_rows_intervals"][level.to_string()];
        let (mean, lower, upper) = (
            floats(&want["mean"]),
            floats(&want["lower"]),
            floats(&want["upper"]),
        );
        assert_eq!(mean.len(), front.len());
        for (i, x) in front.iter().enumerate() {
            let near = |what: String, got: f64, want: f64| {
                assert!((got - want).abs() <= 1e-6, "{what}: {got} vs {want}")
            };
            near(format!("mean {i}"), f.predict_one(x), mean[i]);
            let (lo, hi) = f
                .prediction_interval(x, IntervalLevel::new(level).unwrap())
                .unwrap();
            near(format!("{level} lower {i}"), lo, lower[i]);
            near(format!("{level} upper {i}"), hi, upper[i]);
        }
    }
}

#[test]
fn pca_matches_scikit_learn() {
    let g = &golden()["pca"];
    let rows: Vec<Vec<f64>> = table()
        .iter()
        .map(|r| {
            vec![
                r.fz_avg_n,
                r.pressure_avg_pa,
                r.sliding_distance_m,
                r.t_inner_avg_c,
                r.t_surface_avg_c,
                r.friction_energy_j,
                r.hurst,
                r.skewness,
            ]
        })
        .collect();
    let names = strings(&g["inputs"]);
    let p = PcaSettings { threshold: 0.99 }
        .fit(Dataset::new(&rows, &[], &names))
        .unwrap();
    for (i, (a, b)) in p
        .proportions
        .iter()
        .zip(floats(&g["proportions"]))
        .enumerate()
    {
        close(&format!("proportion[{i}]"), *a, b, 1e-9);
    }
    for (i, comp) in g["loadings"].as_array().unwrap().iter().enumerate() {
        let want = floats(comp);
        // Eigenvectors are defined up to sign.
        let sign = if p.loadings[i]
            .iter()
            .zip(&want)
            .map(|(a, b)| a * b)
            .sum::<f64>()
            < 0.0
        {
            -1.0
        } else {
            1.0
        };
        for (j, (a, b)) in p.loadings[i].iter().zip(&want).enumerate() {
            assert!(
                (sign * a - b).abs() < 1e-8,
                "loading[{i}][{j}]: {} vs {b}",
                sign * a
            );
        }
    }
    let cum: f64 = p.proportions[..p.kept].iter().sum();
    assert!(cum >= 0.99 && (p.kept == 1 || p.proportions[..p.kept - 1].iter().sum::<f64>() < 0.99));
}

/// y = a·exp(−b·t) + c fitted to the oracle's data.
struct ExpDecay {
    t: Vec<f64>,
    y: Vec<f64>,
}

impl LeastSquares for ExpDecay {
    fn n_residuals(&self) -> usize {
        self.t.len()
    }
    fn n_params(&self) -> usize {
        3
    }
    fn residuals(&self, p: &[f64], r: &mut [f64]) {
        for ((r, t), y) in r.iter_mut().zip(&self.t).zip(&self.y) {
            *r = p[0] * (-p[1] * t).exp() + p[2] - y;
        }
    }
    fn jacobian(&self, p: &[f64], j: &mut faer::Mat<f64>) {
        for i in 0..self.t.len() {
            let e = (-p[1] * self.t[i]).exp();
            j[(i, 0)] = e;
            j[(i, 1)] = -p[0] * self.t[i] * e;
            j[(i, 2)] = 1.0;
        }
    }
}

/// The network's split-conformal half-width against numpy's quantile
/// (tests/oracles/conformal_oracle.py): the same score exactly (one of the
/// inputs, chosen by rank), or none where the scores are too few.
#[test]
fn conformal_half_width_matches_numpy() {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden/conformal.json");
    let g: Value = serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
    let cases = g["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 48);
    let mut nones = 0;
    for c in cases {
        let mut scores = floats(&c["scores"]);
        scores.sort_by(f64::total_cmp);
        let level = IntervalLevel::new(c["level"].as_f64().unwrap()).unwrap();
        let got = conformal_half_width(&scores, level);
        let want = c["half_width"].as_f64();
        assert_eq!(got, want, "{} scores at {level:?}", scores.len());
        nones += usize::from(want.is_none());
    }
    // One score from 80 % up, 12 and 18 at 95 and 99 %, 19 to 45 at 99 %.
    assert_eq!(nones, 11);
}

#[test]
fn levenberg_marquardt_matches_scipy() {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden/lm.json");
    let g: Value = serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
    let problem = ExpDecay {
        t: floats(&g["t"]),
        y: floats(&g["y"]),
    };
    let res = levenberg_marquardt(&problem, &floats(&g["x0"]), &LmSettings::default()).unwrap();
    // Same minimum as MINPACK's LM (scipy): parameters to 1e-6 relative, cost (½·SSE) to 1e-9.
    for (a, b) in res.params.iter().zip(floats(&g["solution"])) {
        close("LM parameter", *a, b, 1e-6);
    }
    close("LM cost", 0.5 * res.sse, g["cost"].as_f64().unwrap(), 1e-9);
}
