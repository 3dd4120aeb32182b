//! `tirewear fit`: the three methods on one split of the KPI database,
//! each returned as a saved model with its performance table.

use super::data::{TARGET, candidate_inputs, select_inputs, split_by_events};
use super::interval::{Coverage, IntervalLevel};
use super::metrics::metrics;
use super::network::NetworkSettings;
use super::ols::OlsSettings;
use super::pca::PcaSettings;
use super::physical::{PHYSICAL_INPUTS, analyse_axle};
use super::saved::{
    EventErrors, Feature, Indicators, MODEL_FORMAT, MODEL_VERSION, ModelBody, SavedModel,
};
use super::{Dataset, Fit, ModelError};
use crate::Axle;
use crate::kpi::KpiRow;
use crate::kpi::table::road_hint;
use std::fmt::Write;

/// A wear-model method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Feed-forward network trained by Levenberg–Marquardt (paper 4.1).
    Ffnn,
    /// PCA + multiple linear regression (paper 4.2).
    Pca,
    /// Physical correlations + regression per axle (paper 4.3).
    Physical,
}

impl Method {
    pub const ALL: [Method; 3] = [Method::Ffnn, Method::Pca, Method::Physical];
}

/// Settings of a fit.
#[derive(Debug, Clone, Default)]
pub struct FitSettings {
    /// Testing events; None = every third event (docs/models.md).
    pub test_events: Option<Vec<String>>,
    pub network: NetworkSettings,
    /// The PCA + regression method's components (threshold 0.99, the paper's).
    pub pca: PcaSettings,
    /// A progress bar over the network's widths (a season's network takes
    /// a minute: docs/models.md).
    pub progress: bool,
}

impl FitSettings {
    /// Every setting in its range, or the first one that is not, named.
    pub fn check(&self) -> Result<(), ModelError> {
        self.pca.check()?;
        self.network.check()
    }
}

/// Rows usable by a model: finite target and inputs, and a tread not worn
/// through (censored wear). Returns the kept rows and a note for each
/// dropped one; where every row of a track lacks the same values (a track
/// without road profiles), one note for the track says so instead of one
/// per tire.
fn usable<'a>(rows: &[&'a KpiRow], inputs: &[String], set: &str) -> (Vec<&'a KpiRow>, Vec<String>) {
    let mut ok = Vec::new();
    let mut dropped: Vec<(&KpiRow, Option<Vec<&str>>)> = Vec::new();
    for r in rows {
        let bad: Vec<&str> = std::iter::once(TARGET)
            .chain(inputs.iter().map(String::as_str))
            .filter(|c| !r.number(c).is_some_and(f64::is_finite))
            .collect();
        if r.worn_through_readings > 0.0 {
            // A reading at the worn-through depth: the tread is gone there, and the
            // tire's wear is only a lower bound.
            dropped.push((r, None));
        } else if bad.is_empty() {
            ok.push(*r)
        } else {
            dropped.push((r, Some(bad)))
        }
    }
    (ok, drop_notes(rows, &dropped, set))
}

/// The notes for [`usable`]'s dropped rows (`None`: censored; else the
/// columns without a value), a whole track's rows lacking the same road
/// or viscoelastic columns in one note.
fn drop_notes(
    rows: &[&KpiRow],
    dropped: &[(&KpiRow, Option<Vec<&str>>)],
    set: &str,
) -> Vec<String> {
    use std::collections::{HashMap, HashSet};
    // Per track: how many rows it has here, and what each row dropped for
    // missing values lacks.
    let mut count: HashMap<&str, usize> = HashMap::new();
    for r in rows {
        *count.entry(r.track.as_str()).or_default() += 1;
    }
    let mut lacking: HashMap<&str, Vec<&[&str]>> = HashMap::new();
    for (r, bad) in dropped {
        if let Some(bad) = bad {
            lacking.entry(r.track.as_str()).or_default().push(bad);
        }
    }
    let whole_tracks: HashSet<&str> = lacking
        .iter()
        .filter(|(t, bads)| {
            bads.len() == count[*t]
                && bads.iter().all(|b| *b == bads[0])
                && !road_hint(bads[0]).is_empty()
        })
        .map(|(t, _)| *t)
        .collect();
    let mut noted: HashSet<&str> = HashSet::new();
    let mut notes = Vec::new();
    for (r, bad) in dropped {
        match bad {
            None => notes.push(format!(
                "run {} wheel {}: tread worn through at {} reading{}, the wear is censored",
                r.run,
                r.wheel,
                r.worn_through_readings,
                if r.worn_through_readings == 1.0 {
                    ""
                } else {
                    "s"
                }
            )),
            Some(bad) if whole_tracks.contains(r.track.as_str()) => {
                if noted.insert(r.track.as_str()) {
                    notes.push(format!(
                        "track {}: all its {} {set} rows: not finite: {}{}",
                        r.track,
                        count[r.track.as_str()],
                        bad.join(", "),
                        road_hint(bad)
                    ));
                }
            }
            Some(bad) => notes.push(format!(
                "run {} wheel {}: not finite: {}",
                r.run,
                r.wheel,
                bad.join(", ")
            )),
        }
    }
    notes
}

