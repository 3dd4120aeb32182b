//! `tirewear process`: its arguments and what it runs.

use anyhow::Result;
use std::path::PathBuf;
use tirewear::nightly::{Mode, NightlyError, ProcessOptions, ProcessSummary};

#[derive(clap::Args)]
pub(crate) struct ProcessArgs {
    /// Season archive folders (with season.toml) or manifests. May be left
    /// out with --commit: the shards' list (or the last commit's) is used.
    archives: Vec<PathBuf>,
    /// The dataset folder to bring up to date (created if missing).
    #[arg(long)]
    out: PathBuf,
    /// Engine for the heavy reductions: cpu, gpu, or auto. The engine is part
    /// of every run's key: changing it reprocesses every run.
    #[arg(long, value_enum, default_value = "auto")]
    engine: super::extract::EngineArg,
    /// Worker threads (default: all cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// Process only share K of N (1-based, e.g. 3/8): stage its parts and
    /// commit nothing; `--commit` (or a later whole run) commits them.
    #[arg(long, value_name = "K/N", value_parser = parse_shard, conflicts_with = "commit")]
    shard: Option<(u32, u32)>,
    /// Commit the parts the shards staged; process nothing. Runs no shard
    /// staged are reported as failed (exit 3).
    #[arg(long)]
    commit: bool,
    /// List what would be processed; write nothing.
    #[arg(long)]
    dry_run: bool,
    /// Process every run again, whatever its key.
    #[arg(long)]
    force: bool,
    /// Accept manifest paths outside the archive folders (see `extract`).
    #[arg(long)]
    allow_external_paths: bool,
}

/// `K/N` with 1 <= K <= N, as (K - 1, N).
fn parse_shard(s: &str) -> Result<(u32, u32), String> {
    let (k, n) = s
        .split_once('/')
        .ok_or_else(|| format!("'{s}' is not K/N (e.g. 2/4)"))?;
    let k: u32 = k
        .trim()
        .parse()
        .map_err(|_| format!("'{k}' is not a shard number"))?;
    let n: u32 = n
        .trim()
        .parse()
        .map_err(|_| format!("'{n}' is not a shard count"))?;
    if n == 0 || k == 0 || k > n {
        return Err(format!("shard {k}/{n}: K must be 1..=N and N at least 1"));
    }
    Ok((k - 1, n))
}

/// What `process` ended with, for the exit code.
pub(crate) enum Outcome {
    Done,
    SomeFailed,
    Locked,
}

fn print_summary(s: &ProcessSummary) {
    if s.dry_run {
        println!(
            "dry run ({}): {} runs planned, {} unchanged, {} staged by an earlier run, {} to process, {} to remove",
            s.mode,
            s.planned,
            s.unchanged,
            s.reused_staged,
            s.runs_processed.len(),
            s.removed
        );
        for r in &s.runs_processed {
            println!("would process run {r}");
        }
        return;
    }
    println!(
        "{}: {} runs planned, {} unchanged, {} processed, {} taken from staging, {} removed, {} failed; {} in {:.1} s ({:?} engine on {})",
        s.mode,
        s.planned,
        s.unchanged,
        s.processed,
        s.reused_staged,
        s.removed,
        s.failed.len(),
        if s.committed {
            format!("committed dataset {} ({} rows)", s.dataset_id, s.rows)
        } else if s.mode.starts_with("shard") {
            "parts staged".to_string()
        } else {
            "nothing to commit".to_string()
        },
        s.seconds,
        s.engine,
        s.device
    );
    println!(
        "read {:.1} MB of telemetry, hashed {:.1} MB of inputs",
        s.telemetry_bytes as f64 / 1e6,
        s.hashed_bytes as f64 / 1e6
    );
    for f in &s.failed {
        println!("failed run {} ({}): {}", f.run, f.season, f.reason);
    }
    for w in s.warnings.iter().take(10) {
        println!("warning: {w}");
    }
    if s.warnings.len() > 10 {
        println!(
            "... and {} more warnings (see summary.json)",
            s.warnings.len() - 10
        );
    }
}

/// Runs `tirewear process`.
pub(crate) fn run(a: ProcessArgs, progress: bool) -> Result<Outcome> {
    if let Some(j) = a.jobs {
        rayon::ThreadPoolBuilder::new()
            .num_threads(j.max(1))
            .build_global()?;
    }
    let mode = match (a.shard, a.commit) {
        (Some((index, count)), _) => Mode::Shard { index, count },
        (None, true) => Mode::Commit,
        (None, false) => Mode::Whole,
    };
    let opts = ProcessOptions {
        archives: a.archives,
        dataset: a.out,
        engine: a.engine.into(),
        mode,
        dry_run: a.dry_run,
        force: a.force,
        progress,
        allow_external_paths: a.allow_external_paths,
    };
    match tirewear::nightly::process(&opts) {
        Ok(s) => {
            print_summary(&s);
            Ok(if s.failed.is_empty() {
                Outcome::Done
            } else {
                Outcome::SomeFailed
            })
        }
        Err(e @ NightlyError::Locked { .. }) => {
            eprintln!("Error: {e}");
            Ok(Outcome::Locked)
        }
        Err(e) => {
            Err(anyhow::Error::new(e)
                .context(format!("processing into {}", opts.dataset.display())))
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn shard_arguments() {
        assert_eq!(super::parse_shard("1/4"), Ok((0, 4)));
        assert_eq!(super::parse_shard("4/4"), Ok((3, 4)));
        assert!(super::parse_shard("0/4").is_err());
        assert!(super::parse_shard("5/4").is_err());
        assert!(super::parse_shard("1").is_err());
        assert!(super::parse_shard("1/0").is_err());
    }
}
