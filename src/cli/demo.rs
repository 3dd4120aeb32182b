//! `tirewear demo`: its arguments and what it runs.

use super::extract::run_extract;
use super::fit::run_fit;
use super::gap::run_gap;
use super::report::run_report;
use super::simulate::{parse_effects, run_simulation};
use anyhow::Result;
use std::path::PathBuf;
use tirewear::ingest::telemetry::Encoding;
use tirewear::model::fit::{FitSettings, Method};
use tirewear::sim::{Preset, SimOptions};

#[derive(clap::Args)]
pub(crate) struct DemoArgs {
    /// Where to write the demo season.
    #[arg(long, default_value = "demo-season")]
    out: PathBuf,
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Planted effect, repeatable, as for `tirewear simulate --effect`:
    /// NAME[=MAGNITUDE][,threshold=T][,width=W], NAME one of graining,
    /// blistering, thermal, road-abrasion.
    #[arg(long = "effect", value_name = "SPEC")]
    effects: Vec<String>,
}

/// Runs `tirewear demo`.
pub(crate) fn run(a: DemoArgs, progress: bool) -> Result<()> {
    let DemoArgs { out, seed, effects } = a;
    let opts = SimOptions {
        preset: Preset::Demo,
        scale: 1.0,
        tracks: None,
        seed,
        effects: parse_effects(&effects)?,
        generated: None,
        scatter: tirewear::sim::WearScatter::NONE,
        encoding: Encoding::Block,
        rate_hz: None,
        out: out.clone(),
        sensor_noise: true,
        logger_export: None,
        progress,
    };
    let s = run_simulation(&opts)?;
    println!("\nThe demo season in {}:", s.out.display());
    println!("  season.toml             manifest: events, tracks, cars, runs, file paths");
    println!(
        "  telemetry/*.mcap        one MCAP per run: /tire/FL|FR|RL|RR and /vehicle (protobuf)"
    );
    println!("  road/profiles.parquet   road texture profiles (plus one CSV per track in road/)");
    println!("  compounds/*.toml        E' and tan δ master curves with WLF constants");
    println!("  wear/readings.csv       tread depth per spot, several readings per spot");
    println!("  truth/                  the simulator's ground truth (never read by the analysis)");
    println!();
    run_extract(&tirewear::kpi::ExtractOptions {
        season: out.clone(),
        out: out.join("kpis.parquet"),
        csv: Some(out.join("kpis.csv")),
        engine: tirewear::kpi::Engine::Auto,
        progress,
        allow_external_paths: false,
        pipeline: true,
        memory_limit: tirewear::memory::MemoryLimit::Auto,
    })?;
    println!();
    run_fit(
        &out.join("kpis.parquet"),
        &Method::ALL,
        &FitSettings {
            progress,
            ..Default::default()
        },
        &out.join("models"),
    )?;
    println!();
    let settings = tirewear::gap::report::GapSettings {
        wlf: tirewear::ingest::compound::read_wlf(&out.join("compounds"))?,
        ..Default::default()
    };
    run_gap(
        &out.join("kpis.parquet"),
        "physics",
        &settings,
        &out.join("gap"),
    )?;
    println!();
    run_report(&out, &out.join("report.html"), &[])?;
    Ok(())
}
