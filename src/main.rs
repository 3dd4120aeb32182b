//! The `tirewear` command line.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::time::Instant;
use tirewear::ingest::telemetry::Encoding;
use tirewear::model::fit::{self, FitSettings, Method};
use tirewear::model::saved::SavedModel;
use tirewear::sim::{self, Effect, Preset, SimOptions};

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
some runs (listed, and in NAME.report.json); 101 internal error (a bug, please report). \
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
    /// Simulate a whole season (telemetry, road profiles, compounds, wear
    /// readings) with known physics and optionally planted effects; the
    /// ground truth goes to `OUT/truth/`.
    Simulate(SimulateArgs),
    /// Extract the KPI database from a season archive: one row per tire and
    /// run with the paper's road (table 3), telemetry (table 4) and
    /// viscoelastic (table 5) indices and the mean wear; side tables of road
    /// spectra and friction-energy maps; a report of skipped runs.
    Extract(ExtractArgs),
    /// Fit wear models on a KPI database: the feed-forward network (LM),
    /// PCA + regression and the physical correlations + regression per axle,
    /// trained on some events and tested on others. Prints the paper's
    /// performance tables and writes each model as JSON (OUT/METHOD.json).
    Fit(FitArgs),
    /// Apply a saved model to a KPI database; refuses a table whose columns
    /// or units differ from the model's, naming them.
    Predict {
        /// Model written by `tirewear fit` (e.g. models/physical.json).
        model: PathBuf,
        /// KPI database (Parquet, as written by `tirewear extract`).
        kpis: PathBuf,
        /// Predictions to write (CSV: event, track, car, run, wheel, axle,
        /// compound, measured and predicted mean wear in %).
        #[arg(long, default_value = "predictions.csv")]
        out: PathBuf,
    },
    /// Diagnose the sim-to-real gap. Calibrates the physics baseline (the
    /// frictional-energy wear law per compound and axle, with the rubber's
    /// temperature factor over the energy map and the road's skewness) on the
    /// training events, or takes a saved model; then (1) where the gap lies:
    /// bias and RMSE on training and testing events and slices of the
    /// residual with false-discovery control; (2) which unmodelled effect
    /// explains it: candidate mechanisms (graining, blistering, thermal
    /// degradation, fast sliding, road abrasion, every unused KPI) scored by
    /// track-grouped cross-validation and a permutation test; (3) how far it
    /// shrinks as significant terms are added in turn, the physics law
    /// calibrated again around them. Writes OUT/gap.json
    /// and OUT/gap.md. `tirewear gap validate` proves it on seasons with
    /// planted effects.
    #[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
    Gap {
        #[command(subcommand)]
        action: Option<GapAction>,
        /// KPI database (Parquet, as written by `tirewear extract`); its
        /// energy maps are read from NAME.energy_maps.parquet beside it.
        #[arg(required = true)]
        kpis: Option<PathBuf>,
        /// `physics`, a model file written by `tirewear fit`, or a CSV of
        /// predicted wear from any simulation (columns `run`, `wheel`,
        /// `predicted_wear_pct`; `tirewear predict` writes one): the "sim"
        /// side of the gap can be the team's own tool.
        #[arg(long, default_value = "physics")]
        baseline: String,
        /// Testing events (comma-separated); default every third event.
        #[arg(long, value_delimiter = ',')]
        test_events: Option<Vec<String>>,
        /// Folder of compound files (TOML) whose WLF constants give the
        /// physics baseline its temperature factor; default `compounds/`
        /// beside the KPI file when it exists, else the exponential approximation.
        #[arg(long)]
        compounds: Option<PathBuf>,
        /// Your own hypotheses (TOML): named expressions over the energy-map
        /// bins and the KPIs, scored beside the built-in candidates (format:
        /// docs/gap.md).
        #[arg(long)]
        effects: Option<PathBuf>,
        #[command(flatten)]
        stats: GapStatsArgs,
        #[arg(long, default_value = "gap")]
        out: PathBuf,
    },
    /// Measure the engines: each kernel on the CPU (1 thread, all threads) and
    /// the GPU (upload, compute, readback), against a plain memory pass over
    /// the same buffer. Prints a table and saves it as JSON; run it on two
    /// machines to compare them.
    Bench {
        /// Engines to measure: cpu, gpu, or all.
        #[arg(long, value_enum, default_value = "all")]
        engine: BenchEngine,
        /// Small sizes (a quick check that everything runs).
        #[arg(long)]
        small: bool,
        /// Repeats per measurement (the best is kept).
        #[arg(long, default_value_t = 3)]
        repeats: usize,
        /// Where to save the results.
        #[arg(long, default_value = "bench.json")]
        out: PathBuf,
    },
    /// Try tirewear: simulate the demo season, extract its KPI database, fit
    /// the three wear models and diagnose the gap between the physics law and
    /// the measured wear. The default season has no planted effect; plant one
    /// (`--effect graining=1`) to see the diagnosis find it without reading
    /// the truth, then compare with demo-season/truth/wear_truth.csv.
    Demo {
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
    engine: EngineArg,
    /// Worker threads (default: all cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// Accept manifest paths outside the archive folder (absolute, or with
    /// '..'). Off by default, so an archive from elsewhere cannot make
    /// tirewear read arbitrary files.
    #[arg(long)]
    allow_external_paths: bool,
}

