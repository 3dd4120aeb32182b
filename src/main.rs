//! The `tirewear` command line.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::time::Instant;
use tirewear::ingest::telemetry::Encoding;
use tirewear::sim::{self, Effect, Preset, SimOptions};

/// Motorsport tire-wear analytics: season archives in, wear models and
/// sim-to-real gap diagnosis out.
///
/// A season archive is a folder with `season.toml`, MCAP telemetry per run,
/// road texture profiles, compound master curves and tread-depth readings
/// (see docs/formats.md). `tirewear simulate` writes one with known physics.
#[derive(Parser)]
#[command(name = "tirewear", version, about, long_about)]
struct Cli {
    /// Log filter (e.g. `info`, `debug`, `tirewear=trace`); RUST_LOG works too.
    #[arg(long, global = true, default_value = "info")]
    log: String,
    /// No progress bars.
    #[arg(long, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a whole season (telemetry, road profiles, compounds, wear
    /// readings) with known physics and optionally planted effects; the
    /// ground truth goes to `OUT/truth/`.
    Simulate(SimulateArgs),
    /// Extract the KPI database from a season archive: one row per tire and
    /// run with the paper's road (table 3), telemetry (table 4) and
    /// viscoelastic (table 5) indices and the mean wear; side tables of road
    /// spectra and friction-energy maps; a report of skipped runs.
    Extract(ExtractArgs),
    /// Try tirewear: simulate the demo season and extract its KPI database.
    Demo {
        /// Where to write the demo season.
        #[arg(long, default_value = "demo-season")]
        out: PathBuf,
        #[arg(long, default_value_t = 7)]
        seed: u64,
    },
}

#[derive(clap::Args)]
struct ExtractArgs {
    /// Season archive folder (with season.toml) or the manifest itself.
    season: PathBuf,
    /// KPI database to write (Parquet); side tables go next to it
    /// (NAME.road.parquet, NAME.energy_maps.parquet, NAME.report.json).
    #[arg(long, default_value = "kpis.parquet")]
    out: PathBuf,
    /// Also write the KPI database as CSV.
    #[arg(long)]
    csv: Option<PathBuf>,
    /// Engine for the heavy reductions: cpu, gpu, or auto (GPU when usable, else CPU).
    #[arg(long, value_enum, default_value = "auto")]
    engine: tirewear::kpi::Engine,
    /// Worker threads (default: all cores).
    #[arg(long)]
    jobs: Option<usize>,
}

#[derive(clap::Args)]
struct SimulateArgs {
    /// Season preset.
    #[arg(long, value_enum, default_value = "demo")]
    preset: Preset,
    /// Multiplies the number of events of the `season` preset (toward full-season archives).
    #[arg(long, default_value_t = 1.0)]
    scale: f64,
    /// Random seed: the same seed gives the same season.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Planted effect, repeatable: NAME[=MAGNITUDE][,threshold=T][,width=W] with NAME one of
    /// graining, blistering, thermal, road-abrasion (or `none`). The magnitude is the effect's
    /// abrasion per joule relative to base wear where it acts (default 0.5). Thresholds are °C
    /// (graining: tread-bulk temperature below; blistering: inner liner above; thermal: surface
    /// above) or mm (road-abrasion: micro-texture rms above).
    #[arg(long = "effect", value_name = "SPEC")]
    effects: Vec<String>,
    /// Telemetry message form: per-sample messages (Foxglove-friendly) or packed blocks (fast).
    #[arg(long, value_enum, default_value = "block")]
    encoding: Encoding,
    /// Telemetry sample rate in Hz (default: 20 for demo, 200 for season; at most 1000).
    #[arg(long)]
    rate: Option<f64>,
    /// Ideal sensors: no measurement noise and no logger dropouts.
    #[arg(long)]
    no_noise: bool,
    /// Output folder (created; files in it are replaced).
    #[arg(long)]
    out: PathBuf,
}

fn parse_effects(specs: &[String]) -> Result<Vec<Effect>> {
    specs
        .iter()
        .filter(|s| s.as_str() != "none")
        .map(|s| {
            s.parse::<Effect>()
                .map_err(|e| anyhow::anyhow!("--effect {s}: {e}"))
        })
        .collect()
}

