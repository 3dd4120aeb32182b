//! `tirewear gap`: the baseline, the gap's size on training and testing
//! events, and where it lies; written as JSON and Markdown.

use super::baseline::PhysicsBaseline;
use super::candidates::{Candidate, Score, candidate_feature, library, rank};
use super::slices::{Slice, slice_residuals};
use crate::kpi::KpiRow;
use crate::kpi::energy_map::EnergyMaps;
use crate::model::ModelError;
use crate::model::fit::split;
use crate::model::saved::SavedModel;
use std::collections::BTreeMap;
use std::fmt::Write;

/// The simulation side of the gap.
pub enum Baseline {
    /// The frictional-energy wear law, calibrated on the training events.
    Physics,
    /// A model saved by `tirewear fit`.
    Model(Box<SavedModel>),
}

/// Size of the gap on a set of rows.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct GapSize {
    pub n: usize,
    /// Mean of measured − baseline (% of tread).
    pub bias_pct: f64,
    pub rmse_pct: f64,
}

/// One step of the forward selection (step 3).
#[derive(Debug, Clone, serde::Serialize)]
pub struct Step {
    /// The term added ("baseline" for the starting point).
    pub added: String,
    pub threshold: f64,
    pub coefficient: f64,
    pub training: GapSize,
    pub testing: Option<GapSize>,
    /// RMSE (%) inside each slice of `Diagnosis::slices` shown (same order, at most 5).
    pub slice_rmse_pct: Vec<f64>,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct Diagnosis {
    pub baseline: String,
    pub physics: Option<PhysicsBaseline>,
    pub training_events: Vec<String>,
    pub testing_events: Vec<String>,
    pub training: GapSize,
    pub testing: Option<GapSize>,
    /// False-discovery rate of the slice tests.
    pub fdr: f64,
    pub slices_tested: usize,
    /// Slices whose adjusted p-value is at most `fdr`, by share of the squared gap.
    pub slices: Vec<Slice>,
    /// Step 2: candidate effects ranked on the training events (empty without energy maps).
    pub candidates: Vec<Score>,
    /// Step 3: the gap before and after each significant term, added in turn.
    pub steps: Vec<Step>,
}

fn size(r: &[f64]) -> GapSize {
    let n = r.len();
    GapSize {
        n,
        bias_pct: r.iter().sum::<f64>() / n as f64,
        rmse_pct: (r.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt(),
    }
}

/// Runs steps 0–1 of the diagnosis on a KPI table.
pub fn diagnose(
    rows: &[KpiRow],
    maps: &BTreeMap<(String, String), EnergyMaps>,
    baseline: &Baseline,
    test_events: Option<&[String]>,
    fdr: f64,
) -> Result<Diagnosis, ModelError> {
    let s = split(rows, test_events)?;
    let (name, physics) = match baseline {
        Baseline::Physics => (
            "physics (wear = k_compound · E · exp(β(T_surf − 60 °C)))".to_string(),
            Some(PhysicsBaseline::fit(&s.train)),
        ),
        Baseline::Model(m) => (format!("{} model", m.method()), None),
    };
    let predict = |r: &KpiRow| -> f64 {
        match (baseline, &physics) {
            (Baseline::Model(m), _) => m.predict_row(r).unwrap_or(f64::NAN),
            (_, Some(p)) => p.predict(r),
            _ => f64::NAN,
        }
    };
    let residuals = |set: &[&KpiRow]| -> Vec<(usize, f64)> {
        set.iter()
            .enumerate()
            .map(|(i, r)| (i, r.wear_mean_pct - predict(r)))
            .filter(|(_, v)| v.is_finite())
            .collect()
    };
    let (tr, te) = (residuals(&s.train), residuals(&s.test));
    if tr.len() < 20 {
        return Err(ModelError::TooFewObservations {
            what: "gap diagnosis".into(),
            needed: 20,
            got: tr.len(),
        });
    }
    let trv: Vec<f64> = tr.iter().map(|x| x.1).collect();
    let tev: Vec<f64> = te.iter().map(|x| x.1).collect();
    // Slices over all rows with a residual: the gap is judged where it lies, in and out of training.
    let mut all_rows: Vec<&KpiRow> = tr.iter().map(|(i, _)| s.train[*i]).collect();
    all_rows.extend(te.iter().map(|(i, _)| s.test[*i]));
    let all_res: Vec<f64> = trv.iter().chain(&tev).copied().collect();
    let (tested, count) = slice_residuals(&all_rows, &all_res, fdr);
    let slices: Vec<Slice> = tested.into_iter().filter(|t| t.p_adjusted <= fdr).collect();

    // Steps 2 and 3 on the training rows; terms then apply to every row.
    let n_train = tr.len();
    let row_maps: Vec<Option<&EnergyMaps>> = all_rows
        .iter()
        .map(|r| maps.get(&(r.run.clone(), r.wheel.clone())))
        .collect();
    let lib = library(&all_rows);
    let mut res = all_res.clone();
    let members: Vec<Vec<bool>> = slices
        .iter()
        .take(5)
        .map(|s| slice_members(&s.name, &all_rows))
        .collect();
    let step_of = |added: String, threshold: f64, coefficient: f64, res: &[f64]| Step {
        added,
        threshold,
        coefficient,
        training: size(&res[..n_train]),
        testing: (res.len() > n_train).then(|| size(&res[n_train..])),
        slice_rmse_pct: members
            .iter()
            .map(|m| {
                let v: Vec<f64> = res
                    .iter()
                    .zip(m)
                    .filter(|(_, k)| **k)
                    .map(|(r, _)| *r)
                    .collect();
                size(&v).rmse_pct
            })
            .collect(),
    };
    let mut steps = vec![step_of("baseline".into(), f64::NAN, f64::NAN, &res)];
    let mut candidates = Vec::new();
    if !maps.is_empty() {
        let mut used: Vec<String> = Vec::new();
        for round in 0..5 {
            let ranked = rank(
                &all_rows[..n_train],
                &row_maps[..n_train],
                &res[..n_train],
                &lib,
            );
            if round == 0 {
                candidates = ranked.clone();
            }
            let Some(best) = ranked
                .iter()
                .find(|s| s.p_adjusted <= fdr && s.cv_gain > 0.0 && !used.contains(&s.name))
            else {
                break;
            };
            let cand = Candidate {
                name: best.name.clone(),
                feature: best.feature,
                thresholds: vec![best.threshold],
                axle: best.axle,
            };
            let a = {
                let x: Vec<f64> = (0..n_train)
                    .map(|i| candidate_feature(&cand, all_rows[i], row_maps[i], best.threshold))
                    .collect();
                let mx = x.iter().sum::<f64>() / n_train as f64;
                res[..n_train].iter().sum::<f64>() / n_train as f64 - best.coefficient * mx
            };
            for i in 0..res.len() {
                res[i] -= a + best.coefficient
                    * candidate_feature(&cand, all_rows[i], row_maps[i], best.threshold);
            }
            used.push(best.name.clone());
            steps.push(step_of(
                best.name.clone(),
                best.threshold,
                best.coefficient,
                &res,
            ));
        }
    }
    Ok(Diagnosis {
        baseline: name,
        physics,
        training_events: s.train_events.clone(),
        testing_events: s.test_events.clone(),
        training: size(&trv),
        testing: (!tev.is_empty()).then(|| size(&tev)),
        fdr,
        slices_tested: count,
        slices,
        candidates,
        steps,
    })
}

/// Rows of a slice named as in step 1 (`A & B`, each `col = level` or `col in Qk [lo, hi]`).
fn slice_members(name: &str, rows: &[&KpiRow]) -> Vec<bool> {
    let part = |p: &str, r: &KpiRow| -> bool {
        if let Some((col, level)) = p.split_once(" = ") {
            let v = match col {
                "axle" => &r.axle,
                "wheel" => &r.wheel,
                "track" => &r.track,
                "event" => &r.event,
                "compound" => &r.compound,
                _ => &r.car,
            };
            v == level
        } else if let Some((col, rest)) = p.split_once(" in Q") {
            let inner = rest
                .split_once('[')
                .map(|x| x.1.trim_end_matches(']'))
                .unwrap_or("");
            let (lo, hi) = inner.split_once(", ").unwrap_or(("nan", "nan"));
            let (lo, hi): (f64, f64) = (
                lo.parse().unwrap_or(f64::NAN),
                hi.parse().unwrap_or(f64::NAN),
            );
            r.number(col)
                .is_some_and(|x| x >= lo - 1e-4 && x <= hi + 1e-4)
        } else {
            false
        }
    };
    rows.iter()
        .map(|r| name.split(" & ").all(|p| part(p, r)))
        .collect()
}

/// The diagnosis as Markdown (also what `tirewear gap` prints).
pub fn render_markdown(d: &Diagnosis, max_slices: usize) -> String {
    let mut s = String::from("# Sim-to-real gap\n\n");
    let _ = writeln!(s, "Baseline: {}", d.baseline);
    if let Some(p) = &d.physics {
        let ks: Vec<String> = p
            .k_pct_per_mj
            .iter()
            .map(|(c, k)| format!("{c} {k:.4}"))
            .collect();
        let _ = writeln!(
            s,
            "Calibrated on the training events: k (%/MJ) {}; β = {:.3} /K",
            ks.join(", "),
            p.beta_per_k
        );
    }
    let _ = writeln!(
        s,
        "\n| events | n | bias (%) | RMSE (%) |\n|---|---|---|---|"
    );
    let _ = writeln!(
        s,
        "| training | {} | {:+.3} | {:.3} |",
        d.training.n, d.training.bias_pct, d.training.rmse_pct
    );
    if let Some(t) = &d.testing {
        let _ = writeln!(
            s,
            "| testing ({}) | {} | {:+.3} | {:.3} |",
            d.testing_events.join(", "),
            t.n,
            t.bias_pct,
            t.rmse_pct
        );
    }
    let _ = writeln!(
        s,
        "\n## Where the gap lies\n\n{} distinct slices tested (singly and in pairs, against the rest, Welch's t); {} survive Benjamini–Hochberg at FDR {}. Ranked by the part of the squared gap their offset accounts for (n·mean²/Σr²).\n",
        d.slices_tested,
        d.slices.len(),
        d.fdr
    );
    if !d.slices.is_empty() {
        let _ = writeln!(
            s,
            "| slice | n | mean residual (%) | vs rest (95 % CI) | effect size | p adj. | gap² accounted for | gap² held |\n|---|---|---|---|---|---|---|---|"
        );
        for t in d.slices.iter().take(max_slices) {
            let _ = writeln!(
                s,
                "| {}{} | {} | {:+.2} | {:+.2} [{:+.2}, {:+.2}] | {:+.2} | {:.1e} | {:.1} % | {:.1} % |",
                t.name,
                if t.aliases.is_empty() {
                    String::new()
                } else {
                    format!(" (same rows as {} more)", t.aliases.len())
                },
                t.n,
                t.mean_residual_pct,
                t.difference_pct,
                t.ci_pct.0,
                t.ci_pct.1,
                t.effect_size,
                t.p_adjusted,
                100.0 * t.explained_share,
                100.0 * t.share_of_squared_gap
            );
        }
        if d.slices.len() > max_slices {
            let _ = writeln!(
                s,
                "\n… and {} more (gap.json has them all).",
                d.slices.len() - max_slices
            );
        }
    }
    if !d.candidates.is_empty() {
        let _ = writeln!(
            s,
            "\n## Which unmodelled effect\n\nEach candidate fitted as residual ≈ a + c·feature on the training events, its threshold scanned inside leave-one-event-out cross-validation; gain = 1 − held-out SSE / held-out SSE of the intercept alone; p from a one-sided t-test of the per-event gains, Benjamini–Hochberg over {} candidates.\n\n| candidate | threshold | coefficient | CV gain | p adj. |\n|---|---|---|---|---|",
            d.candidates.len()
        );
        for c in d.candidates.iter().take(max_slices.min(10)) {
            let _ = writeln!(
                s,
                "| {} | {:.3} | {:+.4} | {:+.3} | {:.1e} |",
                c.name, c.threshold, c.coefficient, c.cv_gain, c.p_adjusted
            );
        }
        let _ = writeln!(
            s,
            "\n## How far the gap shrinks\n\n| step | training bias / RMSE (%) | testing bias / RMSE (%) | RMSE in the top flagged slices (%) |\n|---|---|---|---|"
        );
        for st in &d.steps {
            let te = st.testing.map_or("–".to_string(), |t| {
                format!("{:+.3} / {:.3}", t.bias_pct, t.rmse_pct)
            });
            let sl: Vec<String> = st
                .slice_rmse_pct
                .iter()
                .map(|v| format!("{v:.2}"))
                .collect();
            let _ = writeln!(
                s,
                "| {} | {:+.3} / {:.3} | {te} | {} |",
                st.added,
                st.training.bias_pct,
                st.training.rmse_pct,
                sl.join(", ")
            );
        }
    }
    s
}