/// Why no training row is usable: how many lack each needed column (the
/// most first) or are censored, out of how many.
fn no_rows_left(rows: &[&KpiRow], inputs: &[String]) -> String {
    if rows.is_empty() {
        return "no training rows: the table has none outside the testing events".into();
    }
    let mut missing: Vec<(usize, &str)> = std::iter::once(TARGET)
        .chain(inputs.iter().map(String::as_str))
        .map(|c| {
            let n = rows
                .iter()
                .filter(|r| !r.number(c).is_some_and(f64::is_finite))
                .count();
            (n, c)
        })
        .filter(|&(n, _)| n > 0)
        .collect();
    missing.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(b.1)));
    let shown = &missing[..missing.len().min(6)];
    let mut why: Vec<String> = shown
        .iter()
        .map(|&(n, c)| {
            let hint = if c == TARGET {
                " (no wear readings: docs/formats.md section 5)"
            } else {
                ""
            };
            format!("{c} in {n}{hint}")
        })
        .collect();
    if missing.len() > 6 {
        why.push(format!("{} more columns", missing.len() - 6));
    }
    // Once, after the columns, where any is a road one.
    let columns: Vec<&str> = shown.iter().map(|&(_, c)| c).collect();
    if let Some(last) = why.last_mut() {
        last.push_str(road_hint(&columns));
    }
    let worn = rows
        .iter()
        .filter(|r| r.worn_through_readings > 0.0)
        .count();
    if worn > 0 {
        why.push(format!("{worn} worn through (censored)"));
    }
    format!(
        "no usable training rows: of the {} training rows, each lacks a value a model needs \
         or is censored: {}",
        rows.len(),
        why.join(", ")
    )
}

fn matrix(rows: &[&KpiRow], inputs: &[String]) -> Vec<Vec<f64>> {
    rows.iter()
        .map(|r| {
            inputs
                .iter()
                .map(|c| r.number(c).expect("KPI column"))
                .collect()
        })
        .collect()
}

fn target(rows: &[&KpiRow]) -> Vec<f64> {
    rows.iter().map(|r| r.wear_mean_pct).collect()
}

/// The split, shared by all methods.
pub struct Split<'a> {
    pub train: Vec<&'a KpiRow>,
    pub test: Vec<&'a KpiRow>,
    pub test_events: Vec<String>,
    pub train_events: Vec<String>,
}

