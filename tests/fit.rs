//! `tirewear fit` end to end on the demo season: the three methods fit on
//! whole training events and are tested on others; the physical method's
//! rear-axle testing R² beats PCA's (the paper's ranking, table 11 vs 9);
//! saved models reload and predict the same numbers, and a damaged one is
//! refused by its field or predicts alike; `predict` refuses a table with a
//! missing column or a different unit, naming it.

mod common;

use std::collections::HashMap;
use std::sync::Arc;
use tirewear::kpi::KpiRow;
use tirewear::kpi::table::{ROAD_KPIS, VISCOELASTIC_KPIS, read_units, write_batch};
use tirewear::model::fit::{FitSettings, Method, fit_method, split};
use tirewear::model::interval::IntervalLevel;
use tirewear::model::network::NetworkSettings;
use tirewear::model::saved::{ModelBody, SavedModel};

fn testing_r2(m: &SavedModel, label: &str) -> f64 {
    m.indicators
        .iter()
        .find(|i| i.label == label)
        .unwrap_or_else(|| panic!("{} has no '{label}' line", m.method()))
        .metrics
        .r2
}

#[test]
fn demo_fit_ranks_like_the_paper_and_models_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let rows = common::demo_kpis(dir.path());
    let s = split(&rows, None).unwrap();
    // Whole events: no event on both sides.
    assert!(s.train_events.iter().all(|e| !s.test_events.contains(e)));
    assert!(!s.test.is_empty() && s.train.len() > 2 * s.test.len() - 10);
    let settings = FitSettings {
        // Two widths keep the debug-build test quick; the CLI loops over 1..=inputs+4.
        network: NetworkSettings {
            hidden2_candidates: vec![4, 8],
            ..Default::default()
        },
        ..Default::default()
    };
    let models: HashMap<&str, SavedModel> = Method::ALL
        .iter()
        .map(|&m| {
            let (model, notes) = fit_method(m, &s, &settings).unwrap();
            // Demo rows are complete; the only rows left out are the tires
            // worn through (censored wear).
            let worn = s
                .train
                .iter()
                .filter(|r| r.worn_through_readings > 0.0)
                .count();
            assert!(
                notes.len() == worn && notes.iter().all(|n| n.contains("worn through")),
                "{worn} worn-through training rows: {notes:?}"
            );
            (model.method(), model)
        })
        .collect();
    let (phys_rear, pca) = (
        testing_r2(&models["physical"], "Rear—Testing"),
        testing_r2(&models["pca"], "Testing"),
    );
    assert!(
        phys_rear > pca,
        "physical rear testing R² {phys_rear:.4} vs PCA testing R² {pca:.4}"
    );
    // The physical method's preliminary analysis (paper figures 13 and 14).
    let ModelBody::Physical { front, rear } = &models["physical"].model else {
        panic!("physical body")
    };
    assert!(rear.slope_vs_t_surface > 0.0 && front.slope_vs_t_surface > 0.0);
    assert!(rear.lines.iter().all(|l| (0.0..=1.0).contains(&l.r2)));
    assert_eq!(rear.regression.inputs.len(), 6);

    // Save, reload, predict: identical numbers.
    let out = dir.path().join("models");
    let paths =
        tirewear::model::saved::save_all(&models.values().cloned().collect::<Vec<_>>(), &out)
            .unwrap();
    assert_eq!(paths.len(), 3);
    // Written as one set: its journal and temporary files are gone.
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["ffnn.json", "pca.json", "physical.json"]);
    for m in models.values() {
        let back = SavedModel::load(&out.join(format!("{}.json", m.method()))).unwrap();
        assert_eq!(&back, m);
        for r in rows.iter().take(20) {
            assert_eq!(back.predict_row(r).unwrap(), m.predict_row(r).unwrap());
        }
    }
    damaged_models_are_refused_by_field_or_predict_alike(&models, &out, &rows);
    undefined_numbers_read_back(&rows, dir.path());
    event_errors_match_the_hat_matrix(&models["physical"], &s);
    // Nine training events: eight folds, one of two events.
    let mut events: Vec<String> = rows.iter().map(|r| r.event.clone()).collect();
    events.sort();
    events.dedup();
    let nine = split(&rows, Some(&events[..1])).unwrap();
    assert_eq!(nine.train_events.len(), 9);
    let (model, _) = fit_method(Method::Physical, &nine, &settings).unwrap();
    event_errors_match_the_hat_matrix(&model, &nine);
    changed_bytes_of_a_model_file_are_refused(&models, &out);

    // The indicators recomputed from the reloaded model's predictions on the testing events.
    let phys = SavedModel::load(&out.join("physical.json")).unwrap();
    let rear_test: Vec<&KpiRow> = s
        .test
        .iter()
        .copied()
        .filter(|r| r.axle == tirewear::Axle::Rear)
        .collect();
    let y: Vec<f64> = rear_test.iter().map(|r| r.wear_mean_pct).collect();
    let p: Vec<f64> = rear_test
        .iter()
        .map(|r| phys.predict_row(r).unwrap())
        .collect();
    let m = tirewear::model::metrics::metrics(&y, &p, 6).unwrap();
    assert!((m.r2 - phys_rear).abs() < 1e-12);
    // The share inside the 95 % prediction interval, counted from the
    // reloaded model's intervals.
    let level = IntervalLevel::P95;
    let inside = rear_test
        .iter()
        .filter(|r| {
            let (_, interval) = phys.predict_row_within(r, Some(level)).unwrap();
            let (low, high) = interval.unwrap();
            low <= r.wear_mean_pct && r.wear_mean_pct <= high
        })
        .count();
    let line = |m: &SavedModel, label: &str| {
        m.indicators
            .iter()
            .find(|i| i.label == label)
            .unwrap()
            .inside_95_interval
    };
    assert_eq!(
        line(&phys, "Rear—Testing"),
        Some(inside as f64 / rear_test.len() as f64)
    );
    // The network's: ŷ ± the ⌈(n + 1)·0.95⌉-th smallest of its n
    // validation errors, one half-width for every tire.
    let ffnn = SavedModel::load(&out.join("ffnn.json")).unwrap();
    let ModelBody::Ffnn { network, .. } = &ffnn.model else {
        panic!("network body")
    };
    let scores = network.validation_abs_residuals.as_ref().unwrap();
    let n = scores.len();
    assert!(n == network.validation_rows && n >= 19, "{n}");
    assert!(scores.windows(2).all(|w| w[0] <= w[1]));
    let half = scores[((n + 1) as f64 * 0.95).ceil() as usize - 1];
    let measured: Vec<&KpiRow> = s
        .test
        .iter()
        .copied()
        .filter(|r| r.worn_through_readings <= 0.0 && r.wear_mean_pct.is_finite())
        .collect();
    let inside = measured
        .iter()
        .filter(|r| {
            let (p, interval) = ffnn.predict_row_within(r, Some(level)).unwrap();
            let (low, high) = interval.unwrap();
            assert_eq!((low, high), (p - half, p + half));
            low <= r.wear_mean_pct && r.wear_mean_pct <= high
        })
        .count();
    assert_eq!(
        line(&ffnn, "Testing"),
        Some(inside as f64 / measured.len() as f64)
    );

    // The KPI table carries units; a changed unit or a missing column is refused by name.
    let units = read_units(&dir.path().join("kpis.parquet")).unwrap();
    phys.check_columns(&units).unwrap();
    let mut changed = units.clone();
    for (n, u) in &mut changed {
        if n == "contact_patch_mm2" {
            *u = Some("cm^2".into());
        }
    }
    let e = phys.check_columns(&changed).unwrap_err().to_string();
    assert!(
        e.contains("contact_patch_mm2") && e.contains("cm^2") && e.contains("mm^2"),
        "{e}"
    );
    let missing: Vec<_> = units.into_iter().filter(|(n, _)| n != "skewness").collect();
    let e = phys.check_columns(&missing).unwrap_err().to_string();
    assert!(e.contains("'skewness' is missing"), "{e}");

    // A Parquet file whose schema states another unit is caught from the file itself.
    let batch = {
        let file = std::fs::File::open(dir.path().join("kpis.parquet")).unwrap();
        let mut r = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)
            .unwrap()
            .build()
            .unwrap();
        r.next().unwrap().unwrap()
    };
    let fields: Vec<arrow_schema::Field> = batch
        .schema()
        .fields()
        .iter()
        .map(|f| {
            let f = f.as_ref().clone();
            if f.name() == "t_surface_avg_c" {
                f.with_metadata(HashMap::from([("unit".into(), "K".into())]))
            } else {
                f
            }
        })
        .collect();
    let kelvin = dir.path().join("kelvin.parquet");
    let batch = arrow_array::RecordBatch::try_new(
        Arc::new(arrow_schema::Schema::new(fields)),
        batch.columns().to_vec(),
    )
    .unwrap();
    write_batch(&kelvin, &batch).unwrap();
    let e = phys
        .check_columns(&read_units(&kelvin).unwrap())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("t_surface_avg_c") && e.contains("is in K"),
        "{e}"
    );
    predict_writes_each_rows_prediction_and_refuses_an_empty_table(&phys, dir.path(), &rows);
}

