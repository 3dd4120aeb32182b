//! `tirewear predict`: its arguments and what it runs.

use anyhow::{Context, Result};
use std::path::PathBuf;
use tirewear::model::interval::{Coverage, IntervalLevel};
use tirewear::model::saved::SavedModel;

#[derive(clap::Args)]
pub(crate) struct PredictArgs {
    /// Model written by `tirewear fit` (e.g. models/physical.json).
    model: PathBuf,
    /// KPI database (Parquet, as written by `tirewear extract`).
    kpis: PathBuf,
    /// Predictions to write (CSV: event, track, car, run, wheel, axle,
    /// compound, measured and predicted mean wear in %, the prediction
    /// interval's and the new-event interval's bounds in %, a note where a
    /// row has no prediction).
    #[arg(long, default_value = "predictions.csv")]
    out: PathBuf,
    /// Coverage of the two intervals written beside each prediction: the
    /// model's own for a new tire at the training events (the PCA and
    /// physical models' regression interval, the network's split-conformal
    /// one from its validation rows) and the one for a tire at a new event
    /// (split conformal on the training tires' errors with their event left
    /// out of the fit): docs/models.md. Between 0 and 1.
    #[arg(long, default_value = "0.95", value_name = "LEVEL", value_parser = parse_level)]
    interval: IntervalLevel,
}

fn parse_level(s: &str) -> Result<IntervalLevel, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    IntervalLevel::new(v).map_err(|e| e.to_string())
}

pub(crate) fn run_predict(
    model: &std::path::Path,
    kpis: &std::path::Path,
    out: &std::path::Path,
    level: IntervalLevel,
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
        /// The prediction interval's bounds; NaN without one.
        predicted_low_pct: f64,
        predicted_high_pct: f64,
        /// The new-event interval's bounds (docs/models.md); NaN without one.
        new_event_low_pct: f64,
        new_event_high_pct: f64,
        note: String,
        #[serde(skip)]
        worn_through: bool,
    }
    let mut out_rows = Vec::with_capacity(rows.len());
    for r in &rows {
        let (p, (low, high), note) = match m.predict_row_within(r, Some(level)) {
            Ok((p, interval)) => (p, interval.unwrap_or((f64::NAN, f64::NAN)), String::new()),
            Err(e) => (f64::NAN, (f64::NAN, f64::NAN), e.to_string()),
        };
        let (event_low, event_high) = m
            .event_interval_around(p, r.axle, level)
            .unwrap_or((f64::NAN, f64::NAN));
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
            predicted_low_pct: low,
            predicted_high_pct: high,
            new_event_low_pct: event_low,
            new_event_high_pct: event_high,
            note,
            worn_through: r.worn_through_readings > 0.0,
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
    // Of the measured, uncensored wears with an interval, how many it holds.
    let inside = |events: Option<&[String]>, bounds: fn(&Prediction) -> (f64, f64)| {
        Coverage::of(
            out_rows
                .iter()
                .filter(|p| events.is_none_or(|e| e.iter().any(|e| *e == p.event)))
                .filter(|p| !p.worn_through && p.measured_wear_pct.is_finite())
                .map(|p| {
                    (
                        p.measured_wear_pct,
                        Some(bounds(p)).filter(|b| b.0.is_finite()),
                    )
                }),
        )
    };
    type Bounds = fn(&Prediction) -> (f64, f64);
    let own: Bounds = |p| (p.predicted_low_pct, p.predicted_high_pct);
    let new_event: Bounds = |p| (p.new_event_low_pct, p.new_event_high_pct);
    for (what, why, bounds) in [
        ("prediction intervals", m.why_no_intervals(level), own),
        (
            "new-event intervals",
            m.why_no_event_intervals(level),
            new_event,
        ),
    ] {
        let line = IntervalLine {
            what,
            level,
            all: inside(None, bounds),
            training: inside(Some(&m.training_events), bounds),
            testing: inside(Some(&m.testing_events), bounds),
        };
        println!("{}", line.render(why));
    }
    Ok(())
}

/// One kind of interval `predict` wrote and how many measured wears it
/// holds: all rows, then the model's training and testing events.
struct IntervalLine {
    /// "prediction intervals" or "new-event intervals".
    what: &'static str,
    level: IntervalLevel,
    all: Coverage,
    training: Coverage,
    testing: Coverage,
}

impl IntervalLine {
    /// What `predict` says of them: why there are none (`why`), or the
    /// check that they are as wide as they claim.
    fn render(&self, why: Option<String>) -> String {
        let what = self.what;
        // 0.9 is 90.00000000000001 %.
        let pct = (1e6 * self.level.get()).round() / 1e4;
        if let Some(why) = why {
            return format!("no {pct} % {what}: {why}");
        }
        if self.all.of == 0 {
            return format!("{pct} % {what} written; no measured wear to check them against");
        }
        let part = |name: &str, c: Coverage| (c.of > 0).then(|| format!("{name} {c}"));
        let parts: Vec<String> = [
            part("training events", self.training),
            part("testing events", self.testing),
        ]
        .into_iter()
        .flatten()
        .collect();
        format!(
            "{pct} % {what}: they hold {} measured wears{}",
            self.all,
            if parts.is_empty() {
                String::new()
            } else {
                format!(" ({})", parts.join(", "))
            }
        )
    }
}

/// Runs `tirewear predict`.
pub(crate) fn run(a: PredictArgs) -> Result<()> {
    run_predict(&a.model, &a.kpis, &a.out, a.interval)
}
