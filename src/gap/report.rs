//! `tirewear gap`: the baseline, the gap's size on training and testing
//! events, and where it lies; written as JSON and Markdown.

use super::baseline::PhysicsBaseline;
use super::slices::{Slice, slice_residuals};
use crate::kpi::KpiRow;
use crate::model::ModelError;
use crate::model::fit::split;
use crate::model::saved::SavedModel;
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
    Ok(Diagnosis {
        baseline: name,
        physics,
        training_events: s.train_events.clone(),
        testing_events: s.test_events.clone(),
        training: size(&trv),
        testing: (!tev.is_empty()).then(|| size(&tev)),
        fdr,
        slices_tested: count,
        slices: tested.into_iter().filter(|t| t.p_adjusted <= fdr).collect(),
    })
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
    s
}