fn run_simulation(opts: &SimOptions) -> Result<sim::SimSummary> {
    let t0 = Instant::now();
    let s =
        sim::simulate(opts).with_context(|| format!("simulating into {}", opts.out.display()))?;
    println!(
        "wrote {}: {} tracks, {} events, {} runs, {} tire-run observations, {:.1} M telemetry samples, {:.1} MB in {:.1} s",
        s.out.display(),
        s.tracks,
        s.events,
        s.runs,
        s.observations,
        s.samples as f64 / 1e6,
        s.bytes as f64 / 1e6,
        t0.elapsed().as_secs_f64()
    );
    if s.saturated_fraction > 0.0 {
        tracing::debug!(
            "{:.3} % of wheel samples past the tire's force peak",
            100.0 * s.saturated_fraction
        );
    }
    Ok(s)
}

fn run_extract(opts: &tirewear::kpi::ExtractOptions) -> Result<tirewear::kpi::ExtractSummary> {
    let s = tirewear::kpi::extract(opts)
        .with_context(|| format!("extracting {}", opts.season.display()))?;
    println!(
        "wrote {}: {} rows from {} of {} runs in {:.1} s ({:?} engine)",
        opts.out.display(),
        s.rows,
        s.runs - s.skipped.len(),
        s.runs,
        s.seconds,
        s.engine
    );
    let threads = rayon::current_num_threads() as f64;
    println!(
        "telemetry: {:.2} M samples/s, {:.0} MB/s of MCAP ({:.0} MB/s per core); {:.0} % of run time decoding, {:.0} % reducing",
        s.samples_per_second() / 1e6,
        s.telemetry_bytes as f64 / 1e6 / s.seconds,
        s.telemetry_bytes as f64 / 1e6 / s.seconds / threads,
        100.0 * s.decode_seconds / (s.decode_seconds + s.reduce_seconds),
        100.0 * s.reduce_seconds / (s.decode_seconds + s.reduce_seconds)
    );
    for k in &s.skipped {
        println!("skipped run {}: {}", k.run, k.reason);
    }
    for w in s.warnings.iter().take(10) {
        println!("warning: {w}");
    }
    if s.warnings.len() > 10 {
        println!(
            "... and {} more warnings (see the report)",
            s.warnings.len() - 10
        );
    }
    Ok(s)
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(&cli.log));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .init();
    let progress = !cli.quiet && std::io::IsTerminal::is_terminal(&std::io::stderr());
    match cli.command {
        Command::Simulate(a) => {
            let opts = SimOptions {
                preset: a.preset,
                scale: a.scale,
                seed: a.seed,
                effects: parse_effects(&a.effects)?,
                encoding: a.encoding,
                rate_hz: a.rate,
                out: a.out,
                sensor_noise: !a.no_noise,
                progress,
            };
            run_simulation(&opts)?;
        }
        Command::Extract(a) => {
            if let Some(j) = a.jobs {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(j.max(1))
                    .build_global()?;
            }
            run_extract(&tirewear::kpi::ExtractOptions {
                season: a.season,
                out: a.out,
                csv: a.csv,
                engine: a.engine,
                progress,
            })?;
        }
        Command::Demo { out, seed } => {
            let opts = SimOptions {
                preset: Preset::Demo,
                scale: 1.0,
                seed,
                effects: Vec::new(),
                encoding: Encoding::Block,
                rate_hz: None,
                out: out.clone(),
                sensor_noise: true,
                progress,
            };
            let s = run_simulation(&opts)?;
            println!("\nThe demo season in {}:", s.out.display());
            println!("  season.toml             manifest: events, tracks, cars, runs, file paths");
            println!(
                "  telemetry/*.mcap        one MCAP per run: /tire/FL|FR|RL|RR and /vehicle (protobuf)"
            );
            println!(
                "  road/profiles.parquet   road texture profiles (plus one CSV per track in road/)"
            );
            println!("  compounds/*.toml        E' and tan δ master curves with WLF constants");
            println!("  wear/readings.csv       tread depth per spot, several readings per spot");
            println!(
                "  truth/                  the simulator's ground truth (never read by the analysis)"
            );
            println!();
            run_extract(&tirewear::kpi::ExtractOptions {
                season: out.clone(),
                out: out.join("kpis.parquet"),
                csv: Some(out.join("kpis.csv")),
                engine: tirewear::kpi::Engine::Auto,
                progress,
            })?;
            println!("\nNext steps of the pipeline (fit → gap) arrive with their issues.");
        }
    }
    Ok(())
}
