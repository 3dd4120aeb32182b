//! `tirewear fit`: its arguments and what it runs.

use anyhow::{Context, Result};
use std::path::PathBuf;
use std::time::Instant;
use tirewear::model::fit::{self, FitSettings, Method};
use tirewear::model::saved::SavedModel;

#[derive(clap::Args)]
pub(crate) struct FitArgs {
    /// KPI database (Parquet, as written by `tirewear extract`).
    kpis: PathBuf,
    /// Method(s) to fit.
    #[arg(long, value_enum, default_value = "all")]
    method: MethodArg,
    /// Testing events (comma-separated event ids), never seen in training.
    /// Default: every third event in event-id order.
    #[arg(long, value_delimiter = ',')]
    test_events: Option<Vec<String>>,
    /// Folder for the fitted models (METHOD.json) and the summary (fit.json).
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

pub(crate) fn run_fit(
    kpis: &std::path::Path,
    methods: &[Method],
    settings: &FitSettings,
    out: &std::path::Path,
) -> Result<Vec<SavedModel>> {
    let t0 = Instant::now();
    let rows = tirewear::kpi::table::read_parquet(kpis)?;
    let split = fit::split(&rows, settings.test_events.as_deref())
        .with_context(|| format!("splitting {}", kpis.display()))?;
    println!(
        "{}: {} rows; training on {} events ({} rows), testing on {} events ({} rows): {}",
        kpis.display(),
        rows.len(),
        split.train_events.len(),
        split.train.len(),
        split.test_events.len(),
        split.test.len(),
        split.test_events.join(", ")
    );
    let mut models = Vec::new();
    // The rows each method leaves out; listed again only where they differ.
    let mut listed: Option<Vec<String>> = None;
    for &m in methods {
        let t = Instant::now();
        let (model, notes) = fit::fit_method(m, &split, settings)
            .with_context(|| format!("fitting the {m:?} model on {}", kpis.display()))?;
        if listed.as_ref() == Some(&notes) {
            if !notes.is_empty() {
                println!("left out: the same {} rows as above", notes.len());
            }
        } else {
            for n in notes.iter().take(5) {
                println!("left out: {n}");
            }
            match notes.len().saturating_sub(5) {
                0 => {}
                1 => println!("... and 1 more row left out"),
                more => println!("... and {more} more rows left out"),
            }
            listed = Some(notes);
        }
        println!(
            "\n{}  ({:.1} s)",
            fit::render_table(&model),
            t.elapsed().as_secs_f64()
        );
        models.push(model);
    }
    let paths = tirewear::model::saved::save_all(&models, out)
        .with_context(|| format!("writing models to {}", out.display()))?;
    if models.len() > 1 {
        println!("{}", fit::render_comparison(&models));
    }
    for p in paths {
        println!("wrote {}", p.display());
    }
    println!("fitted in {:.1} s", t0.elapsed().as_secs_f64());
    Ok(models)
}

/// Runs `tirewear fit`.
pub(crate) fn run(a: FitArgs) -> Result<()> {
    let methods = match a.method {
        MethodArg::Ffnn => vec![Method::Ffnn],
        MethodArg::Pca => vec![Method::Pca],
        MethodArg::Physical => vec![Method::Physical],
        MethodArg::All => Method::ALL.to_vec(),
    };
    let settings = FitSettings {
        test_events: a.test_events,
        network: tirewear::model::network::NetworkSettings {
            seed: a.seed,
            ..Default::default()
        },
        ..Default::default()
    };
    run_fit(&a.kpis, &methods, &settings, &a.out)?;
    Ok(())
}
