//! The `tirewear` command line.

mod cli;

use anyhow::Result;
use clap::{Parser, Subcommand};

/// Motorsport tire-wear analytics: season archives in, wear models and
/// sim-to-real gap diagnosis out.
///
/// A season archive is a folder with `season.toml`, MCAP telemetry per run,
/// road texture profiles, compound master curves and tread-depth readings
/// (see docs/formats.md). `tirewear simulate` writes one with known physics.
#[derive(Parser)]
#[command(
    name = "tirewear",
    version,
    about,
    long_about,
    after_help = "Exit codes: 0 done; 1 an error stopped the command (it names the file, \
record and what was wrong); 2 bad command line; 3 extract wrote its outputs but skipped \
some runs (listed, and in NAME.report.json), import imported some logs but not all (listed; none imported is exit 1), \
fit wrote some models but not all (the others named), report wrote the page without \
inputs it could not read (named), or process committed all runs but some that \
failed (listed, and in DATASET/summary.json) or a --then step failed (named); 4 process found the dataset locked by another \
process; 101 internal error (a bug, please report). \
See docs/reliability.md."
)]
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
#[allow(clippy::large_enum_variant)] // parsed once; boxing would only obscure the CLI
enum Command {
    /// Simulate a season with known physics and planted effects.
    ///
    /// Simulate a whole season (telemetry, road profiles, compounds, wear
    /// readings) with known physics and optionally planted effects; the
    /// ground truth goes to `OUT/truth/`.
    Simulate(cli::simulate::SimulateArgs),
    /// Extract the KPI database (one row per tire and run) from a season.
    ///
    /// Extract the KPI database from a season archive: one row per tire and
    /// run with the paper's road (table 3), telemetry (table 4) and
    /// viscoelastic (table 5) indices and the mean wear; side tables of road
    /// spectra and friction-energy maps; a report of skipped runs.
    Extract(cli::extract::ExtractArgs),
    /// Nightly: bring a KPI dataset up to date, incremental and resumable.
    ///
    /// Bring a KPI dataset up to date with season archives, every night:
    /// only runs whose inputs changed are processed (content-hash keys), a
    /// killed run resumes where it stopped, outputs are committed together,
    /// and `--shard K/N` + `--commit` spread the work over machines
    /// (Slurm, Kubernetes; docs/nightly.md). Exit 3: some runs failed, the
    /// rest committed (a failed run keeps its rows from an earlier commit,
    /// and is tried again), or a `--then` step failed (the others still
    /// ran; a step not done runs again the next night); exit 4: another
    /// process holds the dataset.
    Process(cli::process::ProcessArgs),
    /// Import logger data (MoTeC, CSV, Parquet) into a season archive.
    ///
    /// Import real logger data into a season archive: MoTeC `.ld`, MoTeC
    /// CSV exports, generic CSV or Parquet with a time column. Channels are
    /// named through a channel map (a shipped default knows MoTeC, ACC and
    /// iRacing spellings), put on one time base, and what loggers do not
    /// record (wheel loads, forces, wheel-centre and sliding velocities) is
    /// estimated from a vehicle description (car.toml) and marked as
    /// estimated (docs/import.md). Exit 3: some logs failed, the rest were
    /// imported; exit 1: every log failed (the archive is as it was).
    Import(cli::import::ImportArgs),
    /// Fit the three wear models on a KPI database.
    ///
    /// Fit wear models on a KPI database: the feed-forward network (LM),
    /// PCA + regression and the physical correlations + regression per axle,
    /// trained on some events and tested on others. Prints the paper's
    /// performance tables and writes each model as JSON (OUT/METHOD.json).
    /// A method that fails does not stop the others: exit 3 when some
    /// models were written and others not (named), 1 when none was.
    Fit(cli::fit::FitArgs),
    /// Predict wear with a saved model.
    ///
    /// Apply a saved model to a KPI database; refuses a table whose columns
    /// or units differ from the model's, naming them.
    Predict(cli::predict::PredictArgs),
    /// Diagnose the sim-to-real gap: where, which effect, how far it shrinks.
    ///
    /// Diagnose the sim-to-real gap. Calibrates the physics baseline (the
    /// frictional-energy wear law per compound and axle, with the rubber's
    /// temperature factor over the energy map and the road's skewness) on the
    /// training events, or takes a saved model or a CSV of predicted wear
    /// from your own simulation; then (1) where the gap lies: bias and RMSE
    /// on training and testing events and slices of the residual with
    /// false-discovery control; (2) which unmodelled effect explains it:
    /// energy above, below or between thresholds of every per-sample
    /// condition and pair of the condition maps (slip, sliding speed, load,
    /// temperatures and their rates, pressure, camber, speed,
    /// accelerations…) on each axle and wheel, the named mechanisms
    /// (graining, blistering, thermal degradation, fast sliding, road
    /// abrasion), set-up effects of a car, axle or wheel that no telemetry
    /// shows, every unused KPI and your own `--effects`, scored by
    /// track-grouped cross-validation and a permutation test with false
    /// discoveries controlled over the whole family; (3) how far it shrinks
    /// as significant terms are added in turn, the physics law calibrated
    /// again around them. Writes OUT/gap.json and OUT/gap.md, which open
    /// with the findings in words and units. `tirewear gap validate` proves
    /// it on seasons with planted effects, including randomly generated
    /// ones.
    #[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
    Gap(cli::gap::GapArgs),
    /// Measure the engines, decoding against zstd, the diagnosis's and the fit's time.
    ///
    /// Measure the engines: each kernel on the CPU (1 thread, all threads) and
    /// the GPU (upload, compute, readback), against a plain memory pass over
    /// the same buffer; decoding against zstd alone; the gap diagnosis
    /// against its 10 s target; the network's Levenberg–Marquardt step in
    /// both spaces. Prints a table and saves it as JSON; run it on two
    /// machines to compare them.
    Bench(cli::bench::BenchArgs),
    /// Write the season's HTML report (one offline page).
    ///
    /// Write DIR/report.html: one self-contained page (inline SVG figures,
    /// nothing fetched) with the season, the physical correlations (wear
    /// against friction energy per track), the models' predictions against
    /// the measurements and the sim-to-real gap, from what `extract`, `fit`
    /// and `gap` wrote in the season folder (docs/report.md). Only
    /// `kpis.parquet` is required: a model, side table, gap or extraction
    /// report that exists but cannot be read is named at the top of the
    /// page and left out (exit 3), not the whole report.
    Report(cli::report::ReportArgs),
    /// Try tirewear: simulate, extract, fit, diagnose and report the demo season.
    ///
    /// Try tirewear: simulate the demo season, extract its KPI database, fit
    /// the three wear models and diagnose the gap between the physics law and
    /// the measured wear. The default season has no planted effect; plant one
    /// (`--effect graining=1`) to see the diagnosis find it without reading
    /// the truth, then compare with demo-season/truth/wear_truth.csv.
    Demo(cli::demo::DemoArgs),
}