pub fn split<'a>(
    rows: &'a [KpiRow],
    test_events: Option<&[String]>,
) -> Result<Split<'a>, ModelError> {
    if let Some(list) = test_events {
        let unknown: Vec<&String> = list
            .iter()
            .filter(|e| !rows.iter().any(|r| &r.event == *e))
            .collect();
        if !unknown.is_empty() {
            return Err(ModelError::Invalid(format!(
                "testing events not in the table: {}",
                unknown
                    .iter()
                    .map(|s| if s.is_empty() {
                        "'' (an empty id: a stray comma?)"
                    } else {
                        s.as_str()
                    })
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
    }
    let (tr, te, test_events) = split_by_events(rows, test_events);
    if tr.is_empty() && !te.is_empty() {
        // Else each method (and gap) fails on its own, the physical one
        // blaming road profiles for columns no training row has.
        return Err(ModelError::Invalid(format!(
            "testing events {}: they are every event of the table, so no row is left to \
             train on (name fewer, or leave --test-events out: every third event tests)",
            test_events.join(", ")
        )));
    }
    let mut train_events: Vec<String> = tr.iter().map(|&i| rows[i].event.clone()).collect();
    train_events.sort();
    train_events.dedup();
    Ok(Split {
        train: tr.iter().map(|&i| &rows[i]).collect(),
        test: te.iter().map(|&i| &rows[i]).collect(),
        test_events,
        train_events,
    })
}

/// One line of a model's indicator table and the rows it was computed on
/// (a split, of one axle for the physical method's lines).
struct Line<'a> {
    indicators: Indicators,
    rows: Vec<&'a KpiRow>,
}

/// Training and (when there are testing rows) testing indicators of a predictor.
fn indicators<'a>(
    prefix: &str,
    train: &[&'a KpiRow],
    test: &[&'a KpiRow],
    k: usize,
    predict: impl Fn(&KpiRow) -> (f64, Option<(f64, f64)>),
) -> Result<Vec<Line<'a>>, ModelError> {
    let mut out = Vec::new();
    for (label, rows) in [("Training", train), ("Testing", test)] {
        if rows.is_empty() {
            continue;
        }
        let predicted: Vec<(f64, Option<(f64, f64)>)> = rows.iter().map(|r| predict(r)).collect();
        let p: Vec<f64> = predicted.iter().map(|(p, _)| *p).collect();
        let y = target(rows);
        let inside = Coverage::of(predicted.iter().zip(&y).map(|(&(_, i), &y)| (y, i)));
        out.push(Line {
            indicators: Indicators {
                label: format!("{prefix}{label}"),
                metrics: metrics(&y, &p, k)?,
                inside_95_interval: inside.share(),
                inside_95_event_interval: None,
            },
            rows: rows.to_vec(),
        });
    }
    Ok(out)
}

/// Fits one method on the split, then again without each training event
/// in turn for its new-event intervals ([`event_errors`]).
pub fn fit_method(
    method: Method,
    s: &Split,
    settings: &FitSettings,
) -> Result<(SavedModel, Vec<String>), ModelError> {
    let Fitted {
        mut model,
        mut notes,
        line_rows,
    } = fit_core(method, s, settings)?;
    model.event_errors = event_errors(method, s, settings, &model, &mut notes);
    if model.event_errors.is_some() {
        // The event errors come after the lines (the network's refits need
        // its chosen width): each line's share is added on its own rows.
        let mut lines = std::mem::take(&mut model.indicators);
        for (line, rows) in lines.iter_mut().zip(&line_rows) {
            let inside = Coverage::of(rows.iter().filter_map(|r| {
                let p = model.predict_row(r).ok()?;
                Some((
                    r.wear_mean_pct,
                    model.event_interval_around(p, r.axle, IntervalLevel::P95),
                ))
            }));
            line.inside_95_event_interval = inside.share();
        }
        model.indicators = lines;
    }
    Ok((model, notes))
}

/// Most refits the new-event errors take: a season's training events are
/// grouped into this many folds beyond it (a network refit at season scale
/// costs about a second per training on 2 cores).
pub const MAX_EVENT_FOLDS: usize = 8;

/// The training tires' errors when their event is left out of the fit,
/// |y − ŷ₋ₑ| in %: the method fitted again without the event (the network
/// at the width the full fit chose, its input selection and training
/// redone; PCA's selection and components and the physical method's lines
/// redone) predicts the left-out event's measured tires. With more than
/// [`MAX_EVENT_FOLDS`] training events, they are left out in that many
/// folds (the sorted events dealt round-robin). The scores of the
/// split-conformal new-event interval (`SavedModel::event_interval_around`):
/// a new race is a new event, whose shift from the training events the
/// model's own interval does not see. None with one training event; a fold
/// whose refit fails is named in the notes and left out.
fn event_errors(
    method: Method,
    s: &Split,
    settings: &FitSettings,
    model: &SavedModel,
    notes: &mut Vec<String>,
) -> Option<EventErrors> {
    use rayon::prelude::*;
    if s.train_events.len() < 2 {
        notes.push(
            "no new-event intervals: one training event, none to leave out (docs/models.md)".into(),
        );
        return None;
    }
    let mut again = settings.clone();
    again.progress = false;
    if let ModelBody::Ffnn { network, .. } = &model.model {
        again.network.hidden2_candidates = vec![network.net.hidden2];
    }
    let k = s.train_events.len().min(MAX_EVENT_FOLDS);
    let mut events = s.train_events.clone();
    events.sort();
    let folds: Vec<Vec<String>> = (0..k)
        .map(|f| events.iter().skip(f).step_by(k).cloned().collect())
        .collect();
    // A season's network takes as long again as its width search: a bar.
    let bar = crate::progress::bar(
        settings.progress,
        k as u64,
        "refitting without each training event",
    );
    let per_fold: Vec<Result<Vec<(Axle, f64)>, String>> = folds
        .par_iter()
        .map(|fold| {
            let (test, train): (Vec<&KpiRow>, Vec<&KpiRow>) = s
                .train
                .iter()
                .copied()
                .partition(|r| fold.contains(&r.event));
            let sub = Split {
                train,
                test,
                test_events: fold.clone(),
                train_events: events
                    .iter()
                    .filter(|e| !fold.contains(e))
                    .cloned()
                    .collect(),
            };
            let fitted = fit_core(method, &sub, &again);
            bar.inc(1);
            let m = fitted
                .map_err(|err| format!("{}: {err}", fold.join(", ")))?
                .model;
            Ok(sub
                .test
                .iter()
                .filter(|r| r.worn_through_readings <= 0.0 && r.wear_mean_pct.is_finite())
                .filter_map(|r| {
                    let p = m.predict_row(r).ok().filter(|p| p.is_finite())?;
                    Some((r.axle, (r.wear_mean_pct - p).abs()))
                })
                .collect())
        })
        .collect();
    bar.finish_and_clear();
    let mut errors = EventErrors {
        events: Vec::new(),
        folds: 0,
        front: Vec::new(),
        rear: Vec::new(),
    };
    for (fold, result) in folds.iter().zip(per_fold) {
        match result {
            Ok(scores) => {
                errors.events.extend(fold.iter().cloned());
                errors.folds += 1;
                for (axle, v) in scores {
                    match axle {
                        Axle::Front => errors.front.push(v),
                        Axle::Rear => errors.rear.push(v),
                    }
                }
            }
            Err(why) => notes.push(format!(
                "new-event intervals: leaving out {why}; its tires are not among the scores"
            )),
        }
    }
    errors.events.sort();
    errors.front.sort_by(f64::total_cmp);
    errors.rear.sort_by(f64::total_cmp);
    (errors.folds >= 2).then_some(errors)
}

/// A method fitted on a split, with what its indicators were computed on.
struct Fitted<'a> {
    model: SavedModel,
    notes: Vec<String>,
    /// The rows of each of `model.indicators`, in its order (usable rows,
    /// [`usable`]).
    line_rows: Vec<Vec<&'a KpiRow>>,
}

/// Fits one method on the split.
fn fit_core<'a>(
    method: Method,
    s: &Split<'a>,
    settings: &FitSettings,
) -> Result<Fitted<'a>, ModelError> {
    settings.check()?;
    let (candidates, mut notes) = present_inputs(method, &s.train)?;
    let (train, dropped) = usable(&s.train, &candidates, "training");
    notes.extend(dropped);
    let (test, dropped) = usable(&s.test, &candidates, "testing");
    notes.extend(dropped);
    if train.is_empty() {
        return Err(ModelError::Invalid(no_rows_left(&s.train, &candidates)));
    }
    let (features, body, table) = match method {
        Method::Ffnn => fit_network_body(&train, &test, settings)?,
        Method::Pca => fit_pca_body(&train, &test, settings)?,
        Method::Physical => fit_physical_body(&train, &test)?,
    };
    let (table, line_rows): (Vec<Indicators>, Vec<Vec<&KpiRow>>) =
        table.into_iter().map(|l| (l.indicators, l.rows)).unzip();
    let model = SavedModel {
        format: MODEL_FORMAT.into(),
        version: MODEL_VERSION,
        tirewear_version: env!("CARGO_PKG_VERSION").into(),
        target: Feature::of(TARGET),
        features: features.iter().map(|f| Feature::of(f)).collect(),
        training_events: s.train_events.clone(),
        testing_events: s.test_events.clone(),
        indicators: table,
        model: body,
        event_errors: None,
    };
    Ok(Fitted {
        model,
        notes,
        line_rows,
    })
}

