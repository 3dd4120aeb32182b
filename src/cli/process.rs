//! `tirewear process`: its arguments and what it runs.

use anyhow::Result;
use std::path::PathBuf;
use tirewear::nightly::remote::{Location, S3Settings, Session};
use tirewear::nightly::steps::StepsDone;
use tirewear::nightly::{Mode, NightlyError, ProcessOptions, ProcessSummary};

#[derive(clap::Args)]
pub(crate) struct ProcessArgs {
    /// Season archive folders (with season.toml) or manifests, or
    /// `s3://bucket/prefix` (mirrored into --cache first, only changed
    /// objects downloaded). May be left out with --commit: the shards' list
    /// (or the last commit's) is used.
    archives: Vec<String>,
    /// The dataset folder to bring up to date (created if missing), or
    /// `s3://bucket/prefix`: processed in its mirror under --cache and
    /// published after the commit, `dataset.json` last with a conditional
    /// put. The store is reached through the AWS_* environment variables
    /// (AWS_ENDPOINT, AWS_REGION, AWS_ACCESS_KEY_ID, AWS_SECRET_ACCESS_KEY,
    /// AWS_ALLOW_HTTP; docs/nightly.md, "Object storage").
    #[arg(long)]
    out: String,
    /// Local folder for the mirrors of s3:// archives and datasets (kept
    /// between nights: only what changed is transferred).
    #[arg(long, env = "TIREWEAR_CACHE")]
    cache: Option<PathBuf>,
    /// Engine for the heavy reductions: cpu, gpu, or auto. The engine is part
    /// of every run's key: changing it reprocesses every run.
    #[arg(long, value_enum, default_value = "auto")]
    engine: super::extract::EngineArg,
    /// Worker threads, 1 to 1024 (default: all cores).
    #[arg(long, value_parser = super::parse_jobs)]
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
    /// How much memory the runs decoded at once may need together:
    /// `auto` (three quarters of the memory available at start: the
    /// system's MemAvailable or the control group's limit, whichever is
    /// smaller) or a size such as 8G or 512M. Runs start while their
    /// estimated needs fit; a run that alone needs more fails, naming its
    /// file, and is tried again the next night (docs/reliability.md,
    /// "Memory").
    #[arg(long, value_name = "SIZE", default_value = "auto", value_parser = super::parse_memory_limit)]
    memory_limit: tirewear::memory::MemoryLimit,
    /// After a commit that changed the dataset, also refit the models
    /// (`fit`: DATASET/models/STAMP/) and rerun the gap diagnosis (`gap`:
    /// DATASET/gap/STAMP/) and write the HTML report (`report`:
    /// DATASET/report/STAMP/report.html, from the newest models and gap),
    /// STAMP being the UTC time (YYYY-MM-DDTHHMMSSZ; a second later when an
    /// earlier night used it, so each night's folders are its own). A step
    /// an earlier night did not finish on the committed dataset (it failed,
    /// or the night was stopped) runs even when nothing changed
    /// (DATASET/then.json).
    #[arg(long, value_delimiter = ',', value_enum)]
    then: Vec<Then>,
    /// Keep only the N newest dated folders of each `--then` step
    /// (DATASET/models/, gap/, report/): after a step succeeds, its older
    /// dated folders are removed. A step that failed removes nothing, so
    /// the last good result stays. Default: keep every folder.
    #[arg(long, value_name = "N", requires = "then",
          value_parser = clap::value_parser!(u32).range(1..))]
    keep_results: Option<u32>,
}

