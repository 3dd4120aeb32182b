//! `tirewear fit`: its arguments and what it runs.

use anyhow::{Context, Result};
use std::path::PathBuf;
use std::time::Instant;
use tirewear::model::fit::{self, FitSettings, Method};

#[derive(clap::Args)]
pub(crate) struct FitArgs {
    /// KPI database (Parquet, as written by `tirewear extract`).
    kpis: PathBuf,
    /// Method(s) to fit, comma-separated (`--method physical,pca`).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "all")]
    method: Vec<MethodArg>,
    /// Testing events (comma-separated event ids), never seen in training.
    /// Default: every third event in event-id order.
    #[arg(long, value_delimiter = ',')]
    test_events: Option<Vec<String>>,
    /// Folder for the fitted models (METHOD.json).
    #[arg(long, default_value = "models")]
    out: PathBuf,
    /// Seed of the network's initial weights and its training/validation split.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum MethodArg {
    Ffnn,
    Pca,
    Physical,
    All,
}

/// The testing events, or why there are none: a first night's table with
/// two events has no third one to test on, and the models then carry
/// training indicators only.
fn testing_events_said(split: &fit::Split) -> String {
    if split.test_events.is_empty() {
        format!(
            "none: the default tests every third event and the table has {} events \
             (--test-events names testing events); the models have training indicators only",
            split.train_events.len()
        )
    } else {
        split.test_events.join(", ")
    }
}

/// Fits each method and writes the models that fitted, together, into
/// `out`. A method that fails does not stop the others (a singular design
/// for the physical model says nothing of the network); only when none
/// fits is it an error. Returns the methods that failed, with their errors.
pub(crate) fn run_fit(
    kpis: &std::path::Path,
    methods: &[Method],
    settings: &FitSettings,
    out: &std::path::Path,
) -> Result<Vec<(Method, anyhow::Error)>> {
    let t0 = Instant::now();
    super::not_a_file(out, "fit")?;
    let rows = tirewear::kpi::table::read_parquet_rows(kpis)?;
    let split = fit::split(&rows, settings.test_events.as_deref())
        .with_context(|| format!("splitting {}", kpis.display()))?;
    // Before minutes of fitting, not after: an output folder that cannot be made.
    super::output_folder(out, "fit")?;
    println!(
        "{}: {} rows; training on {} events ({} rows), testing on {} events ({} rows): {}",
        kpis.display(),
        rows.len(),
        split.train_events.len(),
        split.train.len(),
        split.test_events.len(),
        split.test.len(),
        testing_events_said(&split)
    );
    let mut models = Vec::new();
    let mut failed = Vec::new();
    // The rows each method leaves out; listed again only where they differ.
    let mut listed: Option<Vec<String>> = None;
    for &m in methods {
        let t = Instant::now();
        let (model, notes) = match fit::fit_method(m, &split, settings) {
            Ok(fitted) => fitted,
            Err(e) => {
                let e = anyhow::Error::new(e)
                    .context(format!("fitting the {m:?} model on {}", kpis.display()));
                println!("\n{m:?} model not fitted: {e:#}");
                tracing::warn!("{e:#}");
                failed.push((m, e));
                continue;
            }
        };
        for line in left_out_lines(listed.as_deref(), &notes) {
            println!("{line}");
        }
        listed = Some(notes);
        println!(
            "\n{}  ({:.1} s)",
            fit::render_table(&model),
            t.elapsed().as_secs_f64()
        );
        models.push(model);
    }
    if models.is_empty() {
        return Err(none_fitted(kpis, failed));
    }
    let paths = tirewear::model::saved::save_all(&models, out)
        .with_context(|| format!("writing models to {}", out.display()))?;
    if models.len() > 1 && !split.test.is_empty() {
        println!("{}", fit::render_comparison(&models));
    }
    for p in paths {
        println!("wrote {}", p.display());
    }
    if !failed.is_empty() {
        let names: Vec<String> = failed.iter().map(|(m, _)| format!("{m:?}")).collect();
        println!(
            "not fitted: {} (above); the other models were written",
            names.join(", ")
        );
    }
    println!("fitted in {:.1} s", t0.elapsed().as_secs_f64());
    Ok(failed)
}