/// `tirewear predict` end to end: one CSV line per KPI row, in the table's
/// order, with the saved model's prediction for it (the CSV writer keeps
/// an f64 exactly) and its 95 % prediction interval around it, whose
/// coverage of the measured wear it prints as counted here from the CSV
/// (worn-through tires left out); a level outside (0, 1) is a bad command
/// line (exit 2); a table without rows (a night on which every run
/// failed) is refused, exit 1, naming it, and no predictions file appears
/// (it once wrote an empty one and exited 0).
fn predict_writes_each_rows_prediction_and_refuses_an_empty_table(
    phys: &SavedModel,
    dir: &std::path::Path,
    rows: &[KpiRow],
) {
    let model = dir.join("models").join("physical.json");
    let predict_at = |kpis: &std::path::Path, out: &std::path::Path, level: &str| {
        std::process::Command::new(env!("CARGO_BIN_EXE_tirewear"))
            .arg("--quiet")
            .arg("predict")
            .arg(&model)
            .arg(kpis)
            .arg("--out")
            .arg(out)
            .args(["--interval", level])
            .output()
            .unwrap()
    };
    let predict = |kpis: &std::path::Path, out: &std::path::Path| predict_at(kpis, out, "0.95");
    let csv = dir.join("predictions.csv");
    let run = predict(&dir.join("kpis.parquet"), &csv);
    assert_eq!(run.status.code(), Some(0), "{run:?}");
    let mut reader = csv::Reader::from_path(&csv).unwrap();
    let header = reader.headers().unwrap().clone();
    let column = |name: &str| header.iter().position(|h| h == name).unwrap();
    let (run_col, wheel_col, predicted_col) =
        (column("run"), column("wheel"), column("predicted_wear_pct"));
    let (low_col, high_col) = (column("predicted_low_pct"), column("predicted_high_pct"));
    let lines: Vec<csv::StringRecord> = reader.records().map(|r| r.unwrap()).collect();
    assert_eq!(lines.len(), rows.len());
    let level = IntervalLevel::P95;
    let mut inside = [0usize; 2];
    for (line, r) in lines.iter().zip(rows) {
        assert_eq!(
            (&line[run_col], &line[wheel_col]),
            (r.run.as_str(), r.wheel.name())
        );
        let value = |c: usize| -> f64 { line[c].parse().unwrap() };
        let predicted = value(predicted_col);
        assert_eq!(predicted, phys.predict_row(r).unwrap(), "{line:?}");
        let (low, high) = (value(low_col), value(high_col));
        assert_eq!(
            (predicted, Some((low, high))),
            phys.predict_row_within(r, Some(level)).unwrap()
        );
        assert!(low < predicted && predicted < high, "{line:?}");
        if r.worn_through_readings == 0.0 && r.wear_mean_pct.is_finite() {
            inside[0] += usize::from(low <= r.wear_mean_pct && r.wear_mean_pct <= high);
            inside[1] += 1;
        }
    }
    let stdout = String::from_utf8_lossy(&run.stdout);
    let share = format!(
        "95 % prediction intervals: they hold {:.1} % of {} measured wears (",
        100.0 * inside[0] as f64 / inside[1] as f64,
        inside[1]
    );
    assert!(stdout.contains(&share), "{share} not in {stdout}");
    // The new-event intervals: each row's prediction ± the ⌈(n + 1)·0.95⌉-th
    // of its axle's leave-one-event-out errors, their share printed too.
    let (event_low_col, event_high_col) =
        (column("new_event_low_pct"), column("new_event_high_pct"));
    let errors = phys.event_errors.as_ref().unwrap();
    let mut inside = [0usize; 2];
    for (line, r) in lines.iter().zip(rows) {
        let value = |c: usize| -> f64 { line[c].parse().unwrap() };
        let scores = match r.axle {
            tirewear::Axle::Front => &errors.front,
            tirewear::Axle::Rear => &errors.rear,
        };
        let half = scores[((scores.len() + 1) as f64 * 0.95).ceil() as usize - 1];
        let p = value(predicted_col);
        let (low, high) = (value(event_low_col), value(event_high_col));
        assert_eq!((low, high), (p - half, p + half), "{line:?}");
        if r.worn_through_readings == 0.0 && r.wear_mean_pct.is_finite() {
            inside[0] += usize::from(low <= r.wear_mean_pct && r.wear_mean_pct <= high);
            inside[1] += 1;
        }
    }
    let share = format!(
        "95 % new-event intervals: they hold {:.1} % of {} measured wears (",
        100.0 * inside[0] as f64 / inside[1] as f64,
        inside[1]
    );
    assert!(stdout.contains(&share), "{share} not in {stdout}");
    // A model saved before the intervals (no `xtx_inverse`; without its
    // checksum, as such files were): predictions alike, no bounds, and why.
    let mut old: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    let body = old.as_object_mut().unwrap();
    body.remove("data_crc32");
    for axle in ["front", "rear"] {
        body["model"][axle]["regression"]
            .as_object_mut()
            .unwrap()
            .remove("xtx_inverse");
    }
    let old_model = dir.join("old-physical.json");
    std::fs::write(&old_model, serde_json::to_string(&old).unwrap()).unwrap();
    let old_csv = dir.join("old.csv");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_tirewear"))
        .args(["--quiet", "predict"])
        .args([
            &old_model,
            &dir.join("kpis.parquet"),
            &"--out".into(),
            &old_csv,
        ])
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(0), "{run:?}");
    assert!(
        String::from_utf8_lossy(&run.stdout)
            .contains("no 95 % prediction intervals: the model was saved before"),
        "{run:?}"
    );
    let mut reader = csv::Reader::from_path(&old_csv).unwrap();
    for (line, r) in reader.records().map(Result::unwrap).zip(rows) {
        assert_eq!(
            line[predicted_col].parse::<f64>().unwrap(),
            phys.predict_row(r).unwrap()
        );
        assert_eq!((&line[low_col], &line[high_col]), ("NaN", "NaN"));
    }
    // The network's conformal intervals: written at 95 %; at 99.9 % its
    // validation rows are too few (⌈(n + 1)·0.999⌉ ≤ n needs n ≥ 999), and
    // it says so.
    let network = |level: &str| {
        std::process::Command::new(env!("CARGO_BIN_EXE_tirewear"))
            .args(["--quiet", "predict"])
            .arg(dir.join("models").join("ffnn.json"))
            .arg(dir.join("kpis.parquet"))
            .arg("--out")
            .arg(dir.join("ffnn.csv"))
            .args(["--interval", level])
            .output()
            .unwrap()
    };
    let run = network("0.95");
    assert_eq!(run.status.code(), Some(0), "{run:?}");
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        stdout.contains("95 % prediction intervals: they hold"),
        "{stdout}"
    );
    let run = network("0.999");
    assert_eq!(run.status.code(), Some(0), "{run:?}");
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        stdout.contains("no 99.9 % prediction intervals: the network kept")
            && stdout.contains("at this level needs 999"),
        "{stdout}"
    );

    let run = predict_at(&dir.join("kpis.parquet"), &dir.join("p.csv"), "1");
    assert_eq!(run.status.code(), Some(2), "{run:?}");
    assert!(
        String::from_utf8_lossy(&run.stderr).contains("between 0 and 1"),
        "{run:?}"
    );

    // `fit --method` takes a list: those two models, no network.
    let two = dir.join("two-models");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_tirewear"))
        .args(["--quiet", "fit"])
        .arg(dir.join("kpis.parquet"))
        .args(["--method", "physical,pca", "--out"])
        .arg(&two)
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(0), "{run:?}");
    assert!(two.join("physical.json").is_file() && two.join("pca.json").is_file());
    assert!(!two.join("ffnn.json").exists());

    // The same table without its rows: same schema and units.
    let batch = {
        let file = std::fs::File::open(dir.join("kpis.parquet")).unwrap();
        let mut r = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)
            .unwrap()
            .build()
            .unwrap();
        r.next().unwrap().unwrap()
    };
    let empty = dir.join("empty.parquet");
    write_batch(&empty, &batch.slice(0, 0)).unwrap();
    let none = dir.join("none.csv");
    let run = predict(&empty, &none);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "{}: rows: the KPI table has no rows",
            empty.display()
        )),
        "{stderr}"
    );
    assert!(!none.exists());
}

