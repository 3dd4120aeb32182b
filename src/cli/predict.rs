//! `tirewear predict`: its arguments and what it runs.

use anyhow::{Context, Result};
use std::path::PathBuf;
use tirewear::model::saved::SavedModel;

#[derive(clap::Args)]
pub(crate) struct PredictArgs {
    /// Model written by `tirewear fit` (e.g. models/physical.json).
    model: PathBuf,
    /// KPI database (Parquet, as written by `tirewear extract`).
    kpis: PathBuf,
    /// Predictions to write (CSV: event, track, car, run, wheel, axle,
    /// compound, measured and predicted mean wear in %).
    #[arg(long, default_value = "predictions.csv")]
    out: PathBuf,
}

pub(crate) fn run_predict(
    model: &std::path::Path,
    kpis: &std::path::Path,
    out: &std::path::Path,
) -> Result<()> {
    let inputs = [
        ("the model".to_string(), model.to_path_buf()),
        ("the KPI database".to_string(), kpis.to_path_buf()),
    ];
    tirewear::atomic::check_destinations(&[("predictions", out)], &inputs)?;
    let m = SavedModel::load(model)?;
    let units = tirewear::kpi::table::read_units(kpis)?;
    m.check_columns(&units)
        .with_context(|| format!("{} against {}", kpis.display(), model.display()))?;
    if units.iter().all(|(_, u)| u.is_none()) {
        tracing::warn!(
            "{} states no units; assuming those of docs/kpis.md",
            kpis.display()
        );
    }
    // A table without rows (a night on which every run failed) would give an
    // empty predictions file and exit 0: refused like `fit` and `gap` do.
    let rows = tirewear::kpi::table::read_parquet_rows(kpis)?;
    #[derive(serde::Serialize)]
    struct Prediction<'a> {
        event: &'a str,
        track: &'a str,
        car: &'a str,
        run: &'a str,
        wheel: &'a str,
        axle: &'a str,
        compound: &'a str,
        measured_wear_pct: f64,
        /// NaN when the row has no prediction; `note` says why.
        predicted_wear_pct: f64,
        note: String,
    }
    let mut out_rows = Vec::with_capacity(rows.len());
    for r in &rows {
        let (p, note) = match m.predict_row(r) {
            Ok(p) => (p, String::new()),
            Err(e) => (f64::NAN, e.to_string()),
        };
        out_rows.push(Prediction {
            event: &r.event,
            track: &r.track,
            car: &r.car,
            run: &r.run,
            wheel: r.wheel.name(),
            axle: r.axle.name(),
            compound: &r.compound,
            measured_wear_pct: r.wear_mean_pct,
            predicted_wear_pct: p,
            note,
        });
    }
    let missing = out_rows.iter().filter(|p| !p.note.is_empty()).count();
    if missing > 0 {
        let first = out_rows
            .iter()
            .find(|p| !p.note.is_empty())
            .expect("counted");
        println!(
            "{missing} rows have no prediction (NaN, reason in the note column), e.g. {}",
            first.note
        );
    }
    tirewear::atomic::write_csv(out, &out_rows)
        .with_context(|| format!("writing {}", out.display()))?;
    // Indicators over the rows with both a measurement and a prediction.
    let both: Vec<&Prediction> = out_rows
        .iter()
        .filter(|p| p.measured_wear_pct.is_finite() && p.predicted_wear_pct.is_finite())
        .collect();
    let observed: Vec<f64> = both.iter().map(|p| p.measured_wear_pct).collect();
    let predicted: Vec<f64> = both.iter().map(|p| p.predicted_wear_pct).collect();
    match tirewear::model::metrics::metrics(&observed, &predicted, m.features.len()) {
        Ok(x) => println!(
            "wrote {}: {} predictions ({} model); against the measured wear R² {:.4}, RMSE {:.4} %",
            out.display(),
            x.n,
            m.method(),
            x.r2,
            x.rmse
        ),
        Err(_) => println!(
            "wrote {}: {} rows, {} with a prediction ({} model)",
            out.display(),
            out_rows.len(),
            out_rows.len() - missing,
            m.method()
        ),
    }
    Ok(())
}

/// Runs `tirewear predict`.
pub(crate) fn run(a: PredictArgs) -> Result<()> {
    run_predict(&a.model, &a.kpis, &a.out)
}