/// The candidate inputs some training row has a value of, and a note
/// naming the others. A column no training row has (the road KPIs of a
/// season without road profiles) would leave out every row: it is left
/// out instead, unless the physical method needs it.
fn present_inputs(
    method: Method,
    train: &[&KpiRow],
) -> Result<(Vec<String>, Vec<String>), ModelError> {
    let (candidates, absent): (Vec<String>, Vec<String>) = candidate_inputs()
        .iter()
        .map(|c| c.to_string())
        .partition(|c| {
            train
                .iter()
                .any(|r| r.number(c).is_some_and(f64::is_finite))
        });
    let mut notes = Vec::new();
    if !absent.is_empty() {
        if method == Method::Physical {
            let needed: Vec<&str> = PHYSICAL_INPUTS
                .into_iter()
                .filter(|c| absent.iter().any(|a| a == c))
                .collect();
            if !needed.is_empty() {
                return Err(ModelError::Invalid(format!(
                    "the physical method needs {}, which no training row has{}",
                    needed.join(", "),
                    road_hint(&needed)
                )));
            }
        }
        let shown: Vec<&str> = absent.iter().map(String::as_str).collect();
        notes.push(format!(
            "inputs {}: no training row has a value{}",
            shown.join(", "),
            road_hint(&shown)
        ));
    }
    Ok((candidates, notes))
}