#[derive(clap::Args)]
struct FitArgs {
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

/// Statistics settings shared by `gap` and `gap validate`.
#[derive(clap::Args)]
struct GapStatsArgs {
    /// Error rate of the tests: the false-discovery rate of the slices
    /// (Benjamini-Hochberg), the family-wise rate of the candidates (the
    /// permutation max-statistic over all of them; road terms:
    /// Benjamini-Hochberg among themselves).
    #[arg(long, default_value_t = 0.05)]
    fdr: f64,
    /// Permutations of each candidate's significance test.
    #[arg(long, default_value_t = 1999)]
    permutations: usize,
    /// Seed of the permutations (the same seed gives the same p-values).
    #[arg(long, default_value_t = 2026)]
    perm_seed: u64,
    /// Most terms forward selection adds.
    #[arg(long, default_value_t = 4)]
    max_terms: usize,
}

impl GapStatsArgs {
    fn settings(&self, test_events: Option<Vec<String>>) -> tirewear::gap::report::GapSettings {
        tirewear::gap::report::GapSettings {
            test_events,
            fdr: self.fdr,
            scoring: tirewear::gap::scoring::ScoringSettings {
                permutations: self.permutations,
                seed: self.perm_seed,
            },
            max_terms: self.max_terms,
            wlf: Default::default(),
            user_effects: Vec::new(),
        }
    }
}

#[derive(Subcommand)]
enum GapAction {
    /// Prove the diagnosis on seasons with withheld effects: simulate
    /// seasons with each planted effect (magnitudes × seeds, thresholds off
    /// the defaults) and clean ones, extract and diagnose each with the
    /// physics baseline (the diagnosis never reads truth/), then score hit
    /// rate, shrinkage against the ideal and false discoveries. Writes
    /// OUT/validate.json and OUT/validate.md. The defaults run the matrix
    /// of docs/gap.md (68 seasons, about 7 minutes on 2 cores).
    Validate {
        /// Effects to plant (comma-separated; `none` for none).
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "graining,blistering,thermal,road-abrasion"
        )]
        effects: Vec<String>,
        /// Magnitudes of each planted effect (abrasion per joule relative to base wear where it acts).
        #[arg(long, value_delimiter = ',', default_value = "0.5,1,2,4")]
        magnitudes: Vec<f64>,
        /// Seeds of the planted seasons.
        #[arg(long, value_delimiter = ',', default_value = "1,2,3")]
        seeds: Vec<u64>,
        /// Seeds of the clean seasons (`--clean-seeds` alone: none).
        #[arg(
            long,
            num_args = 0..,
            value_delimiter = ',',
            default_value = "1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16,17,18,19,20"
        )]
        clean_seeds: Vec<u64>,
        /// Seasons with a randomly generated effect each (docs/gap.md,
        /// "Generated effects"): a condition, pair, band, power law or set-up
        /// factor on a random scope with 5-40 % of the wear variance, drawn
        /// from seeds RANDOM_FROM, RANDOM_FROM+1, ... A hit is a diagnosis
        /// whose terms' wear correlates >= 0.8 with the planted wear.
        #[arg(long, default_value_t = 0)]
        random: u64,
        /// First seed of the generated effects (docs/gap.md keeps the seeds
        /// the development looked at apart from the held-out ones).
        #[arg(long, default_value_t = 1)]
        random_from: u64,
        /// Season preset of the simulated seasons. `season` at scale 0.5 has
        /// 12 events on 12 tracks: a track-level effect such as road abrasion
        /// needs the tracks (the demo's 6 training tracks leave its test 3
        /// degrees of freedom).
        #[arg(long, value_enum, default_value = "season")]
        preset: PresetArg,
        /// Multiplies the number of events of the `season` preset (0.5: one
        /// event per track).
        #[arg(long, default_value_t = 0.5)]
        scale: f64,
        /// Telemetry rate of the simulated seasons (Hz).
        #[arg(long, default_value_t = 5.0)]
        rate: f64,
        /// Scratch folder for the seasons (default: OUT/seasons).
        #[arg(long)]
        work: Option<PathBuf>,
        /// Keep each season's files.
        #[arg(long)]
        keep: bool,
        #[command(flatten)]
        stats: GapStatsArgs,
        #[arg(long, default_value = "gap-validate")]
        out: PathBuf,
    },
}