/// A physical model whose tracks' lines are all unreliable but one's (the
/// other tracks cut to two tires an axle, and a line needs three): the
/// correlation of the slopes of the reliable tracks with temperature is
/// undefined, NaN, which serde_json writes as `null`. Such a file (on a
/// real-data-noise season, a training set without one event) was written
/// by `fit` and then refused by `predict` as "invalid type: null, expected
/// f64". It now reads back and predicts as the fitted model. A NaN where a
/// prediction needs a number is refused when saving, not left for
/// `predict` to find. And a fit on one training event has no new-event
/// intervals, and says so.
fn undefined_numbers_read_back(rows: &[KpiRow], dir: &std::path::Path) {
    let first = rows[0].track.clone();
    let mut count: HashMap<(String, tirewear::Axle), usize> = HashMap::new();
    let cut: Vec<KpiRow> = rows
        .iter()
        .filter(|r| r.worn_through_readings <= 0.0)
        .filter(|r| {
            let n = count.entry((r.track.clone(), r.axle)).or_default();
            *n += 1;
            r.track == first || *n <= 2
        })
        .cloned()
        .collect();
    let test = cut
        .iter()
        .rev()
        .find(|r| r.track != first)
        .unwrap()
        .event
        .clone();
    let s = split(&cut, Some(std::slice::from_ref(&test))).unwrap();
    let (model, _) = fit_method(Method::Physical, &s, &FitSettings::default()).unwrap();
    let ModelBody::Physical { front, rear } = &model.model else {
        panic!("physical body")
    };
    for a in [front, rear] {
        assert_eq!(
            a.lines.iter().filter(|l| l.n >= 3).count(),
            1,
            "{:?}",
            a.lines
        );
        assert!(a.slope_vs_t_surface.is_nan());
    }
    let out = dir.join("one-reliable-track");
    tirewear::model::saved::save_all(std::slice::from_ref(&model), &out).unwrap();
    let text = std::fs::read_to_string(out.join("physical.json")).unwrap();
    assert!(text.contains("\"slope_vs_t_surface\": null"), "{text}");
    let back = SavedModel::load(&out.join("physical.json")).unwrap();
    let ModelBody::Physical { front, .. } = &back.model else {
        panic!("physical body")
    };
    assert!(front.slope_vs_t_surface.is_nan());
    for r in rows.iter().take(40) {
        assert_eq!(
            back.predict_row_within(r, Some(IntervalLevel::P95)).ok(),
            model.predict_row_within(r, Some(IntervalLevel::P95)).ok()
        );
    }
    // A coefficient that is not a number: refused when saving, by the field.
    let mut broken = model.clone();
    if let ModelBody::Physical { rear, .. } = &mut broken.model {
        rear.regression.coef[2] = f64::NAN;
    }
    let e = tirewear::model::saved::save_all(&[broken], &dir.join("broken"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("the physical model would not read back") && e.contains("null, expected f64"),
        "{e}"
    );
    assert!(!dir.join("broken").join("physical.json").exists());

    // One training event: nothing to leave out.
    let mut events: Vec<String> = rows.iter().map(|r| r.event.clone()).collect();
    events.sort();
    events.dedup();
    let s = split(rows, Some(&events[1..])).unwrap();
    let (model, notes) = fit_method(Method::Pca, &s, &FitSettings::default()).unwrap();
    assert!(model.event_errors.is_none());
    assert!(
        notes
            .iter()
            .any(|n| n.starts_with("no new-event intervals: one training event")),
        "{notes:?}"
    );
}

/// The physical model's leave-one-event-out errors by a second route:
/// for least squares, leaving out a group g turns its residuals e_g into
/// (I − H_gg)⁻¹ e_g, with H_gg = X_g (XᵀX)⁻¹ X_gᵀ the hat matrix's block of
/// the full fit (no refit; the physical method's regression inputs are
/// fixed, so its refits are this regression without the event or fold). Each
/// axle's errors equal the refits' to 1e-7 % of the tread (the refits
/// solve by QR, this route through the saved (XᵀX)⁻¹), and the shares of
/// the model's indicator lines are the tires inside p ± the conformal
/// width of those errors.
fn event_errors_match_the_hat_matrix(model: &SavedModel, s: &tirewear::model::fit::Split) {
    use faer::linalg::solvers::Solve;
    let ModelBody::Physical { front, rear } = &model.model else {
        panic!("physical body")
    };
    let errors = model.event_errors.as_ref().expect("event errors");
    assert_eq!(errors.events, s.train_events);
    // Each event its own fold up to MAX_EVENT_FOLDS; beyond, the sorted
    // events dealt round-robin into that many.
    let k = s
        .train_events
        .len()
        .min(tirewear::model::fit::MAX_EVENT_FOLDS);
    assert_eq!(errors.folds, k);
    let folds: Vec<Vec<&String>> = (0..k)
        .map(|f| s.train_events.iter().skip(f).step_by(k).collect())
        .collect();
    for (a, want) in [(front, &errors.front), (rear, &errors.rear)] {
        let ols = &a.regression;
        let inv = ols.xtx_inverse.as_ref().unwrap();
        let k1 = ols.coef.len();
        let x = |r: &KpiRow| -> Vec<f64> {
            std::iter::once(1.0)
                .chain(ols.inputs.iter().map(|c| r.number(c).unwrap()))
                .collect()
        };
        let mut got = Vec::new();
        for fold in &folds {
            let g: Vec<Vec<f64>> = s
                .train
                .iter()
                .filter(|r| {
                    r.axle == a.axle && fold.contains(&&r.event) && r.worn_through_readings <= 0.0
                })
                .map(|r| {
                    let mut v = x(r);
                    v.push(r.wear_mean_pct);
                    v
                })
                .collect();
            let n = g.len();
            let hat = |i: usize, j: usize| -> f64 {
                (0..k1)
                    .map(|p| g[i][p] * (0..k1).map(|q| inv[p * k1 + q] * g[j][q]).sum::<f64>())
                    .sum()
            };
            let i_minus_h =
                faer::Mat::from_fn(n, n, |i, j| f64::from(u8::from(i == j)) - hat(i, j));
            // y − [1, x]·β.
            let residual = faer::Mat::from_fn(n, 1, |i, _| {
                g[i][k1]
                    - g[i][..k1]
                        .iter()
                        .zip(&ols.coef)
                        .map(|(x, b)| x * b)
                        .sum::<f64>()
            });
            let left_out = i_minus_h.partial_piv_lu().solve(&residual);
            got.extend((0..n).map(|i| left_out[(i, 0)].abs()));
        }
        got.sort_by(f64::total_cmp);
        assert_eq!(got.len(), want.len(), "{}", a.axle);
        for (g, w) in got.iter().zip(want.iter()) {
            assert!(
                (g - w).abs() < 1e-7,
                "{}: {g} by the hat matrix, {w} refitted",
                a.axle
            );
        }
        // The testing line's share: p ± the ⌈(n + 1)·0.95⌉-th error.
        let half = want[((want.len() + 1) as f64 * 0.95).ceil() as usize - 1];
        let tires: Vec<&KpiRow> = s
            .test
            .iter()
            .copied()
            .filter(|r| r.axle == a.axle && r.worn_through_readings <= 0.0)
            .collect();
        let inside = tires
            .iter()
            .filter(|r| (model.predict_row(r).unwrap() - r.wear_mean_pct).abs() <= half)
            .count();
        let label = format!(
            "{}—Testing",
            if a.axle == tirewear::Axle::Front {
                "Front"
            } else {
                "Rear"
            }
        );
        let line = model.indicators.iter().find(|i| i.label == label).unwrap();
        assert_eq!(
            line.inside_95_event_interval,
            Some(inside as f64 / tires.len() as f64),
            "{label}"
        );
    }
}

/// JSON pointers of every non-empty array in `v`.
fn array_pointers(v: &serde_json::Value, at: String, out: &mut Vec<String>) {
    match v {
        serde_json::Value::Object(m) => {
            for (k, x) in m {
                array_pointers(x, format!("{at}/{k}"), out);
            }
        }
        serde_json::Value::Array(a) if !a.is_empty() => {
            out.push(at.clone());
            for (i, x) in a.iter().enumerate() {
                array_pointers(x, format!("{at}/{i}"), out);
            }
        }
        _ => {}
    }
}

/// Every byte of the physical and PCA model files changed in turn (one bit
/// flipped): `SavedModel::load` refuses the file naming it, or reads the
/// very model that was saved (a change in the checksum field's name, or in
/// the trailing newline). A digit changed in a coefficient is valid JSON
/// and a valid model: before the file's checksum it was read without a word
/// (docs/models.md, "Checksum"). The same file with the field deleted, as
/// someone editing it on purpose would, reads again and predicts otherwise.
fn changed_bytes_of_a_model_file_are_refused(
    models: &HashMap<&str, SavedModel>,
    dir: &std::path::Path,
) {
    let damaged = dir.join("changed.json");
    for method in ["physical", "pca"] {
        let text = std::fs::read(dir.join(format!("{method}.json"))).unwrap();
        let (mut refused, mut same) = (0, 0);
        for at in 0..text.len() {
            let mut bytes = text.clone();
            bytes[at] ^= 1 << (at % 7);
            std::fs::write(&damaged, &bytes).unwrap();
            match SavedModel::load(&damaged) {
                Err(e) => {
                    assert!(e.to_string().contains("changed.json"), "byte {at}: {e}");
                    refused += 1;
                }
                Ok(back) => {
                    assert_eq!(&back, &models[method], "{method}: byte {at} changed, read");
                    same += 1;
                }
            }
        }
        println!(
            "{method}.json: {refused} of {} changes refused, {same} read the same",
            text.len()
        );
        assert!(
            refused >= text.len() * 99 / 100,
            "{refused} of {}",
            text.len()
        );
    }
    // Line ends turned into CRLF by a checkout (git's autocrlf): the same file.
    let text = std::fs::read_to_string(dir.join("physical.json")).unwrap();
    std::fs::write(&damaged, text.replace('\n', "\r\n")).unwrap();
    assert_eq!(&SavedModel::load(&damaged).unwrap(), &models["physical"]);
    // A file of format version 1 (written before an undefined adjusted R²
    // could be null) reads as the same model; a newer version is refused
    // with both numbers named.
    for version in [1, 3] {
        let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
        v["version"] = version.into();
        v.as_object_mut().unwrap().remove("data_crc32");
        std::fs::write(&damaged, serde_json::to_string_pretty(&v).unwrap()).unwrap();
        match SavedModel::load(&damaged) {
            Ok(mut m) if version == 1 => {
                m.version = models["physical"].version;
                assert_eq!(&m, &models["physical"]);
            }
            Err(e) if version == 3 => assert!(
                e.to_string()
                    .contains("version Some(3), this tirewear reads versions 1 to 2"),
                "{e}"
            ),
            other => panic!("version {version}: {other:?}"),
        }
    }
    // A coefficient's digit changed by hand: refused by the checksum, then
    // read once the field is deleted.
    let at = text.find("\"coef\"").unwrap();
    // The second decimal of the first coefficient, one up.
    let digit = at + text[at..].find('.').unwrap() + 2;
    let up = (text.as_bytes()[digit] - b'0' + 1) % 10;
    let mut edited = text.clone();
    edited.replace_range(digit..digit + 1, &up.to_string());
    std::fs::write(&damaged, &edited).unwrap();
    let e = SavedModel::load(&damaged).unwrap_err().to_string();
    assert!(
        e.contains("data_crc32") && e.contains("delete the field"),
        "{e}"
    );
    let mut v: serde_json::Value = serde_json::from_str(&edited).unwrap();
    v.as_object_mut().unwrap().remove("data_crc32");
    std::fs::write(&damaged, serde_json::to_string(&v).unwrap()).unwrap();
    assert_ne!(&SavedModel::load(&damaged).unwrap(), &models["physical"]);
}

/// Each saved model with one array one element short, every array in
/// turn (a damaged or hand-edited file): `SavedModel::load` refuses it,
/// naming the file and the field, or the model it reads predicts every
/// row exactly as the undamaged one (the arrays a prediction does not read:
/// standard errors, the training curve, loadings beyond the components
/// kept...). Before the shapes were checked, a short weight or mean array
/// panicked and a short coefficient array predicted wrong numbers silently.
fn damaged_models_are_refused_by_field_or_predict_alike(
    models: &HashMap<&str, SavedModel>,
    dir: &std::path::Path,
    rows: &[KpiRow],
) {
    let damaged = dir.join("damaged.json");
    let mut refused = 0;
    for m in models.values() {
        let text = std::fs::read_to_string(dir.join(format!("{}.json", m.method()))).unwrap();
        let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
        // Edited on purpose: the checksum deleted, so the shapes stand guard.
        assert!(json.as_object_mut().unwrap().remove("data_crc32").is_some());
        let mut pointers = Vec::new();
        array_pointers(&json, String::new(), &mut pointers);
        for p in pointers {
            let mut v = json.clone();
            let a = v.pointer_mut(&p).unwrap().as_array_mut().unwrap();
            a.pop();
            std::fs::write(&damaged, serde_json::to_string(&v).unwrap()).unwrap();
            // The field as the refusal names it: /model/pca/means → model.pca.means.
            let field = p.trim_start_matches('/').replace('/', ".");
            match SavedModel::load(&damaged) {
                Err(e) => {
                    let e = e.to_string();
                    assert!(e.contains("damaged.json"), "{p}: {e}");
                    // By its field (model.pca.loadings[3] for /model/pca/loadings/3);
                    // serde's own refusals (a pair one short) by line and column;
                    // a feature fewer by what no longer fits it.
                    let named = e.replace('[', ".").replace(']', "").contains(&field)
                        || e.contains(" line ")
                        || (p == "/features" && e.contains("features"));
                    assert!(named, "{p}: {e}");
                    refused += 1;
                }
                Ok(back) => {
                    for r in rows {
                        assert_eq!(
                            back.predict_row_within(r, Some(IntervalLevel::P95)).ok(),
                            m.predict_row_within(r, Some(IntervalLevel::P95)).ok(),
                            "{} with {p} one short predicts otherwise",
                            m.method()
                        );
                    }
                }
            }
        }
    }
    assert!(refused >= 10, "{refused}");
    // A layer size that would overflow the weights' count.
    let text = std::fs::read_to_string(dir.join("ffnn.json")).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v.as_object_mut().unwrap().remove("data_crc32");
    *v.pointer_mut("/model/network/net/hidden1").unwrap() = u64::MAX.into();
    std::fs::write(&damaged, serde_json::to_string(&v).unwrap()).unwrap();
    let e = SavedModel::load(&damaged).unwrap_err().to_string();
    assert!(
        e.contains("model.network.net.hidden1 is 18446744073709551615"),
        "{e}"
    );
    // The conformal scores edited out of order or below zero: the interval
    // takes the k-th by position, so both are refused by the field.
    let scores = "/model/network/validation_abs_residuals";
    for (edit, why) in [
        (
            (|a: &mut Vec<serde_json::Value>| a.reverse()) as fn(&mut Vec<serde_json::Value>),
            "below the",
        ),
        (|a| a[0] = (-1.0).into(), "[0] is -1, an absolute error"),
    ] {
        let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
        v.as_object_mut().unwrap().remove("data_crc32");
        edit(v.pointer_mut(scores).unwrap().as_array_mut().unwrap());
        std::fs::write(&damaged, serde_json::to_string(&v).unwrap()).unwrap();
        let e = SavedModel::load(&damaged).unwrap_err().to_string();
        assert!(
            e.contains("model.network.validation_abs_residuals") && e.contains(why),
            "{e}"
        );
    }
}

/// Output paths a user can plausibly get wrong are refused before anything
/// is read, with exit code 1, the file named, and every file left as it
/// was: `predict --out` naming its own model or KPI table (once replaced
/// by the predictions), `report --out` naming a data file (once replaced by
/// the page), a file where `fit`, `gap` or `gap validate` want a folder,
/// or a path inside a file (`gap` once ran the whole diagnosis first), and
/// `report` given the KPI table instead of its folder.
#[test]
fn outputs_that_would_replace_an_input_or_a_folder_are_refused_first() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let model = d.join("physical.json");
    let kpis = d.join("kpis.parquet");
    let notes = d.join("notes.txt");
    for (p, text) in [
        (&model, "{\"model\": 1}"),
        (&kpis, "PAR1 not really"),
        (&notes, "mine"),
    ] {
        std::fs::write(p, text).unwrap();
    }
    let before: Vec<Vec<u8>> = [&model, &kpis, &notes]
        .iter()
        .map(|p| std::fs::read(p).unwrap())
        .collect();
    let (m, k, n, dd) = (
        model.to_str().unwrap(),
        kpis.to_str().unwrap(),
        notes.to_str().unwrap(),
        d.to_str().unwrap(),
    );
    let below = format!("{n}/gap");
    for (args, said) in [
        (
            vec!["predict", m, k, "--out", m],
            "input of this command (the model)",
        ),
        (
            vec!["predict", m, k, "--out", k],
            "input of this command (the KPI database)",
        ),
        (vec!["predict", m, k, "--out", dd], "is a folder"),
        (
            vec!["report", dd, "--out", k],
            "is not an HTML page (it is a Parquet file)",
        ),
        (
            vec!["report", dd, "--out", n],
            "is not an HTML page (it is text, beginning `mine`)",
        ),
        (vec!["report", k], "is a file: the report takes the folder"),
        (
            vec!["fit", k, "--out", n],
            "is a file, not a folder: fit writes",
        ),
        (
            vec!["gap", k, "--out", n],
            "is a file, not a folder: gap writes",
        ),
        (
            vec!["gap", "validate", "--out", n],
            "is a file, not a folder: gap validate writes",
        ),
        (
            vec!["gap", k, "--out", &below],
            "which is a file, not a folder: gap cannot make its folder there",
        ),
        (
            vec!["predict", m, k, "--out", &below],
            "which is a file, not a folder: the predictions cannot be written there",
        ),
    ] {
        let run = std::process::Command::new(env!("CARGO_BIN_EXE_tirewear"))
            .arg("--quiet")
            .args(&args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains(said), "{args:?}: {err}");
    }
    let after: Vec<Vec<u8>> = [&model, &kpis, &notes]
        .iter()
        .map(|p| std::fs::read(p).unwrap())
        .collect();
    assert_eq!(after, before);
    assert_eq!(
        std::fs::read_dir(d).unwrap().count(),
        3,
        "nothing else written"
    );
}