/// A method's inputs, its fitted body and its indicator lines.
type Body<'a> = (Vec<String>, ModelBody, Vec<Line<'a>>);

/// Every candidate input's column over `rows` (usable rows: each has them all).
fn columns(rows: &[&KpiRow]) -> Vec<(&'static str, Vec<f64>)> {
    candidate_inputs()
        .into_iter()
        .map(|c| {
            (
                c,
                rows.iter().map(|r| r.number(c).expect("column")).collect(),
            )
        })
        .collect()
}

/// `inputs` of a row, in their order (a usable row has them all).
fn row_inputs(r: &KpiRow, inputs: &[String]) -> Vec<f64> {
    inputs
        .iter()
        .map(|c| r.number(c).expect("column"))
        .collect()
}

/// The network (paper section 4.1): inputs chosen by their correlation
/// with the wear and with each other, trained by Levenberg–Marquardt.
fn fit_network_body<'a>(
    train: &[&'a KpiRow],
    test: &[&'a KpiRow],
    settings: &FitSettings,
) -> Result<Body<'a>, ModelError> {
    let ns = &settings.network;
    let y = target(train);
    let inputs = select_inputs(
        &columns(train),
        Some((&y, ns.min_target_corr)),
        ns.max_mutual_corr,
    );
    let x = matrix(train, &inputs);
    let bar = crate::progress::bar(settings.progress, 0, "training the network's widths");
    let network = super::network::fit_network(&x, &y, ns, &bar);
    bar.finish_and_clear();
    let network = network?;
    let predict = |r: &KpiRow| {
        let x = row_inputs(r, &inputs);
        (
            network.net.predict_one(&x),
            network.prediction_interval(&x, IntervalLevel::P95),
        )
    };
    let table = indicators("", train, test, inputs.len(), predict)?;
    let body = ModelBody::Ffnn {
        settings: ns.clone(),
        network,
    };
    Ok((inputs, body, table))
}