#[derive(Clone, Copy, PartialEq, clap::ValueEnum)]
enum BenchEngine {
    Cpu,
    Gpu,
    All,
}

/// `--preset`: the library's `sim::Preset` (the library knows nothing of clap).
#[derive(Clone, Copy, clap::ValueEnum)]
enum PresetArg {
    /// 2 tracks, 2 events, 1 car, 2 short runs each: for tests and quick checks.
    Tiny,
    /// 8 tracks, 10 events, 2 cars, 320 tire-runs at 20 Hz: under a minute.
    Demo,
    /// 12 tracks, 24 events × scale, 3 cars, 6 runs each at 200 Hz: ~20 GB at scale 1.
    Season,
}

impl From<PresetArg> for Preset {
    fn from(p: PresetArg) -> Preset {
        match p {
            PresetArg::Tiny => Preset::Tiny,
            PresetArg::Demo => Preset::Demo,
            PresetArg::Season => Preset::Season,
        }
    }
}

/// `--engine` of `extract`: the library's `kpi::Engine`.
#[derive(Clone, Copy, clap::ValueEnum)]
enum EngineArg {
    Cpu,
    Gpu,
    /// The GPU when one is usable, else the CPU (with a message saying so).
    Auto,
}

impl From<EngineArg> for tirewear::kpi::Engine {
    fn from(e: EngineArg) -> Self {
        match e {
            EngineArg::Cpu => Self::Cpu,
            EngineArg::Gpu => Self::Gpu,
            EngineArg::Auto => Self::Auto,
        }
    }
}

/// `--encoding` of `simulate`: the library's `Encoding`.
#[derive(Clone, Copy, clap::ValueEnum)]
enum EncodingArg {
    /// One message per sample per topic (`TireSample`, `VehicleSample`).
    Sample,
    /// Packed blocks of equally spaced samples (`TireBlock`, `VehicleBlock`).
    Block,
}