/// Exit codes (docs/reliability.md): 0 done; 1 an error stopped the command
/// (the message names the file, record and what was wrong); 2 the command
/// line is wrong (clap); 3 `extract` wrote its outputs but skipped some runs
/// (listed, and in the report), or `process` committed all but some failed
/// runs; 4 `process` found the dataset locked; 101 an internal error (a bug:
/// please report).
const EXIT_RUNS_SKIPPED: u8 = 3;
const EXIT_LOCKED: u8 = 4;

fn main() -> std::process::ExitCode {
    match std::panic::catch_unwind(run) {
        Ok(Ok(code)) => code,
        Ok(Err(e)) => {
            eprintln!("Error: {e:?}");
            std::process::ExitCode::FAILURE
        }
        // A bug: what the panic hook held back is printed, and the
        // process ends as a panic does (exit 101).
        Err(panic) => {
            tirewear::print_held_panics();
            std::panic::resume_unwind(panic)
        }
    }
}

fn run() -> Result<std::process::ExitCode> {
    let cli = Cli::parse();
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(&cli.log));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .init();
    tirewear::quiet_caught_panics();
    // Before any thread starts (rayon's pool, the engines).
    cli::allocator::tune();
    cli::device_select::quiet();
    let progress = !cli.quiet && std::io::IsTerminal::is_terminal(&std::io::stderr());
    match cli.command {
        Command::Simulate(a) => cli::simulate::run(a, progress)?,
        Command::Extract(a) => {
            if !cli::extract::run(a, progress)?.skipped.is_empty() {
                return Ok(std::process::ExitCode::from(EXIT_RUNS_SKIPPED));
            }
        }
        Command::Process(a) => match cli::process::run(a, progress)? {
            cli::process::Outcome::Done => {}
            cli::process::Outcome::SomeFailed => {
                return Ok(std::process::ExitCode::from(EXIT_RUNS_SKIPPED));
            }
            cli::process::Outcome::Locked => return Ok(std::process::ExitCode::from(EXIT_LOCKED)),
        },
        Command::Import(a) => {
            if !cli::import::run(a)? {
                return Ok(std::process::ExitCode::from(EXIT_RUNS_SKIPPED));
            }
        }
        Command::Fit(a) => {
            if !cli::fit::run(a, progress)? {
                return Ok(std::process::ExitCode::from(EXIT_RUNS_SKIPPED));
            }
        }
        Command::Predict(a) => cli::predict::run(a)?,
        Command::Gap(a) => cli::gap::run(a, progress)?,
        Command::Bench(a) => cli::bench::run(a)?,
        Command::Report(a) => {
            if !cli::report::run(a)? {
                return Ok(std::process::ExitCode::from(EXIT_RUNS_SKIPPED));
            }
        }
        Command::Demo(a) => cli::demo::run(a, progress)?,
    }
    Ok(std::process::ExitCode::SUCCESS)
}