/// PCA + regression (paper section 4.2): the mutually uncorrelated inputs'
/// principal components, the wear regressed on the kept ones.
fn fit_pca_body<'a>(
    train: &[&'a KpiRow],
    test: &[&'a KpiRow],
    settings: &FitSettings,
) -> Result<Body<'a>, ModelError> {
    let all = columns(train);
    let inputs = select_inputs(&all, None, settings.network.max_mutual_corr);
    let dropped_correlated = all
        .iter()
        .map(|c| c.0.to_string())
        .filter(|c| !inputs.contains(c))
        .collect();
    let x = matrix(train, &inputs);
    let pca = settings.pca.fit(Dataset::new(&x, &[], &inputs))?;
    let scores = pca.transform(&matrix(train, &inputs));
    let names: Vec<String> = (1..=pca.kept).map(|i| format!("PC{i}")).collect();
    let regression = OlsSettings.fit(Dataset::new(&scores, &target(train), &names))?;
    let predict = |r: &KpiRow| {
        let scores = &pca.transform(&[row_inputs(r, &inputs)])[0];
        (
            regression.predict_one(scores),
            regression.prediction_interval(scores, IntervalLevel::P95),
        )
    };
    let table = indicators("", train, test, pca.kept, predict)?;
    let body = ModelBody::Pca {
        dropped_correlated,
        pca,
        regression,
    };
    Ok((inputs, body, table))
}

/// The physical correlations + regression (paper section 4.3), per axle.
fn fit_physical_body<'a>(
    train: &[&'a KpiRow],
    test: &[&'a KpiRow],
) -> Result<Body<'a>, ModelError> {
    fn axle<'r>(rows: &[&'r KpiRow], a: Axle) -> Vec<&'r KpiRow> {
        rows.iter().filter(|r| r.axle == a).copied().collect()
    }
    let of = |a: Axle| analyse_axle(a, &axle(train, a));
    let (front, rear) = (of(Axle::Front)?, of(Axle::Rear)?);
    let mut table = Vec::new();
    for (name, a) in [("Front—", &front), ("Rear—", &rear)] {
        let predict = |r: &KpiRow| {
            let x = super::physical::inputs_of(r);
            let interval = a.regression.prediction_interval(&x, IntervalLevel::P95);
            (a.regression.predict_one(&x), interval)
        };
        table.extend(indicators(
            name,
            &axle(train, a.axle),
            &axle(test, a.axle),
            PHYSICAL_INPUTS.len(),
            predict,
        )?);
    }
    let inputs = PHYSICAL_INPUTS.iter().map(|c| c.to_string()).collect();
    Ok((inputs, ModelBody::Physical { front, rear }, table))
}

fn method_title(m: &SavedModel) -> &'static str {
    match m.model {
        ModelBody::Ffnn { .. } => "Feed-forward neural network (Levenberg–Marquardt)",
        ModelBody::Pca { .. } => "PCA + multiple linear regression",
        ModelBody::Physical { .. } => "Physical correlations + regression",
    }
}

/// An adjusted R² for a table: four decimals, or "–" where undefined.
fn r2_adj_cell(r2_adj: Option<f64>) -> String {
    r2_adj.map_or_else(|| "–".to_string(), |v| format!("{v:.4}"))
}

/// A share an indicator line may carry.
type IndicatorShare = fn(&Indicators) -> Option<f64>;

/// The columns of the shares of tires inside their 95 % intervals, each
/// where one of `lines` has it: the model's own prediction interval ("in
/// 95 % PI") and the new-event interval ("new-event PI").
const INTERVAL_COLUMNS: [(&str, IndicatorShare); 2] = [
    ("  in 95 % PI", |i| i.inside_95_interval),
    ("  new-event PI", |i| i.inside_95_event_interval),
];

fn interval_header(lines: &[&Indicators]) -> String {
    INTERVAL_COLUMNS
        .iter()
        .filter(|(_, share)| lines.iter().any(|i| share(i).is_some()))
        .map(|(header, _)| *header)
        .collect()
}

/// A line's cells under [`interval_header`], right-aligned to it ("–"
/// where the line has no share).
fn interval_cell(lines: &[&Indicators], i: &Indicators) -> String {
    INTERVAL_COLUMNS
        .iter()
        .filter(|(_, share)| lines.iter().any(|i| share(i).is_some()))
        .map(|(header, share)| {
            let cell = share(i).map_or("–".into(), |v| format!("{:.1} %", 100.0 * v));
            format!("{cell:>w$}", w = header.chars().count())
        })
        .collect()
}