/// A season without road profiles (a team without texture scans): extract
/// leaves the road KPIs NaN, and the viscoelastic ones that need the
/// road's macro wavelength. `fit` once left out every row ("no usable
/// training rows"); now the network and PCA fit on the other columns,
/// naming those left out, and the physical method, whose inputs (paper
/// table 10) include skewness, kurtosis and tan δ, says so. Without wear
/// readings, the error counts the rows without wear; the gap diagnosis,
/// whose law has a road factor, says which columns its rows lack.
#[test]
fn a_season_without_road_profiles_fits_on_the_other_columns() {
    let dir = tempfile::tempdir().unwrap();
    let mut rows = common::demo_kpis(dir.path());
    let complete = rows.clone();
    // What extract writes for a track without profiles.
    let absent: Vec<&str> = ROAD_KPIS.into_iter().chain(VISCOELASTIC_KPIS).collect();
    for r in &mut rows {
        for &c in &absent {
            assert!(r.set_number(c, f64::NAN), "{c}");
        }
    }
    let s = split(&rows, None).unwrap();
    let settings = FitSettings {
        network: NetworkSettings {
            hidden2_candidates: vec![4],
            ..Default::default()
        },
        ..Default::default()
    };
    let mut fitted = Vec::new();
    for m in [Method::Ffnn, Method::Pca] {
        let (model, notes) = fit_method(m, &s, &settings).unwrap();
        let used: Vec<&str> = model.features.iter().map(|f| f.name.as_str()).collect();
        assert!(
            !used.is_empty() && used.iter().all(|c| !absent.contains(c)),
            "{used:?}"
        );
        let hurst = absent.iter().filter(|c| **c != "hurst_hdc");
        let first = &notes[0];
        assert!(
            hurst.clone().all(|c| first.contains(c))
                && first.contains("no training row has a value")
                && first.contains("road profiles"),
            "{first}"
        );
        // Every training row with a wear is used: the others are the worn-through ones.
        let worn = s
            .train
            .iter()
            .filter(|r| r.worn_through_readings > 0.0)
            .count();
        let line = model
            .indicators
            .iter()
            .find(|i| i.label == "Training")
            .unwrap();
        assert_eq!(line.metrics.n, s.train.len() - worn);
        assert!(testing_r2(&model, "Testing") > 0.5, "{m:?}");
        fitted.push(model);
    }
    let e = fit_method(Method::Physical, &s, &settings)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("the physical method needs skewness, kurtosis, loss_factor")
            && e.contains("road profiles"),
        "{e}"
    );

    let gap = tirewear::gap::report::diagnose(
        &rows,
        &std::collections::BTreeMap::new(),
        &tirewear::gap::report::Baseline::Physics,
        &tirewear::gap::report::GapSettings::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        gap.contains("have no baseline prediction; none of them has")
            && gap.contains("skewness")
            && gap.contains("road profiles")
            && gap.contains("`--baseline models/ffnn.json`")
            && gap.contains(
                "it needs at least 20 training tires with a measured wear and a baseline \
                 prediction, and has 0"
            ),
        "{gap}"
    );
    // As the error says: a model fitted without the road columns is a
    // baseline the diagnosis runs against.
    let pca = fitted.pop().unwrap();
    let d = tirewear::gap::report::diagnose(
        &rows,
        &std::collections::BTreeMap::new(),
        &tirewear::gap::report::Baseline::Model(Box::new(pca)),
        &tirewear::gap::report::GapSettings::default(),
    );
    assert!(d.is_ok(), "{:?}", d.err());

    // One track without profiles among others: the law has no prediction
    // for its tires (no skewness), which are left out by name, not
    // silently, and the rest is diagnosed.
    let track = split(&complete, None).unwrap().train[0].track.clone();
    let mut mixed = complete.clone();
    for r in mixed.iter_mut().filter(|r| r.track == track) {
        r.skewness = f64::NAN;
    }
    let d = tirewear::gap::report::diagnose(
        &mixed,
        &std::collections::BTreeMap::new(),
        &tirewear::gap::report::Baseline::Physics,
        &tirewear::gap::report::GapSettings::default(),
    )
    .unwrap();
    let name = |r: &tirewear::kpi::KpiRow| format!("{}/{}", r.run, r.wheel);
    let on_track: Vec<String> = mixed
        .iter()
        .filter(|r| r.track == track)
        .map(name)
        .collect();
    let measured = mixed
        .iter()
        .filter(|r| r.track == track && r.worn_through_readings == 0.0)
        .map(name);
    for t in measured {
        assert!(d.unpredicted.contains(&t), "{t} not in {:?}", d.unpredicted);
    }
    assert!(
        d.unpredicted.iter().all(|t| on_track.contains(t)),
        "{:?}",
        d.unpredicted
    );
    assert!(d.unpredicted_lacking.iter().any(|c| c == "skewness"));
    let page = tirewear::gap::render::render_markdown(&d, 10);
    assert!(
        page.contains(&format!(
            "{} tires left out: the baseline has no prediction for them (none of them has",
            d.unpredicted.len()
        )) && page.contains("road profiles"),
        "{page}"
    );

    for r in &mut rows {
        r.wear_mean_pct = f64::NAN;
    }
    let s = split(&rows, None).unwrap();
    let e = fit_method(Method::Pca, &s, &settings)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(&format!(
            "of the {} training rows, each lacks a value a model needs or is censored: wear_mean_pct in {} (no wear readings",
            s.train.len(),
            s.train.len()
        )),
        "{e}"
    );
    // One track without profiles among others, and no wear anywhere: both
    // counted, the road hint said once.
    let track = split(&complete, None).unwrap().train[0].track.clone();
    let mut rows = complete;
    for r in &mut rows {
        r.wear_mean_pct = f64::NAN;
        if r.track == track {
            r.skewness = f64::NAN;
        }
    }
    let s = split(&rows, None).unwrap();
    let on_track = s.train.iter().filter(|r| r.track == track).count();
    let e = fit_method(Method::Pca, &s, &settings)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(&format!(
            "skewness in {on_track} (a track without road profiles"
        )),
        "{e}"
    );
    assert_eq!(e.matches("road profiles").count(), 1, "{e}");
}