/// A step `--then` runs after a commit that changed the dataset (or that
/// an earlier night did not finish on the committed dataset).
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum Then {
    Fit,
    Gap,
    Report,
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
        if let Some(n) = &s.largest_memory_need {
            println!(
                "the largest of them, {}, needs about {} of memory ({} bytes); \
                 --memory-limit or a job's memory must hold at least that",
                n.run,
                tirewear::memory::human(n.bytes),
                n.bytes
            );
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
            .num_threads(j)
            .build_global()?;
    }
    let mode = match (a.shard, a.commit) {
        (Some((index, count)), _) => Mode::Shard { index, count },
        (None, true) => Mode::Commit,
        (None, false) => Mode::Whole,
    };
    let archives = a
        .archives
        .iter()
        .map(|s| Location::parse(s))
        .collect::<Result<Vec<_>, _>>()?;
    let dataset = Location::parse(&a.out)?;
    if matches!(dataset, Location::S3 { .. }) && matches!(mode, Mode::Shard { .. }) {
        anyhow::bail!(
            "--shard stages parts in the dataset folder: give shards a shared folder, not s3://"
        );
    }
    // Before anything is pulled; local folders are checked by the library.
    if let Some(a) = archives.iter().find(|a| dataset.holds(a)) {
        anyhow::bail!(
            "{}: the dataset is, or holds, the season archive {}: its files would replace the \
             archive's or sweep them as stale; give the dataset a prefix outside the archive",
            dataset.url(),
            a.url()
        );
    }
    let session = Session::prepare(
        &archives,
        &dataset,
        a.cache.as_deref(),
        &S3Settings::default(),
    )?;
    for (url, r) in &session.pulled {
        println!(
            "pulled {url}: {} objects downloaded ({:.1} MB), {} unchanged, {} removed",
            r.transferred,
            r.bytes as f64 / 1e6,
            r.unchanged,
            r.deleted
        );
    }
    let opts = ProcessOptions {
        archives: session.archive_dirs.clone(),
        dataset: session.dataset_dir.clone(),
        engine: a.engine.into(),
        mode,
        dry_run: a.dry_run,
        force: a.force,
        progress,
        allow_external_paths: a.allow_external_paths,
        memory_limit: a.memory_limit,
    };
    // The lock is held through the `--then` steps and the publish: no other
    // writer commits, tidies or prunes beside them.
    match tirewear::nightly::process_locked(&opts) {
        Ok((s, _lock)) => {
            print_summary(&s);
            let then_failed = if a.then.is_empty() {
                Vec::new()
            } else if opts.dry_run {
                dry_run_then(&opts, &s, &a.then);
                Vec::new()
            } else {
                run_then(&opts, &s, &a.then, a.keep_results)
            };
            if !opts.dry_run
                && let Some(r) = session.publish()?
            {
                println!(
                    "published {}: {} objects uploaded ({:.1} MB), {} unchanged, {} deleted",
                    dataset.url(),
                    r.transferred,
                    r.bytes as f64 / 1e6,
                    r.unchanged,
                    r.deleted
                );
            }
            if !then_failed.is_empty() {
                println!("--then: not done: {}", then_failed.join(", "));
            }
            Ok(if s.failed.is_empty() && then_failed.is_empty() {
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

impl Then {
    fn name(self) -> &'static str {
        match self {
            Then::Fit => "fit",
            Then::Gap => "gap",
            Then::Report => "report",
        }
    }
}

/// The asked steps' names, joined.
fn names(steps: &[Then]) -> String {
    steps
        .iter()
        .map(|t| t.name())
        .collect::<Vec<_>>()
        .join(", ")
}

/// The steps `then.json` records as done on `dataset_id` (a damaged
/// record named on stderr, and none done).
fn recorded(opts: &ProcessOptions, dataset_id: &str) -> StepsDone {
    let (record, warning) = StepsDone::read(&opts.dataset, dataset_id);
    if let Some(w) = warning {
        eprintln!("Warning: {w}");
    }
    record
}

/// The asked steps the record lists as done, and the others.
fn split_done(record: &StepsDone, asked: &[Then]) -> (Vec<Then>, Vec<Then>) {
    asked.iter().partition(|t| record.is_done(t.name()))
}

/// What `--then` would run after a dry run's plan: every step when runs
/// would be processed or removed, else those not done on the dataset.
fn dry_run_then(opts: &ProcessOptions, s: &ProcessSummary, asked: &[Then]) {
    if matches!(opts.mode, Mode::Shard { .. }) {
        return;
    }
    if !s.runs_processed.is_empty() || s.removed > 0 {
        println!("--then: would run {} after the commit", names(asked));
        return;
    }
    let (_, pending) = split_done(&recorded(opts, &s.dataset_id), asked);
    if s.dataset_id.is_empty() {
        println!("--then: nothing to run (no dataset committed)");
    } else if pending.is_empty() {
        println!("--then: nothing to run (no change; every step done on the dataset)");
    } else {
        println!(
            "--then: would run {} (not done on dataset {})",
            names(&pending),
            s.dataset_id
        );
    }
}

/// The `--then` steps this night owes the committed dataset: all of them
/// after a commit, else those an earlier night did not finish on it (a
/// step failed, or the night was stopped after its commit;
/// `DATASET/then.json`). Returns the steps that failed or were skipped.
fn run_then(
    opts: &ProcessOptions,
    s: &ProcessSummary,
    asked: &[Then],
    keep: Option<u32>,
) -> Vec<String> {
    // A shard commits nothing; a dataset never committed has nothing to fit.
    if matches!(opts.mode, Mode::Shard { .. }) || !opts.dataset.join("dataset.json").exists() {
        return Vec::new();
    }
    let mut record = if s.committed {
        let fresh = StepsDone {
            dataset_id: s.dataset_id.clone(),
            done: Vec::new(),
        };
        // Written at once: a night stopped before its first step must not
        // leave an older record that says the steps were done.
        if let Err(e) = fresh.write(&opts.dataset) {
            eprintln!("Warning: --then: {e}");
        }
        fresh
    } else {
        recorded(opts, &s.dataset_id)
    };
    let (done, pending) = split_done(&record, asked);
    if !done.is_empty() {
        println!(
            "--then: {} already done on dataset {}",
            names(&done),
            s.dataset_id
        );
    }
    if !s.committed && !pending.is_empty() {
        println!(
            "--then: {} not done on dataset {} by an earlier night (a step failed or was stopped): running now",
            names(&pending),
            s.dataset_id
        );
    }
    then_steps(opts, &pending, keep, &mut record)
}

/// Runs the `--then` steps on the committed dataset, into dated folders.
/// Each step runs whatever became of the others (`gap` does not need
/// `fit`), except `report`: it shows the newest models and gap, so after a
/// failed `fit` or `gap` it would show an older night's next to this
/// dataset, and is skipped. A step that succeeded keeps only the
/// `keep` newest dated folders of its kind. Returns the steps that failed
/// or were skipped.
fn then_steps(
    opts: &ProcessOptions,
    steps: &[Then],
    keep: Option<u32>,
    record: &mut StepsDone,
) -> Vec<String> {
    if steps.is_empty() {
        return Vec::new();
    }
    // What a night stopped during its steps left in its own folders.
    for sub in tirewear::nightly::stamp::RESULT_FOLDERS {
        match tirewear::nightly::retention::tidy_dated(&opts.dataset.join(sub)) {
            Ok(removed) => {
                for r in removed {
                    println!("--then: removed {} (left by a stopped night)", r.display());
                }
            }
            Err(e) => eprintln!("Warning: --then: tidying {sub}/: {e}"),
        }
    }
    let kpis = opts.dataset.join("kpis.parquet");
    // The night's own folders: a stamp an earlier night used moves on.
    let stamp = tirewear::nightly::stamp::fresh(
        &opts.dataset,
        &tirewear::nightly::stamp::RESULT_FOLDERS,
        std::time::SystemTime::now(),
    );
    let mut failed: Vec<&str> = Vec::new();
    let tell = |name: &str, e: &anyhow::Error| eprintln!("Error: --then {name} failed: {e:?}");
    // A step done: recorded, so that a later night does not run it again
    // on the same dataset; a record that cannot be written only costs that.
    let mut done = |step: Then| {
        if let Err(e) = record.mark_done(&opts.dataset, step.name()) {
            eprintln!("Warning: --then: {e}");
        }
    };
    // A step's older results: their removal failing is named as a step.
    let prune = |sub: &str, label: &'static str, failed: &mut Vec<&str>| {
        if let Some(keep) = keep
            && !prune_results(&opts.dataset.join(sub), keep)
        {
            failed.push(label);
        }
    };
    if steps.contains(&Then::Fit) {
        println!();
        match super::fit::run_fit(
            &kpis,
            &tirewear::model::fit::Method::ALL,
            &tirewear::model::fit::FitSettings {
                progress: opts.progress,
                ..Default::default()
            },
            &opts.dataset.join("models").join(&stamp),
        ) {
            // Some methods fitted: the report shows those (from this fit only).
            Ok(not_fitted) if !not_fitted.is_empty() => failed.push("fit (some methods)"),
            Ok(_) => {
                done(Then::Fit);
                prune("models", "pruning models", &mut failed);
            }
            Err(e) => {
                tell("fit", &e);
                failed.push("fit");
            }
        }
    }
    if steps.contains(&Then::Gap) {
        println!();
        match then_gap(opts, &kpis, &stamp) {
            Ok(()) => {
                done(Then::Gap);
                prune("gap", "pruning gap", &mut failed);
            }
            Err(e) => {
                tell("gap", &e);
                failed.push("gap");
            }
        }
    }
    if steps.contains(&Then::Report) {
        println!();
        let stale: Vec<&str> = failed
            .iter()
            .copied()
            .filter(|s| ["fit", "gap"].contains(s))
            .collect();
        if stale.is_empty() {
            let dir = opts.dataset.join("report").join(&stamp);
            match super::report::run_report(&opts.dataset, &dir.join("report.html"), &[]) {
                Ok(true) => {
                    done(Then::Report);
                    prune("report", "pruning report", &mut failed);
                }
                Ok(false) => failed.push("report (some inputs left out)"),
                Err(e) => {
                    tell("report", &e);
                    failed.push("report");
                }
            }
        } else {
            eprintln!(
                "Error: --then report skipped: {} failed, so the report would show an older \
                 result beside this dataset",
                stale.join(" and ")
            );
            failed.push("report (skipped)");
        }
    }
    failed.into_iter().map(String::from).collect()
}

/// Removes all but the `keep` newest dated folders of `dir`, saying which;
/// false (and the error on stderr) when that failed.
fn prune_results(dir: &std::path::Path, keep: u32) -> bool {
    match tirewear::nightly::retention::prune_dated(dir, keep as usize) {
        Ok(removed) => {
            for r in removed {
                println!("--keep-results {keep}: removed {}", r.display());
            }
            true
        }
        Err(e) => {
            eprintln!(
                "Error: --keep-results: pruning {} failed: {e}",
                dir.display()
            );
            false
        }
    }
}

/// The gap diagnosis of the committed dataset, with the compounds' WLF
/// constants from every archive's manifest.
fn then_gap(opts: &ProcessOptions, kpis: &std::path::Path, stamp: &str) -> Result<()> {
    let mut wlf = std::collections::BTreeMap::new();
    for a in &opts.archives {
        let season = tirewear::ingest::manifest::Season::open_with(a, opts.allow_external_paths)?;
        for c in &season.manifest.compounds {
            let k = tirewear::ingest::compound::Compound::load(&season.path(&c.file))?;
            wlf.insert(c.id.clone(), k.wlf);
        }
    }
    let settings = tirewear::gap::report::GapSettings {
        wlf,
        progress: opts.progress,
        ..Default::default()
    };
    super::gap::run_gap(
        kpis,
        "physics",
        &settings,
        &opts.dataset.join("gap").join(stamp),
    )
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