impl From<EncodingArg> for Encoding {
    fn from(e: EncodingArg) -> Encoding {
        match e {
            EncodingArg::Sample => Encoding::Sample,
            EncodingArg::Block => Encoding::Block,
        }
    }
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum MethodArg {
    Ffnn,
    Pca,
    Physical,
    All,
}

#[derive(clap::Args)]
struct SimulateArgs {
    /// Season preset.
    #[arg(long, value_enum, default_value = "demo")]
    preset: PresetArg,
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
    /// Plant a randomly generated effect drawn from SEED (docs/gap.md,
    /// "Generated effects"): a condition, pair of conditions, band, power law
    /// or set-up factor the gap diagnosis was not written for, on a random
    /// scope, with 5-40 % of the wear's variance. truth/settings.toml
    /// describes it; truth/wear_truth.csv has its wear per tire.
    #[arg(long, value_name = "SEED")]
    random_effect: Option<u64>,
    /// Telemetry message form: per-sample messages (Foxglove-friendly) or packed blocks (fast).
    #[arg(long, value_enum, default_value = "block")]
    encoding: EncodingArg,
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
    println!("engine device: {}", s.device);
    if let Some(t) = s.gpu_timings {
        println!(
            "GPU time: upload {:.0} ms, compute {:.0} ms, readback {:.0} ms",
            t.upload.as_secs_f64() * 1e3,
            t.compute.as_secs_f64() * 1e3,
            t.readback.as_secs_f64() * 1e3
        );
    }
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

fn run_fit(
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
    for &m in methods {
        let t = Instant::now();
        let (model, notes) = fit::fit_method(m, &split, settings)
            .with_context(|| format!("fitting the {m:?} model on {}", kpis.display()))?;
        for n in notes.iter().take(5) {
            println!("left out: {n}");
        }
        if notes.len() > 5 {
            println!("... and {} more rows left out", notes.len() - 5);
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

fn run_predict(
    model: &std::path::Path,
    kpis: &std::path::Path,
    out: &std::path::Path,
) -> Result<()> {
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
    let rows = tirewear::kpi::table::read_parquet(kpis)?;
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
            wheel: &r.wheel,
            axle: &r.axle,
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
            "wrote {}: {} predictions ({} model)",
            out.display(),
            out_rows.len(),
            m.method()
        ),
    }
    Ok(())
}

fn run_validate(
    settings: &tirewear::gap::validate::ValidateSettings,
    out: &std::path::Path,
) -> Result<()> {
    let started = std::time::Instant::now();
    let cases = tirewear::gap::validate::validate(settings);
    let table = tirewear::gap::validate::render(&cases);
    println!("{table}");
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    tirewear::atomic::write_bytes(
        &out.join("validate.json"),
        serde_json::to_string_pretty(&cases)?.as_bytes(),
    )?;
    let md = format!(
        "# Gap diagnosis on withheld effects\n\n{} seasons ({:?} preset, scale {}, {} Hz) in {:.0} s.\n\n{table}",
        cases.len(),
        settings.preset,
        settings.scale,
        settings.rate_hz,
        started.elapsed().as_secs_f64()
    );
    tirewear::atomic::write_bytes(&out.join("validate.md"), md.as_bytes())?;
    println!(
        "wrote {} and {}",
        out.join("validate.json").display(),
        out.join("validate.md").display()
    );
    if cases.iter().any(|c| c.error.is_some()) {
        anyhow::bail!("some seasons failed (listed above)");
    }
    Ok(())
}

fn run_gap(
    kpis: &std::path::Path,
    baseline: &str,
    settings: &tirewear::gap::report::GapSettings,
    out: &std::path::Path,
) -> Result<()> {
    use tirewear::gap::report::{Baseline, diagnose, render_markdown};
    let rows = tirewear::kpi::table::read_parquet(kpis)?;
    let base = if baseline == "physics" {
        Baseline::Physics
    } else if baseline.ends_with(".csv") {
        let p = tirewear::gap::report::Predictions::read(std::path::Path::new(baseline))?;
        let missing = rows
            .iter()
            .filter(|r| !p.wear_pct.contains_key(&(r.run.clone(), r.wheel.clone())))
            .count();
        if missing > 0 {
            tracing::warn!(
                "{baseline}: no prediction for {missing} of {} tires; they are left out",
                rows.len()
            );
        }
        Baseline::Predictions(p)
    } else {
        let m = SavedModel::load(std::path::Path::new(baseline))?;
        m.check_columns(&tirewear::kpi::table::read_units(kpis)?)
            .with_context(|| format!("{} against {baseline}", kpis.display()))?;
        Baseline::Model(Box::new(m))
    };
    let stem = kpis.file_stem().and_then(|s| s.to_str()).unwrap_or("kpis");
    let maps_path = kpis.with_file_name(format!("{stem}.energy_maps.parquet"));
    let maps = if maps_path.exists() {
        tirewear::kpi::energy_map::read_tire_maps(kpis)?
    } else {
        tracing::warn!(
            "{} not found: candidate effects and shrinkage are skipped",
            maps_path.display()
        );
        Default::default()
    };
    let d = diagnose(&rows, &maps, &base, settings)
        .with_context(|| format!("diagnosing {}", kpis.display()))?;
    print!("{}", render_markdown(&d, 12));
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    tirewear::atomic::write_bytes(
        &out.join("gap.json"),
        serde_json::to_string_pretty(&d)?.as_bytes(),
    )?;
    tirewear::atomic::write_bytes(
        &out.join("gap.md"),
        render_markdown(&d, usize::MAX).as_bytes(),
    )?;
    println!(
        "\nwrote {} and {}",
        out.join("gap.json").display(),
        out.join("gap.md").display()
    );
    Ok(())
}

/// Exit codes (docs/reliability.md): 0 done; 1 an error stopped the command
/// (the message names the file, record and what was wrong); 2 the command
/// line is wrong (clap); 3 `extract` wrote its outputs but skipped some runs
/// (listed, and in the report); 101 an internal error (a bug: please report).
const EXIT_RUNS_SKIPPED: u8 = 3;

fn main() -> std::process::ExitCode {
    match run() {
        Ok(code) => code,
        Err(e) => {
            eprintln!("Error: {e:?}");
            std::process::ExitCode::FAILURE
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
    let progress = !cli.quiet && std::io::IsTerminal::is_terminal(&std::io::stderr());
    match cli.command {
        Command::Simulate(a) => {
            let opts = SimOptions {
                preset: a.preset.into(),
                scale: a.scale,
                seed: a.seed,
                effects: parse_effects(&a.effects)?,
                generated: a.random_effect.map(tirewear::sim::GeneratedEffect::draw),
                encoding: a.encoding.into(),
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
            let s = run_extract(&tirewear::kpi::ExtractOptions {
                season: a.season,
                out: a.out,
                csv: a.csv,
                engine: a.engine.into(),
                progress,
                allow_external_paths: a.allow_external_paths,
            })?;
            if !s.skipped.is_empty() {
                return Ok(std::process::ExitCode::from(EXIT_RUNS_SKIPPED));
            }
        }
        Command::Fit(a) => {
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
        }
        Command::Predict { model, kpis, out } => run_predict(&model, &kpis, &out)?,
        Command::Gap {
            action:
                Some(GapAction::Validate {
                    effects,
                    magnitudes,
                    seeds,
                    clean_seeds,
                    random,
                    random_from,
                    preset,
                    scale,
                    rate,
                    work,
                    keep,
                    stats,
                    out,
                }),
            ..
        } => {
            let effects = effects
                .iter()
                .filter(|e| e.as_str() != "none")
                .map(|e| {
                    tirewear::sim::EffectKind::ALL
                        .into_iter()
                        .find(|k| k.name() == e)
                        .ok_or_else(|| anyhow::anyhow!("unknown effect '{e}' (graining, blistering, thermal, road-abrasion)"))
                })
                .collect::<Result<Vec<_>>>()?;
            let settings = tirewear::gap::validate::ValidateSettings {
                effects,
                magnitudes,
                seeds,
                clean_seeds,
                random: (random_from..random_from + random).collect(),
                preset: preset.into(),
                scale,
                rate_hz: rate,
                work: work.unwrap_or_else(|| out.join("seasons")),
                keep,
                gap: stats.settings(None),
                progress,
            };
            run_validate(&settings, &out)?;
        }
        Command::Gap {
            kpis,
            baseline,
            test_events,
            compounds,
            effects,
            stats,
            out,
            ..
        } => {
            let kpis = kpis.expect("clap requires it");
            let mut settings = stats.settings(test_events);
            if let Some(f) = &effects {
                settings.user_effects = tirewear::gap::user_effects::load(f)?;
            }
            let dir = compounds.clone().unwrap_or_else(|| {
                kpis.parent()
                    .unwrap_or(std::path::Path::new("."))
                    .join("compounds")
            });
            if compounds.is_some() || dir.is_dir() {
                settings.wlf = tirewear::gap::validate::read_wlf(&dir)
                    .with_context(|| format!("reading compound files in {}", dir.display()))?;
            } else {
                tracing::warn!(
                    "no compounds/ beside {}: the baseline's temperature factor is exponential",
                    kpis.display()
                );
            }
            run_gap(&kpis, &baseline, &settings, &out)?
        }
        Command::Bench {
            engine,
            small,
            repeats,
            out,
        } => {
            let r = tirewear::bench::run_bench(&tirewear::bench::BenchOptions {
                small,
                gpu: engine != BenchEngine::Cpu,
                repeats,
            });
            print!("{}", tirewear::bench::render(&r));
            if engine == BenchEngine::Gpu && r.gpu.is_none() {
                anyhow::bail!("--engine gpu: no GPU adapter could be opened (see the note above)");
            }
            tirewear::atomic::write_bytes(&out, serde_json::to_string_pretty(&r)?.as_bytes())
                .with_context(|| format!("writing {}", out.display()))?;
            println!("wrote {}", out.display());
        }
        Command::Demo { out, seed, effects } => {
            let opts = SimOptions {
                preset: Preset::Demo,
                scale: 1.0,
                seed,
                effects: parse_effects(&effects)?,
                generated: None,
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
                allow_external_paths: false,
            })?;
            println!();
            run_fit(
                &out.join("kpis.parquet"),
                &Method::ALL,
                &FitSettings::default(),
                &out.join("models"),
            )?;
            println!();
            let settings = tirewear::gap::report::GapSettings {
                wlf: tirewear::gap::validate::read_wlf(&out.join("compounds"))?,
                ..Default::default()
            };
            run_gap(
                &out.join("kpis.parquet"),
                "physics",
                &settings,
                &out.join("gap"),
            )?;
        }
    }
    Ok(std::process::ExitCode::SUCCESS)
}
