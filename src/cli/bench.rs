//! `tirewear bench`: its arguments and what it runs.

use anyhow::{Context, Result};
use std::path::PathBuf;

#[derive(clap::Args)]
pub(crate) struct BenchArgs {
    /// Engines to measure: cpu, gpu, or all.
    #[arg(long, value_enum, default_value = "all")]
    engine: BenchEngine,
    /// Small sizes (a quick check that everything runs).
    #[arg(long)]
    small: bool,
    /// Repeats per measurement, at least 1 (the best is kept).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..))]
    repeats: u32,
    /// Measure only one part: `kernels` (the engines on synthetic buffers),
    /// `decode` (MCAP decoding against zstd alone on a simulated season),
    /// `gap` (the gap diagnosis of the demo season and of `gap validate`'s
    /// season, against its 10 s target) or `fit` (Levenberg–Marquardt's
    /// step in the residuals' and the parameters' space, and the network
    /// method on the demo's KPI table).
    #[arg(long, value_enum)]
    only: Option<BenchPart>,
    /// Season archive (folder with season.toml) to measure decoding and
    /// extraction on, instead of the simulated demo season in both forms.
    #[arg(long)]
    season: Option<PathBuf>,
    /// Where to save the results.
    #[arg(long, default_value = "bench.json")]
    out: PathBuf,
}

#[derive(Clone, Copy, PartialEq, clap::ValueEnum)]
pub(crate) enum BenchPart {
    Kernels,
    Decode,
    Gap,
    Fit,
}

#[derive(Clone, Copy, PartialEq, clap::ValueEnum)]
pub(crate) enum BenchEngine {
    Cpu,
    Gpu,
    All,
}

/// Runs `tirewear bench`.
pub(crate) fn run(a: BenchArgs) -> Result<()> {
    let BenchArgs {
        engine,
        small,
        repeats,
        only,
        season,
        out,
    } = a;
    use tirewear::bench::BenchParts;
    // A season asked for by name is read, or the command fails: a bench
    // that silently measured something else would mislead the comparison.
    let opened = match &season {
        Some(dir) => Some(
            tirewear::ingest::manifest::Season::open(dir)
                .with_context(|| format!("--season {}", dir.display()))?,
        ),
        None => None,
    };
    // Refused before the minutes of measuring, not after them.
    tirewear::bench::check_output(&out, opened.as_ref())?;
    let r = tirewear::bench::run_bench(&tirewear::bench::BenchOptions {
        small,
        gpu: engine != BenchEngine::Cpu,
        repeats: repeats as usize,
        parts: match only {
            None => BenchParts::All,
            Some(BenchPart::Kernels) => BenchParts::Kernels,
            Some(BenchPart::Decode) => BenchParts::Decode,
            Some(BenchPart::Gap) => BenchParts::Gap,
            Some(BenchPart::Fit) => BenchParts::Fit,
        },
        season,
    });
    print!("{}", tirewear::bench::render(&r));
    if engine == BenchEngine::Gpu && r.gpu.is_none() {
        anyhow::bail!("--engine gpu: no GPU adapter could be opened (see the note above)");
    }
    tirewear::atomic::write_bytes(&out, serde_json::to_string_pretty(&r)?.as_bytes())
        .with_context(|| format!("writing {}", out.display()))?;
    println!("wrote {}", out.display());
    Ok(())
}
