//! `tirewear extract`: its arguments and what it runs.

use anyhow::{Context, Result};
use std::path::PathBuf;

#[derive(clap::Args)]
pub(crate) struct ExtractArgs {
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
    /// Worker threads, 1 to 1024 (default: all cores).
    #[arg(long, value_parser = super::parse_jobs)]
    jobs: Option<usize>,
    /// Accept manifest paths outside the archive folder (absolute, or with
    /// '..'). Off by default, so an archive from elsewhere cannot make
    /// tirewear read arbitrary files.
    #[arg(long)]
    allow_external_paths: bool,
    /// How much memory the runs decoded at once may need together:
    /// `auto` (three quarters of the memory available at start: the
    /// system's MemAvailable or the control group's limit, whichever is
    /// smaller) or a size such as 8G or 512M. Runs start while their
    /// estimated needs fit; a run that alone needs more is skipped, naming
    /// its file (docs/reliability.md, "Memory").
    #[arg(long, value_name = "SIZE", default_value = "auto", value_parser = super::parse_memory_limit)]
    memory_limit: tirewear::memory::MemoryLimit,
}

/// `--engine` of `extract`: the library's `kpi::Engine`.
#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum EngineArg {
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

pub(crate) fn run_extract(
    opts: &tirewear::kpi::ExtractOptions,
) -> Result<tirewear::kpi::ExtractSummary> {
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
    let run_time = s.decode_seconds + s.reduce_seconds;
    // With every run skipped there is no telemetry rate to give.
    if s.telemetry_samples > 0 && run_time > 0.0 {
        println!(
            "telemetry: {:.2} M samples/s, {:.0} MB/s of MCAP ({:.0} MB/s per core); {:.0} % of run time decoding, {:.0} % cleaning, {:.0} % reducing",
            s.samples_per_second() / 1e6,
            s.telemetry_bytes as f64 / 1e6 / s.seconds,
            s.telemetry_bytes as f64 / 1e6 / s.seconds / threads,
            100.0 * s.decode_seconds / run_time,
            100.0 * s.prepare_seconds / run_time,
            100.0 * (s.reduce_seconds - s.prepare_seconds) / run_time
        );
    }
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

/// Runs `tirewear extract`; the summary says which runs were skipped.
pub(crate) fn run(a: ExtractArgs, progress: bool) -> Result<tirewear::kpi::ExtractSummary> {
    if let Some(j) = a.jobs {
        rayon::ThreadPoolBuilder::new()
            .num_threads(j)
            .build_global()?;
    }
    run_extract(&tirewear::kpi::ExtractOptions {
        season: a.season,
        out: a.out,
        csv: a.csv,
        engine: a.engine.into(),
        progress,
        allow_external_paths: a.allow_external_paths,
        pipeline: true,
        memory_limit: a.memory_limit,
    })
}