/// The performance table of a model, like the paper's tables 8, 9 and 11,
/// with the share of tires inside their 95 % prediction interval for the
/// regressions.
pub fn render_table(m: &SavedModel) -> String {
    let mut s = String::new();
    let lines: Vec<&Indicators> = m.indicators.iter().collect();
    let _ = writeln!(s, "{} — inputs: {}", method_title(m), m.features.len());
    let _ = writeln!(
        s,
        "  {:<20} {:>5} {:>8} {:>8} {:>9} {:>9}{}",
        "",
        "n",
        "R²",
        "R²adj",
        "RMSE %",
        "MAE %",
        interval_header(&lines)
    );
    for i in &m.indicators {
        let x = &i.metrics;
        let _ = writeln!(
            s,
            "  {:<20} {:>5} {:>8.4} {:>8} {:>9.4} {:>9.4}{}",
            i.label,
            x.n,
            x.r2,
            r2_adj_cell(x.r2_adj),
            x.rmse,
            x.mae,
            interval_cell(&lines, i)
        );
    }
    match &m.model {
        ModelBody::Ffnn { network, .. } => {
            let _ = writeln!(
                s,
                "  architecture {}–{}–{}–1 (second layer chosen among {} widths; retrained pair kept: {}); best epoch {}",
                network.net.inputs,
                network.net.hidden1,
                network.net.hidden2,
                network.trials.len(),
                network.retrained_kept,
                network.net.best_epoch
            );
            let _ = writeln!(
                s,
                "  inputs: {}",
                m.features
                    .iter()
                    .map(|f| f.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        ModelBody::Pca {
            pca,
            dropped_correlated,
            ..
        } => {
            let cum: f64 = pca.proportions[..pca.kept].iter().sum();
            let _ = writeln!(
                s,
                "  {} inputs after dropping {} correlated; {} components explain {:.2} % of the variance",
                pca.inputs.len(),
                dropped_correlated.len(),
                pca.kept,
                100.0 * cum
            );
        }
        ModelBody::Physical { front, rear } => {
            for a in [front, rear] {
                let _ = writeln!(
                    s,
                    "  {}: {} tracks; corr(slope, T_surf) = {:+.2}; corr(residual, skewness) = {:+.2}",
                    a.axle,
                    a.lines.len(),
                    a.slope_vs_t_surface,
                    a.residual_vs_skewness
                );
                let r = &a.regression;
                for (j, name) in std::iter::once("intercept")
                    .chain(r.inputs.iter().map(String::as_str))
                    .enumerate()
                {
                    let _ = writeln!(
                        s,
                        "    {:<20} {:>+12.4e} ± {:>10.3e}  p = {:.3}",
                        name, r.coef[j], r.std_err[j], r.p_values[j]
                    );
                }
            }
        }
    }
    s
}

/// A comparison of the methods' testing indicators (one line per model and axle).
pub fn render_comparison(models: &[SavedModel]) -> String {
    let mut s = String::from("Comparison on the testing events\n");
    fn testing(m: &SavedModel) -> Vec<&Indicators> {
        m.indicators
            .iter()
            .filter(|i| i.label.ends_with("Testing"))
            .collect()
    }
    let lines: Vec<&Indicators> = models.iter().flat_map(testing).collect();
    let _ = writeln!(
        s,
        "  {:<42} {:>5} {:>8} {:>8} {:>9}{}",
        "model",
        "n",
        "R²",
        "R²adj",
        "RMSE %",
        interval_header(&lines)
    );
    for m in models {
        for i in testing(m) {
            let label = format!(
                "{} {}",
                m.method(),
                i.label.trim_end_matches("Testing").trim_end_matches('—')
            );
            let x = &i.metrics;
            let _ = writeln!(
                s,
                "  {:<42} {:>5} {:>8.4} {:>8} {:>9.4}{}",
                label.trim(),
                x.n,
                x.r2,
                r2_adj_cell(x.r2_adj),
                x.rmse,
                interval_cell(&lines, i)
            );
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_out_of_range_are_named() {
        assert_eq!(FitSettings::default().check(), Ok(()));
        assert_eq!(FitSettings::default().pca.threshold, 0.99);
        for t in [0.0, -0.5, 1.5, f64::NAN] {
            let s = FitSettings {
                pca: PcaSettings { threshold: t },
                ..Default::default()
            };
            let e = s.check().unwrap_err().to_string();
            assert!(e.starts_with("setting pca_threshold = "), "{e}");
        }
        let mut s = FitSettings::default();
        s.network.validation_fraction = 1.0;
        let e = s.check().unwrap_err().to_string();
        assert!(e.contains("network.validation_fraction = 1"), "{e}");
        s.network.validation_fraction = 0.2;
        s.network.hidden2_candidates = vec![3, 0];
        assert!(matches!(
            s.check(),
            Err(ModelError::Setting {
                name: "network.hidden2_candidates",
                ..
            })
        ));
    }

    /// Testing events that are every event of the table leave nothing to
    /// train on: one error saying so, not one per method (the physical
    /// one blamed road profiles); unknown events are named as before.
    #[test]
    fn testing_every_event_is_refused_by_the_split() {
        let rows: Vec<KpiRow> = ["E1", "E2", "E1"]
            .iter()
            .map(|e| KpiRow {
                event: e.to_string(),
                ..Default::default()
            })
            .collect();
        let all = ["E2".to_string(), "E1".to_string()];
        let e = split(&rows, Some(&all)).err().unwrap().to_string();
        assert!(
            e.starts_with("testing events E2, E1: they are every event of the table"),
            "{e}"
        );
        let s = split(&rows, Some(&all[..1])).ok().unwrap();
        assert_eq!((s.train.len(), s.test.len()), (2, 1));
        let e = split(&rows, Some(&["E9".to_string()]))
            .err()
            .unwrap()
            .to_string();
        assert_eq!(e, "testing events not in the table: E9");
        let stray = ["E1".to_string(), String::new()];
        let e = split(&rows, Some(&stray)).err().unwrap().to_string();
        assert_eq!(
            e,
            "testing events not in the table: '' (an empty id: a stray comma?)"
        );
    }

    /// A track without road profiles: its rows left out in one note naming
    /// the track, not one per tire (64 lines on the demo); other rows
    /// still one note each.
    #[test]
    fn a_whole_track_without_road_values_is_one_note() {
        let row = |track: &str, run: &str| KpiRow {
            track: track.into(),
            run: run.into(),
            wear_mean_pct: 10.0,
            friction_energy_j: 1e6,
            skewness: 0.1,
            loss_factor: 0.3,
            ..Default::default()
        };
        let no_road = |run: &str| KpiRow {
            skewness: f64::NAN,
            loss_factor: f64::NAN,
            ..row("a", run)
        };
        let rows = [
            no_road("a1"),
            no_road("a2"),
            no_road("a3"),
            row("b", "b1"),
            KpiRow {
                friction_energy_j: f64::NAN,
                ..row("b", "b2")
            },
            KpiRow {
                skewness: f64::NAN,
                ..row("b", "b3")
            },
            KpiRow {
                worn_through_readings: 2.0,
                ..row("c", "c1")
            },
        ];
        let refs: Vec<&KpiRow> = rows.iter().collect();
        let inputs: Vec<String> = ["friction_energy_j", "skewness", "loss_factor"]
            .map(String::from)
            .to_vec();
        let (ok, notes) = usable(&refs, &inputs, "training");
        assert_eq!(ok.len(), 1);
        assert_eq!(notes.len(), 4, "{notes:#?}");
        assert!(
            notes[0].starts_with("track a: all its 3 training rows: not finite: skewness, loss_factor (a track without road profiles"),
            "{}",
            notes[0]
        );
        // Track b lacks values in two of its three rows, and not the same.
        assert_eq!(notes[1], "run b2 wheel FL: not finite: friction_energy_j");
        assert_eq!(notes[2], "run b3 wheel FL: not finite: skewness");
        assert_eq!(
            notes[3],
            "run c1 wheel FL: tread worn through at 2 readings, the wear is censored"
        );
        // A track whose every row lacks a value the road does not explain
        // keeps one note per row.
        let rows: Vec<KpiRow> = ["d1", "d2"]
            .map(|r| KpiRow {
                friction_energy_j: f64::NAN,
                ..row("d", r)
            })
            .to_vec();
        let refs: Vec<&KpiRow> = rows.iter().collect();
        assert_eq!(usable(&refs, &inputs, "training").1.len(), 2);
    }
}