/// The error when no method fitted: one sentence when every method failed
/// for the same reason (a table without wear readings: three copies of
/// one message), else the first error with the others.
fn none_fitted(kpis: &std::path::Path, failed: Vec<(Method, anyhow::Error)>) -> anyhow::Error {
    let causes: Vec<String> = failed
        .iter()
        .map(|(_, e)| e.root_cause().to_string())
        .collect();
    if failed.len() > 1 && causes.iter().all(|c| *c == causes[0]) {
        let names: Vec<String> = failed.iter().map(|(m, _)| format!("{m:?}")).collect();
        return anyhow::anyhow!(
            "{}: no model fitted: every method ({}) failed alike: {}",
            kpis.display(),
            names.join(", "),
            causes[0]
        );
    }
    let mut failed = failed.into_iter();
    let Some((_, first)) = failed.next() else {
        return anyhow::anyhow!("{}: no method to fit", kpis.display());
    };
    let others: Vec<String> = failed.map(|(_, e)| format!("{e:#}")).collect();
    match others.as_slice() {
        [] => first,
        _ => first.context(format!("no model fitted; also: {}", others.join("; "))),
    }
}

/// What `fit` prints of the rows a method leaves out: the first five and
/// how many more, or one line when the method before left out the same.
fn left_out_lines(previous: Option<&[String]>, notes: &[String]) -> Vec<String> {
    if previous == Some(notes) {
        // Each line is a row, a track's rows or an input column.
        return if notes.is_empty() {
            Vec::new()
        } else {
            vec!["left out: the same as above".to_string()]
        };
    }
    let mut lines: Vec<String> = notes
        .iter()
        .take(5)
        .map(|n| format!("left out: {n}"))
        .collect();
    match notes.len().saturating_sub(5) {
        0 => {}
        more => lines.push(format!("... and {more} more left out")),
    }
    lines
}

/// Runs `tirewear fit`; false when some methods fitted and others did not.
pub(crate) fn run(a: FitArgs, progress: bool) -> Result<bool> {
    // In the usual order (network, PCA, physical), each once.
    let methods: Vec<Method> = Method::ALL
        .into_iter()
        .filter(|&m| {
            a.method.iter().any(|&arg| match arg {
                MethodArg::Ffnn => m == Method::Ffnn,
                MethodArg::Pca => m == Method::Pca,
                MethodArg::Physical => m == Method::Physical,
                MethodArg::All => true,
            })
        })
        .collect();
    let settings = FitSettings {
        test_events: a.test_events,
        network: tirewear::model::network::NetworkSettings {
            seed: a.seed,
            ..Default::default()
        },
        progress,
        ..Default::default()
    };
    Ok(run_fit(&a.kpis, &methods, &settings, &a.out)?.is_empty())
}

#[cfg(test)]
mod tests {
    use super::{Method, left_out_lines, none_fitted};

    /// Every method failing for one reason is one sentence; different
    /// reasons keep each method's own error.
    #[test]
    fn methods_failing_alike_are_said_once() {
        let kpis = std::path::Path::new("nw/kpis.parquet");
        let failing = |why: &str| {
            Method::ALL
                .iter()
                .map(|&m| {
                    (
                        m,
                        anyhow::anyhow!("{why}").context(format!("fitting the {m:?} model")),
                    )
                })
                .collect::<Vec<_>>()
        };
        let e = none_fitted(kpis, failing("no usable training rows")).to_string();
        assert_eq!(
            e,
            "nw/kpis.parquet: no model fitted: every method (Ffnn, Pca, Physical) failed \
             alike: no usable training rows"
        );
        let mut mixed = failing("no usable training rows");
        mixed[2].1 = anyhow::anyhow!("singular").context("fitting the Physical model");
        let e = format!("{:#}", none_fitted(kpis, mixed));
        assert!(
            e.starts_with("no model fitted; also: fitting the Pca model: no usable training rows; fitting the Physical model: singular"),
            "{e}"
        );
    }

    #[test]
    fn left_out_rows_are_listed_once_across_methods() {
        let six: Vec<String> = (1..=6).map(|i| format!("row {i}")).collect();
        let first = left_out_lines(None, &six);
        assert_eq!(first.len(), 6);
        assert_eq!(first[0], "left out: row 1");
        assert_eq!(first[5], "... and 1 more left out");
        assert_eq!(
            left_out_lines(Some(&six), &six),
            ["left out: the same as above"]
        );
        // Different rows are listed in full; seven leave "2 more".
        let seven: Vec<String> = (1..=7).map(|i| format!("row {i}")).collect();
        assert_eq!(
            left_out_lines(Some(&six), &seven)[5],
            "... and 2 more left out"
        );
        assert!(left_out_lines(Some(&[]), &[]).is_empty());
        assert!(left_out_lines(None, &[]).is_empty());
    }
}
