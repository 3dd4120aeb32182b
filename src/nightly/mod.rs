//! `tirewear process`: brings a KPI dataset up to date with season archives,
//! processing only the runs whose inputs changed (docs/nightly.md).
//!
//! A dataset folder holds:
//! - `kpis/event=E/RUN.parquet`, `energy_maps/event=E/RUN.parquet`,
//!   `condition_maps/event=E/RUN.parquet`: one committed part per run, a
//!   partitioned Parquet dataset that DuckDB, Polars or Spark read as is;
//! - `road/track=T.parquet`: the road curves of each track;
//! - `kpis.parquet` and its side tables (`kpis.road.parquet`,
//!   `kpis.energy_maps.parquet`, `kpis.condition_maps.parquet`): the parts
//!   consolidated, what `fit` and `gap` read;
//! - `dataset.json`: the committed runs with their keys and parts, written
//!   last at each commit; `summary.json`: what the last invocation did;
//! - `staging/`: finished parts not yet committed (a killed run's, or the
//!   shards'), named by key and reused by the next run or `--commit`.
//!
//! Every commit goes through one journal (`atomic::OutputSet`): a kill at
//! any moment leaves the old set or a journal the next run completes.

mod error;
mod keys;
mod lock;
pub mod remote;
pub mod retention;
pub mod stamp;
pub mod steps;

pub use error::NightlyError;
pub use lock::DatasetLock;

use crate::atomic::OutputSet;
use crate::engine::{CpuEngine, ReduceEngine};
use crate::ingest::IngestError;
use crate::ingest::manifest::{Run, Season};
use crate::kpi::Engine;
use crate::kpi::extract::{
    RunContext, RunOutput, SeasonInputs, energy_maps_batch, extract_runs, open_engine,
    road_curves_batch, road_kpis, season_inputs,
};
use crate::kpi::table::{kpi_batch, with_extraction_id, write_batches_to, write_part_to};
use arrow_array::RecordBatch;
use keys::{FileHashes, FileStamp};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Version of `dataset.json`.
pub(crate) const DATASET_FORMAT_VERSION: u32 = 1;

/// Which share of the work this invocation does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Process every run that needs it, then commit.
    Whole,
    /// Process only shard `index` (0-based) of `count`, stage its parts, no commit.
    Shard { index: u32, count: u32 },
    /// Commit the staged parts of the shards; process nothing.
    Commit,
}

#[derive(Debug, Clone)]
pub struct ProcessOptions {
    /// Season archive folders (or manifests). With `Mode::Commit` they may
    /// be left empty: the shards' or the last commit's list is used.
    pub archives: Vec<PathBuf>,
    pub dataset: PathBuf,
    pub engine: Engine,
    pub mode: Mode,
    /// Plan only: say what would be processed, write nothing.
    pub dry_run: bool,
    /// Process every run again, whatever its key.
    pub force: bool,
    pub progress: bool,
    pub allow_external_paths: bool,
    /// How much memory the runs decoded at once may need together
    /// (`crate::memory`).
    pub memory_limit: crate::memory::MemoryLimit,
}

impl ProcessOptions {
    /// Processing `archives` into `dataset`, whole, on the CPU engine.
    pub fn new(archives: Vec<PathBuf>, dataset: impl Into<PathBuf>) -> Self {
        ProcessOptions {
            archives,
            dataset: dataset.into(),
            engine: Engine::Cpu,
            mode: Mode::Whole,
            dry_run: false,
            force: false,
            progress: false,
            allow_external_paths: false,
            memory_limit: crate::memory::MemoryLimit::Auto,
        }
    }

    /// Refuses options that cannot work together.
    pub fn check(&self) -> Result<(), NightlyError> {
        if let Mode::Shard { index, count } = self.mode
            && (count == 0 || index >= count)
        {
            return Err(NightlyError::Invalid(format!(
                "shard {} of {count} does not exist (shards are numbered 1..={count})",
                index + 1
            )));
        }
        if self.archives.is_empty() && self.mode != Mode::Commit {
            return Err(NightlyError::Invalid(
                "no season archive given (only a commit can take the archives from the dataset)"
                    .into(),
            ));
        }
        for a in &self.archives {
            check_apart(a, &self.dataset)?;
        }
        Ok(())
    }
}

/// Refuses a dataset folder that is an archive's folder or holds one: the
/// dataset's own folders (`road/`, `kpis/`, …) would replace the archive's
/// files or sweep them as stale parts (`process demo --out demo` once
/// deleted the archive's road profiles). A dataset inside an archive's
/// folder is allowed: the archive is read by its manifest alone.
fn check_apart(archive: &Path, dataset: &Path) -> Result<(), NightlyError> {
    let folder = if archive.is_file() {
        crate::atomic::folder_of(archive)
    } else {
        archive
    };
    // Folders are compared where they really are, links followed.
    let real = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| crate::atomic::entry_of(p));
    let (folder, data) = (real(folder), real(dataset));
    if !folder.starts_with(&data) {
        return Ok(());
    }
    let how = if folder == data { "is" } else { "holds" };
    Err(NightlyError::Invalid(format!(
        "{}: the dataset folder {how} the season archive {}: the dataset's files would replace \
         the archive's or sweep them as stale; give the dataset a folder outside the archive",
        dataset.display(),
        archive.display()
    )))
}

/// One committed run of the dataset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct RunEntry {
    run: String,
    event: String,
    track: String,
    /// The archive's manifest name.
    season: String,
    /// The archive as given on the command line: if it cannot be read on a
    /// later night, its committed runs are kept, not dropped. (Empty in
    /// manifests written before it was recorded.)
    #[serde(default)]
    archive: PathBuf,
    key: String,
    rows: usize,
}

/// The road curves of one track.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct RoadEntry {
    track: String,
    key: String,
}

/// `dataset.json`: the committed state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
struct DatasetManifest {
    format_version: u32,
    /// The id every consolidated file carries (`tirewear.extraction_id`).
    dataset_id: String,
    archives: Vec<PathBuf>,
    /// Sorted by event, then run.
    runs: Vec<RunEntry>,
    /// Sorted by track.
    roads: Vec<RoadEntry>,
    /// Stamps of the input files, so unchanged files are not hashed again.
    files: BTreeMap<String, FileStamp>,
}

/// A run that could not be processed, and why.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Failed {
    pub run: String,
    pub season: String,
    pub reason: String,
    /// Its rows from an earlier commit stay in the dataset (its key the
    /// old one, so it is tried again next time). Absent in records written
    /// before 2026-12-02.
    #[serde(default)]
    pub kept: bool,
}

/// A run's estimated memory need, in bytes.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct MemoryNeed {
    pub run: String,
    pub bytes: u64,
}

/// What one invocation did (stdout and `DATASET/summary.json`).
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct ProcessSummary {
    pub mode: String,
    pub dry_run: bool,
    /// Runs in the archives (this shard's share for a shard).
    pub planned: usize,
    pub unchanged: usize,
    /// Runs processed by this invocation.
    pub processed: usize,
    /// Runs whose parts an earlier (killed) invocation or a shard had staged.
    pub reused_staged: usize,
    /// Committed runs no longer in any archive, left out of the dataset.
    pub removed: usize,
    pub failed: Vec<Failed>,
    /// The runs that would be processed (dry run) or were.
    pub runs_processed: Vec<String>,
    /// Dry run: the run to process that needs the most memory, and how
    /// much (`kpi::run_memory_need`), to size a machine or a job by.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub largest_memory_need: Option<MemoryNeed>,
    pub committed: bool,
    /// The committed dataset's id after this invocation (a dry run: as
    /// committed before it; empty for a shard).
    pub dataset_id: String,
    pub rows: usize,
    pub seconds: f64,
    /// Telemetry bytes decoded, and input bytes read only to hash them.
    pub telemetry_bytes: u64,
    pub hashed_bytes: u64,
    pub engine: Engine,
    pub device: String,
    pub warnings: Vec<String>,
}

/// A run of an archive with its key.
struct Planned {
    season: usize,
    run: Run,
    track: String,
    key: String,
    road_key: String,
}

/// The three part kinds of a run, in the order they are written.
const PART_KINDS: [&str; 3] = ["kpis", "energy_maps", "condition_maps"];

/// A folder or file name for an id: bytes outside `[A-Za-z0-9_-]` (and a
/// dot) percent-encoded, as Hive-style partitions expect.
fn path_name(id: &str) -> String {
    let mut s = String::with_capacity(id.len());
    for b in id.bytes() {
        if b.is_ascii_alphanumeric() || b == b'_' || b == b'-' {
            s.push(b as char);
        } else {
            s.push_str(&format!("%{b:02X}"));
        }
    }
    s
}

fn committed_part(dataset: &Path, kind: &str, e: &RunEntry) -> PathBuf {
    dataset
        .join(kind)
        .join(format!("event={}", path_name(&e.event)))
        .join(format!("{}.parquet", path_name(&e.run)))
}

fn committed_road(dataset: &Path, track: &str) -> PathBuf {
    dataset
        .join("road")
        .join(format!("track={}.parquet", path_name(track)))
}

fn staged_part(dataset: &Path, kind: &str, key: &str) -> PathBuf {
    dataset
        .join("staging")
        .join(format!("{key}.{kind}.parquet"))
}

fn staged_failure(dataset: &Path, key: &str) -> PathBuf {
    dataset.join("staging").join(format!("{key}.failed.json"))
}

fn staged_road(dataset: &Path, key: &str) -> PathBuf {
    dataset.join("staging").join(format!("{key}.road.parquet"))
}

/// Whether a run's parts are all staged (each was renamed into place whole).
fn staged_complete(dataset: &Path, key: &str) -> bool {
    PART_KINDS
        .iter()
        .all(|k| staged_part(dataset, k, key).exists())
}

/// Which shard a run belongs to: stable across nights and machines.
fn shard_of(season: &str, run: &str, count: u32) -> u32 {
    let h = blake3::hash(format!("{season}\u{0}{run}").as_bytes());
    let b = h.as_bytes();
    (u64::from_le_bytes(b[..8].try_into().expect("8 bytes")) % count as u64) as u32
}

fn read_manifest(dataset: &Path) -> Result<Option<DatasetManifest>, NightlyError> {
    let path = dataset.join("dataset.json");
    let text = match std::fs::read(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(NightlyError::io(&path)(e)),
    };
    let invalid = |e: &dyn std::fmt::Display| {
        NightlyError::Invalid(format!(
            "{}: not a tirewear dataset manifest: {e} (nothing was changed; move the file \
             aside and the next run processes every run of the archives again)",
            path.display()
        ))
    };
    let m: DatasetManifest = parse_sealed(&text).map_err(|why| invalid(&why))?;
    if m.format_version != DATASET_FORMAT_VERSION {
        return Err(NightlyError::Invalid(format!(
            "{}: format_version {} (this build reads {DATASET_FORMAT_VERSION})",
            path.display(),
            m.format_version
        )));
    }
    Ok(Some(m))
}

/// Reads every record batch of a Parquet file, its footer and checksum
/// checked first (`checksum::open_parquet`).
fn read_batches(path: &Path) -> Result<Vec<RecordBatch>, NightlyError> {
    let bad = |e: &dyn std::fmt::Display| {
        NightlyError::Invalid(format!(
            "{}: damaged part: {e} (delete it and it is made again on the next run)",
            path.display()
        ))
    };
    let opened = crate::ingest::checksum::open_parquet(path).map_err(|e| match e {
        IngestError::Io { source, .. } => NightlyError::io(path)(source),
        // The message without its leading path: `bad` names the file once.
        e => {
            let msg = e.to_string();
            bad(&msg
                .strip_prefix(&format!("{}: ", path.display()))
                .unwrap_or(&msg))
        }
    })?;
    let reader = opened.batches().map_err(|e| bad(&e))?;
    reader.collect::<Result<Vec<_>, _>>().map_err(|e| bad(&e))
}

/// Whether every committed part of `e` can still be read: its Parquet
/// footer parses, its data match the footer's checksum and, for the KPI
/// part, it holds the rows the manifest recorded. A part that is missing
/// or fails this is reported in `warnings` and its run is processed again
/// (docs/nightly.md, "Damaged parts and tables").
fn parts_intact(dataset: &Path, e: &RunEntry, warnings: &mut Vec<String>) -> bool {
    match first_damaged_part(dataset, e) {
        None => true,
        Some((path, why)) => {
            warn_damage(
                warnings,
                &path,
                &why,
                &format!("run {} processed again", e.run),
            );
            false
        }
    }
}

/// The first committed part of `e` that is missing or damaged, with why
/// (see [`parts_intact`]).
fn first_damaged_part(dataset: &Path, e: &RunEntry) -> Option<(PathBuf, String)> {
    PART_KINDS.iter().find_map(|kind| {
        let path = committed_part(dataset, kind, e);
        let rows = (*kind == "kpis").then_some(e.rows);
        part_damage(&path, rows).map(|why| (path, why))
    })
}

/// Keeps the committed entry of each run that failed this time, where its
/// parts are intact: a telemetry mount that is down or a sync half done
/// would otherwise empty the dataset for a night, and the rows are only as
/// stale as the last commit. The entry keeps its old key, so the run is
/// processed again next time; `Failed::kept` and the reason say so.
fn keep_failed_runs(
    dataset: &Path,
    committed: &BTreeMap<&str, &RunEntry>,
    runs: &mut Vec<(RunEntry, Option<&Planned>)>,
    summary: &mut ProcessSummary,
) {
    let listed: BTreeSet<String> = runs.iter().map(|(e, _)| e.run.clone()).collect();
    for f in &mut summary.failed {
        let Some(e) = committed.get(f.run.as_str()) else {
            continue;
        };
        if e.season != f.season || listed.contains(&f.run) {
            continue;
        }
        match first_damaged_part(dataset, e) {
            None => {
                runs.push(((*e).clone(), None));
                f.kept = true;
                f.reason
                    .push_str("; its rows from the last commit are kept until it is processed");
            }
            Some((path, why)) => warn_damage(
                &mut summary.warnings,
                &path,
                &why,
                &format!(
                    "run {} failed, so its committed rows cannot be kept: they are left out \
                     until it is processed",
                    f.run
                ),
            ),
        }
    }
}

/// What is wrong with a committed part, if anything (see [`parts_intact`]).
fn part_damage(path: &Path, rows: Option<usize>) -> Option<String> {
    use crate::ingest::checksum::ParquetSource;
    use parquet::file::reader::Length;
    let source = match ParquetSource::open(path) {
        Ok(f) => f,
        Err(IngestError::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {
            return Some("missing".into());
        }
        Err(e) => return Some(format!("cannot be opened: {e}")),
    };
    let meta = match parquet::file::metadata::ParquetMetaDataReader::new().parse_and_finish(&source)
    {
        Ok(m) => m,
        Err(e) => return Some(format!("damaged (not a readable Parquet file: {e})")),
    };
    if let Some(why) = crate::ingest::checksum::layout_fault(&meta, source.len()) {
        return Some(format!("damaged (footer: {why})"));
    }
    let data = match &source {
        ParquetSource::Memory(data) => Some(data.as_ref()),
        ParquetSource::File(_) => None,
    };
    if let Some(why) = crate::ingest::checksum::mismatch_in(path, data, &meta) {
        return Some(format!("damaged (data checksum: {why})"));
    }
    let found = meta.file_metadata().num_rows();
    match rows {
        Some(want) if found != want as i64 => Some(format!(
            "damaged ({found} rows where the manifest recorded {want})"
        )),
        _ => None,
    }
}

/// Whether the four consolidated tables can still be read (footers, as
/// [`parts_intact`]); one that cannot is reported and rebuilt by a commit.
fn tables_intact(dataset: &Path, warnings: &mut Vec<String>) -> bool {
    let mut intact = true;
    for kind in PART_KINDS.iter().chain(&["road"]) {
        let path = table_path(dataset, kind);
        if let Some(why) = part_damage(&path, None) {
            warn_damage(warnings, &path, &why, "rebuilt from the parts");
            intact = false;
        }
    }
    intact
}

/// Logs a damaged file and what is done about it, and keeps it for the summary.
fn warn_damage(warnings: &mut Vec<String>, path: &Path, why: &str, remedy: &str) {
    let w = format!("{}: {why}; {remedy}", path.display());
    tracing::warn!("{w}");
    warnings.push(w);
}

/// Removes temporary files of killed writers everywhere in the dataset.
fn remove_orphans_everywhere(dir: &Path) -> Result<(), NightlyError> {
    crate::atomic::remove_orphans(dir).map_err(NightlyError::io(dir))?;
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(());
    };
    for e in entries.flatten() {
        if e.file_type().is_ok_and(|t| t.is_dir()) {
            remove_orphans_everywhere(&e.path())?;
        }
    }
    Ok(())
}

/// Brings `opts.dataset` up to date with `opts.archives`.
pub fn process(opts: &ProcessOptions) -> Result<ProcessSummary, NightlyError> {
    process_locked(opts).map(|(summary, _lock)| summary)
}

/// [`process`], returning the dataset's lock still held (none for a dry
/// run): what follows the commit (`process --then`) runs with no other
/// writer beside it, until the lock is dropped.
pub fn process_locked(
    opts: &ProcessOptions,
) -> Result<(ProcessSummary, Option<DatasetLock>), NightlyError> {
    opts.check()?;
    let dataset = &opts.dataset;
    let lock = if opts.dry_run {
        None
    } else {
        std::fs::create_dir_all(dataset.join("staging")).map_err(NightlyError::io(dataset))?;
        Some(lock::acquire(
            dataset,
            !matches!(opts.mode, Mode::Shard { .. }),
        )?)
    };
    Ok((process_under_lock(opts)?, lock))
}

/// [`process`]'s work, the lock taken.
fn process_under_lock(opts: &ProcessOptions) -> Result<ProcessSummary, NightlyError> {
    let start = Instant::now();
    let dataset = &opts.dataset;
    if !opts.dry_run && !matches!(opts.mode, Mode::Shard { .. }) {
        // Finish a commit a kill interrupted, and sweep dead writers' files.
        crate::atomic::recover(&dataset.join(".commit.json")).map_err(NightlyError::io(dataset))?;
        remove_orphans_everywhere(dataset)?;
    }
    let old = read_manifest(dataset)?.unwrap_or_default();
    let archives = if opts.archives.is_empty() {
        shard_archives(dataset)?.unwrap_or_else(|| old.archives.clone())
    } else {
        opts.archives.clone()
    };
    if archives.is_empty() {
        return Err(NightlyError::Invalid(format!(
            "{}: no archives to commit (give them on the command line)",
            dataset.display()
        )));
    }
    let opened = open_archives(&archives, &old, opts.allow_external_paths);

    // The engine decides the keys (f32 on the GPU, f64 on the CPU); it is
    // opened before planning, but the device only used if there is work.
    let (engine, gpu) = open_engine(opts.engine).map_err(|e| {
        NightlyError::Invalid(format!(
            "gpu engine: {e} (the cpu and auto engines need no GPU)"
        ))
    })?;
    let reducer: &dyn ReduceEngine = match &gpu {
        Some(g) => g,
        None => &CpuEngine,
    };

    let mut files = FileHashes {
        old: old.files.clone(),
        ..Default::default()
    };
    let plan = plan_runs(&opened, engine, &mut files)?;

    let committed: BTreeMap<&str, &RunEntry> =
        old.runs.iter().map(|e| (e.run.as_str(), e)).collect();
    let mut summary = ProcessSummary {
        mode: match opts.mode {
            Mode::Whole => "whole".into(),
            Mode::Shard { index, count } => format!("shard {}/{count}", index + 1),
            Mode::Commit => "commit".into(),
        },
        dry_run: opts.dry_run,
        engine,
        device: reducer.device(),
        ..Default::default()
    };
    summary.failed.extend(opened.unreadable.iter().cloned());
    summary.failed.extend(plan.failed.iter().cloned());
    let carried = carried_runs(&old, &opened);
    if !matches!(opts.mode, Mode::Shard { .. }) {
        summary.removed = removed_runs(&old, &plan, &carried);
    }
    let (to_process, mut ready) = triage(opts, &plan.runs, &opened, &committed, &mut summary);
    summary.runs_processed = to_process.iter().map(|p| p.run.id.clone()).collect();
    tracing::debug!(
        "planned {} runs in {:.2} s ({} to process)",
        plan.runs.len(),
        start.elapsed().as_secs_f64(),
        to_process.len()
    );
    if opts.dry_run {
        summary.largest_memory_need = largest_memory_need(&opened.seasons, &to_process);
        summary.seconds = start.elapsed().as_secs_f64();
        summary.hashed_bytes = files.bytes_hashed;
        summary.dataset_id = old.dataset_id.clone();
        return Ok(summary);
    }

    // Process and stage.
    let staged = stage_runs(
        opts,
        &opened.seasons,
        &opened.inputs,
        &to_process,
        reducer,
        &mut summary,
    )?;
    ready.extend(staged);
    summary.processed = to_process.len();
    tracing::debug!("staged at {:.2} s", start.elapsed().as_secs_f64());
    summary.hashed_bytes = files.bytes_hashed;

    if let Mode::Shard { index, count } = opts.mode {
        summary.seconds = start.elapsed().as_secs_f64();
        write_shard_record(dataset, index, count, &archives, &summary)?;
        return Ok(summary);
    }

    let mut runs = committed_runs(&plan.runs, &ready, &committed, &opened);
    keep_failed_runs(dataset, &committed, &mut runs, &mut summary);
    runs.extend(carried.iter().map(|e| ((*e).clone(), None)));
    runs.sort_by(|a, b| (&a.0.event, &a.0.run).cmp(&(&b.0.event, &b.0.run)));
    let mut new = new_manifest(&old, &archives, &runs, &plan.runs, &files);
    if new.dataset_id == old.dataset_id
        && ready.is_empty()
        && !opts.force
        && tables_intact(dataset, &mut summary.warnings)
    {
        // Nothing changed in the outputs; keep the stamps current only.
        new.runs = old.runs.clone();
        if new != old {
            write_manifest(dataset, &new)?;
        }
    } else {
        commit(dataset, &old, &mut new, &runs)?;
        summary.committed = true;
    }
    tracing::debug!("committed at {:.2} s", start.elapsed().as_secs_f64());
    // Also finishes the clean-up of a commit a kill interrupted.
    remove_unnamed_parts(dataset, &new)?;
    summary.dataset_id = new.dataset_id.clone();
    summary.rows = new.runs.iter().map(|e| e.rows).sum();
    clean_staging(dataset)?;
    summary.seconds = start.elapsed().as_secs_f64();
    let path = dataset.join("summary.json");
    let text = sealed(&summary);
    crate::atomic::write_bytes(&path, text.as_bytes()).map_err(NightlyError::io(&path))?;
    Ok(summary)
}

/// Writes what shard `index` of `count` leaves for the commit.
fn write_shard_record(
    dataset: &Path,
    index: u32,
    count: u32,
    archives: &[PathBuf],
    summary: &ProcessSummary,
) -> Result<(), NightlyError> {
    let record = ShardRecord {
        archives: archives.to_vec(),
        summary: summary.clone(),
    };
    let path = dataset
        .join("staging")
        .join(format!("shard-{}-of-{count}.json", index + 1));
    let text = sealed(&record);
    crate::atomic::write_bytes(&path, text.as_bytes()).map_err(NightlyError::io(&path))
}

/// The committed runs of archives that could not be read this night,
/// carried over unchanged.
fn carried_runs<'m>(old: &'m DatasetManifest, opened: &OpenedArchives) -> Vec<&'m RunEntry> {
    let kept_archives: BTreeSet<String> =
        opened.unreadable.iter().map(|f| f.season.clone()).collect();
    old.runs
        .iter()
        .filter(|e| kept_archives.contains(&e.archive.display().to_string()))
        .collect()
}

/// How many committed runs are in no archive any more: neither a run of a
/// readable archive (planned or failed) nor a carried one.
fn removed_runs(old: &DatasetManifest, plan: &Plan, carried: &[&RunEntry]) -> usize {
    let in_archives: BTreeSet<&str> = plan
        .run_ids
        .iter()
        .map(|r| r.as_str())
        .chain(carried.iter().map(|e| e.run.as_str()))
        .collect();
    old.runs
        .iter()
        .filter(|e| !in_archives.contains(e.run.as_str()))
        .count()
}

/// The night's archives that could be read, each with its inputs, and a
/// failure for each that could not.
struct OpenedArchives {
    seasons: Vec<Season>,
    inputs: Vec<SeasonInputs>,
    /// The archive of each season.
    paths: Vec<PathBuf>,
    unreadable: Vec<Failed>,
}

/// Opens each archive: one that cannot be read fails its own runs, not the
/// night, and its committed runs (in `old`) stay as they are.
fn open_archives(
    archives: &[PathBuf],
    old: &DatasetManifest,
    allow_external_paths: bool,
) -> OpenedArchives {
    let mut opened = OpenedArchives {
        seasons: Vec::with_capacity(archives.len()),
        inputs: Vec::with_capacity(archives.len()),
        paths: Vec::with_capacity(archives.len()),
        unreadable: Vec::new(),
    };
    for a in archives {
        let read = Season::open_with(a, allow_external_paths)
            .and_then(|s| season_inputs(&s).map(|i| (s, i)));
        match read {
            Ok((s, i)) => {
                opened.seasons.push(s);
                opened.inputs.push(i);
                opened.paths.push(a.clone());
            }
            Err(e) => {
                tracing::warn!("archive {} left as committed: {e}", a.display());
                opened.unreadable.push(Failed {
                    run: "(every run of the archive)".into(),
                    season: a.display().to_string(),
                    reason: format!("{e}; its committed runs are kept as they were"),
                    kept: old.runs.iter().any(|r| r.archive == *a),
                });
            }
        }
    }
    opened
}

/// Every run of the readable archives with its keys.
struct Plan {
    runs: Vec<Planned>,
    /// Runs whose keys could not be made (a file that cannot be read).
    failed: Vec<Failed>,
    /// Every run id of the readable archives, planned or failed.
    run_ids: BTreeSet<String>,
}

/// Keys every run of the opened archives (hashing only files whose stamp
/// changed). A file that cannot be read fails its run, which is tried
/// again; a run id in two seasons stops the night.
fn plan_runs(
    opened: &OpenedArchives,
    engine: Engine,
    files: &mut FileHashes,
) -> Result<Plan, NightlyError> {
    let mut plan = Plan {
        runs: Vec::new(),
        failed: Vec::new(),
        run_ids: BTreeSet::new(),
    };
    let mut season_of_run: BTreeMap<String, String> = BTreeMap::new();
    for (si, season) in opened.seasons.iter().enumerate() {
        let inp = &opened.inputs[si];
        for run in &season.manifest.runs {
            if let Some(other) = season_of_run.insert(run.id.clone(), season.manifest.name.clone())
            {
                return Err(NightlyError::Invalid(format!(
                    "run {} is in both season {other} and season {}: run ids must be unique \
                     across the archives of one dataset",
                    run.id, season.manifest.name
                )));
            }
            let track = season.event(&run.event).expect("validated").track.clone();
            let readings = inp.readings.get(&run.id).map_or(&[][..], |v| v.as_slice());
            let keyed = keys::run_key(season, run, readings, engine, files)
                .and_then(|k| keys::road_key(season, &track, engine, files).map(|r| (k, r)));
            let (key, road_key) = match keyed {
                Ok(k) => k,
                Err(e) => {
                    plan.failed.push(Failed {
                        run: run.id.clone(),
                        season: season.manifest.name.clone(),
                        reason: e.to_string(),
                        kept: false,
                    });
                    continue;
                }
            };
            plan.runs.push(Planned {
                season: si,
                run: run.clone(),
                track,
                key,
                road_key,
            });
        }
    }
    plan.run_ids = season_of_run.into_keys().collect();
    Ok(plan)
}

/// What each planned run (of this shard) needs: nothing (committed and
/// unchanged, its parts intact), its staged parts committed (`ready`), or
/// processing (`to_process`); under `--commit`, a run no shard staged
/// fails with the shard's reason. Counts go to `summary`.
fn triage<'p>(
    opts: &ProcessOptions,
    plan: &'p [Planned],
    opened: &OpenedArchives,
    committed: &BTreeMap<&str, &RunEntry>,
    summary: &mut ProcessSummary,
) -> (Vec<&'p Planned>, Vec<&'p Planned>) {
    let dataset = &opts.dataset;
    let mut to_process: Vec<&Planned> = Vec::new();
    let mut ready: Vec<&Planned> = Vec::new();
    for p in plan {
        if let Mode::Shard { index, count } = opts.mode
            && shard_of(&opened.seasons[p.season].manifest.name, &p.run.id, count) != index
        {
            continue;
        }
        summary.planned += 1;
        // A committed part deleted or damaged since is made again.
        let unchanged = committed
            .get(p.run.id.as_str())
            .is_some_and(|e| e.key == p.key && parts_intact(dataset, e, &mut summary.warnings));
        if unchanged && !opts.force {
            summary.unchanged += 1;
        } else if !opts.force && staged_complete(dataset, &p.key) {
            summary.reused_staged += 1;
            ready.push(p);
        } else if opts.mode == Mode::Commit {
            summary.failed.push(Failed {
                run: p.run.id.clone(),
                season: opened.seasons[p.season].manifest.name.clone(),
                reason: unstaged_reason(dataset, &p.key),
                kept: false,
            });
        } else {
            to_process.push(p);
        }
    }
    (to_process, ready)
}

/// Why the commit finds no staged parts for the run keyed `key`: a shard's
/// failure record, or no shard staged it.
fn unstaged_reason(dataset: &Path, key: &str) -> String {
    let path = staged_failure(dataset, key);
    match read_sealed::<Failed>(&path) {
        Ok(Some(f)) => f.reason,
        Ok(None) => "not processed: no shard staged its parts \
                     (run the shards, or process without --commit)"
            .to_string(),
        Err(why) => format!(
            "a shard failed it, but its record {} is damaged ({why}): \
             run the shard again",
            path.display()
        ),
    }
}

/// The run of `to_process` that needs the most memory (a dry run's
/// forecast); runs whose need cannot be read are left out.
fn largest_memory_need(seasons: &[Season], to_process: &[&Planned]) -> Option<MemoryNeed> {
    to_process
        .iter()
        .filter_map(|p| {
            let path = seasons[p.season].path(&p.run.telemetry);
            let bytes = crate::kpi::run_memory_need(&path).ok()?;
            Some(MemoryNeed {
                run: p.run.id.clone(),
                bytes,
            })
        })
        .max_by_key(|n| n.bytes)
}

/// The runs of the new commit: each ready run with a new entry (its rows
/// counted when committed), each unchanged one with its committed entry.
fn committed_runs<'p>(
    plan: &'p [Planned],
    ready: &[&Planned],
    committed: &BTreeMap<&str, &RunEntry>,
    opened: &OpenedArchives,
) -> Vec<(RunEntry, Option<&'p Planned>)> {
    let ready_keys: BTreeSet<&str> = ready.iter().map(|p| p.key.as_str()).collect();
    let mut runs = Vec::new();
    for p in plan {
        let old_entry = committed.get(p.run.id.as_str());
        if ready_keys.contains(p.key.as_str()) {
            runs.push((
                RunEntry {
                    run: p.run.id.clone(),
                    event: p.run.event.clone(),
                    track: p.track.clone(),
                    season: opened.seasons[p.season].manifest.name.clone(),
                    archive: opened.paths[p.season].clone(),
                    key: p.key.clone(),
                    rows: 0,
                },
                Some(p),
            ));
        } else if let Some(e) = old_entry.filter(|e| e.key == p.key) {
            runs.push(((*e).clone(), None));
        }
    }
    runs
}

/// The dataset manifest of `runs`: each of their tracks with its road key
/// (this night's plan's, else the last commit's), the files' stamps, and
/// the dataset id (a hash of every run and road key).
fn new_manifest(
    old: &DatasetManifest,
    archives: &[PathBuf],
    runs: &[(RunEntry, Option<&Planned>)],
    plan: &[Planned],
    files: &FileHashes,
) -> DatasetManifest {
    let mut road_keys: BTreeMap<&str, &str> = old
        .roads
        .iter()
        .map(|r| (r.track.as_str(), r.key.as_str()))
        .collect();
    road_keys.extend(plan.iter().map(|p| (p.track.as_str(), p.road_key.as_str())));
    let mut roads: BTreeMap<String, RoadEntry> = BTreeMap::new();
    for (e, _) in runs {
        if let Some(key) = road_keys.get(e.track.as_str()) {
            roads.insert(
                e.track.clone(),
                RoadEntry {
                    track: e.track.clone(),
                    key: key.to_string(),
                },
            );
        }
    }
    let mut new = DatasetManifest {
        format_version: DATASET_FORMAT_VERSION,
        dataset_id: String::new(),
        archives: archives.to_vec(),
        runs: runs.iter().map(|(e, _)| e.clone()).collect(),
        roads: roads.into_values().collect(),
        files: files.seen.clone(),
    };
    let mut id = blake3::Hasher::new();
    for e in &new.runs {
        id.update(e.key.as_bytes());
    }
    for r in &new.roads {
        id.update(r.key.as_bytes());
    }
    new.dataset_id = id.finalize().to_hex()[..32].to_string();
    new
}

/// What a shard leaves for the commit: the archives and its summary.
#[derive(Serialize, Deserialize)]
struct ShardRecord {
    archives: Vec<PathBuf>,
    summary: ProcessSummary,
}

/// The archives the shards worked on, if any shard left a record. Every
/// record must name the same archives: a shard given other archives staged
/// runs a commit with the first record's list would not see.
fn shard_archives(dataset: &Path) -> Result<Option<Vec<PathBuf>>, NightlyError> {
    let dir = dataset.join("staging");
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Ok(None);
    };
    let mut names: Vec<PathBuf> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("shard-") && n.ends_with(".json"))
        })
        .collect();
    names.sort();
    let mut first: Option<(PathBuf, Vec<PathBuf>)> = None;
    for p in names {
        let r = read_sealed::<ShardRecord>(&p)
            .map_err(|why| {
                NightlyError::Invalid(format!(
                    "{}: {why} (run that shard again, or give the archives to --commit)",
                    p.display()
                ))
            })?
            .ok_or_else(|| NightlyError::io(&p)(std::io::ErrorKind::NotFound.into()))?;
        match &first {
            None => first = Some((p, r.archives)),
            Some((q, archives)) if *archives != r.archives => {
                return Err(NightlyError::Invalid(format!(
                    "{} and {} name different archives ({} and {}): run the shards \
                     again with the same archives, or give the archives to --commit",
                    q.display(),
                    p.display(),
                    show_paths(archives),
                    show_paths(&r.archives)
                )));
            }
            Some(_) => {}
        }
    }
    Ok(first.map(|(_, archives)| archives))
}

fn show_paths(paths: &[PathBuf]) -> String {
    let shown: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
    shown.join(", ")
}

/// `value` as pretty JSON sealed with its checksum (`checksum::seal_json`).
fn sealed<T: Serialize>(value: &T) -> String {
    crate::ingest::checksum::seal_json(
        &serde_json::to_string_pretty(value).expect("plain data serialises"),
    )
}

/// A record `sealed` wrote, or `None` when there is no file; the error says
/// what is wrong with one that is there (unreadable, not JSON, checksum).
fn read_sealed<T: serde::de::DeserializeOwned>(path: &Path) -> Result<Option<T>, String> {
    let text = match std::fs::read(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e.to_string()),
    };
    parse_sealed(&text).map(Some)
}

/// The value a file `sealed` wrote, its checksum checked; the error says
/// what is wrong (not JSON, the checksum, a field).
fn parse_sealed<T: serde::de::DeserializeOwned>(text: &[u8]) -> Result<T, String> {
    let head: serde_json::Value = serde_json::from_slice(text).map_err(|e| e.to_string())?;
    let text = String::from_utf8_lossy(text);
    if let Some(why) = crate::ingest::checksum::json_mismatch(&text, &head, "tirewear process") {
        return Err(why);
    }
    serde_json::from_value(head).map_err(|e| e.to_string())
}

/// Processes `runs` and stages their parts (and each touched track's road
/// part); returns the runs whose parts are staged. A run that fails is
/// recorded in the summary and staged as a failure for `--commit`. A part
/// that cannot be written (a full disk) is no fault of the run's inputs:
/// it ends the night with an error after the other runs are staged, before
/// any commit, so the run is neither dropped from the dataset nor reported
/// as failed; the parts staged are reused by the next night.
fn stage_runs<'a>(
    opts: &ProcessOptions,
    seasons: &[Season],
    inputs: &[SeasonInputs],
    runs: &[&'a Planned],
    reducer: &dyn ReduceEngine,
    summary: &mut ProcessSummary,
) -> Result<Vec<&'a Planned>, NightlyError> {
    let dataset = &opts.dataset;
    let pb = crate::progress::bar(opts.progress, runs.len() as u64, "processing runs");
    let mut done = Vec::new();
    let memory = crate::memory::MemoryBudget::resolve(opts.memory_limit);
    // The first part that could not be written, which ends the night.
    let mut unwritten: Option<NightlyError> = None;
    for (si, season) in seasons.iter().enumerate() {
        let mine: Vec<&Planned> = runs.iter().copied().filter(|p| p.season == si).collect();
        if mine.is_empty() {
            continue;
        }
        let inp = &inputs[si];
        let mut warnings = inp.warnings.clone();
        // Only the tracks these runs are on.
        let needed: BTreeSet<&str> = mine.iter().map(|p| p.track.as_str()).collect();
        let t = Instant::now();
        let (roads, curves) = road_kpis(season, Some(&needed), &mut warnings, reducer)?;
        tracing::debug!(
            "road indices of {} in {:.2} s",
            season.manifest.name,
            t.elapsed().as_secs_f64()
        );
        summary.warnings.extend(warnings);
        // Road parts of the tracks these runs are on.
        let tracks: BTreeMap<&str, &str> = mine
            .iter()
            .map(|p| (p.track.as_str(), p.road_key.as_str()))
            .collect();
        for (track, key) in tracks {
            let path = staged_road(dataset, key);
            if path.exists() && !opts.force {
                continue;
            }
            let own: Vec<_> = curves
                .iter()
                .filter(|(p, _)| p.track == track)
                .cloned()
                .collect();
            let batch = road_curves_batch(&own);
            crate::atomic::write_file(&path, |f| write_part_to(f, &batch))
                .map_err(NightlyError::io(&path))?;
        }
        let ctx = RunContext {
            season,
            compounds: &inp.compounds,
            roads: &roads,
            wear: &inp.wear,
            wear_problems: &inp.wear_problems,
            memory: &memory,
        };
        let plain: Vec<&Run> = mine.iter().map(|p| &p.run).collect();
        // The GPU reduces one run while the next are decoded (`extract_runs`).
        let pipelined = reducer.name() == "gpu";
        let results: Vec<(&Planned, StagedRun)> =
            extract_runs(&ctx, &plain, reducer, pipelined, |i, out| {
                let staged = stage_one(dataset, mine[i], out);
                pb.inc(1);
                (mine[i], staged)
            });
        for (p, staged) in results {
            summary.warnings.extend(staged.warnings);
            summary.telemetry_bytes += staged.telemetry_bytes;
            match staged.result {
                Ok(()) => done.push(p),
                Err(RunFault::Write(e)) => {
                    tracing::error!("run {}: {e}", p.run.id);
                    unwritten.get_or_insert(e);
                }
                Err(RunFault::Input(reason)) => {
                    tracing::warn!("run {} failed: {reason}", p.run.id);
                    let f = Failed {
                        run: p.run.id.clone(),
                        season: season.manifest.name.clone(),
                        reason,
                        kept: false,
                    };
                    let path = staged_failure(dataset, &p.key);
                    let text = sealed(&f);
                    crate::atomic::write_bytes(&path, text.as_bytes())
                        .map_err(NightlyError::io(&path))?;
                    summary.failed.push(f);
                }
            }
        }
        // The other seasons' parts would meet the same full disk.
        if unwritten.is_some() {
            break;
        }
    }
    pb.finish_and_clear();
    match unwritten {
        Some(e) => Err(e),
        None => Ok(done),
    }
}

/// Why a run was not staged.
enum RunFault {
    /// Its inputs could not be read or processed: the run failed.
    Input(String),
    /// Its processed parts could not be written: the night fails.
    Write(NightlyError),
}

/// One run's outcome: staged, or why not.
struct StagedRun {
    result: Result<(), RunFault>,
    warnings: Vec<String>,
    telemetry_bytes: u64,
}

/// Stages the parts of a run that extracted, with its warnings.
fn stage_one(dataset: &Path, p: &Planned, out: Result<RunOutput, String>) -> StagedRun {
    match out {
        Ok(o) => StagedRun {
            warnings: o.missing_wear_warnings(),
            telemetry_bytes: o.bytes,
            result: write_run_parts(dataset, &p.key, &p.run.id, o),
        },
        Err(reason) => StagedRun {
            result: Err(RunFault::Input(reason)),
            warnings: vec![],
            telemetry_bytes: 0,
        },
    }
}

/// Stages a run's three parts; the KPI part last, since it marks the run
/// staged only once all three exist.
fn write_run_parts(dataset: &Path, key: &str, run: &str, o: RunOutput) -> Result<(), RunFault> {
    let mut energy = Vec::with_capacity(o.maps.len());
    let mut conditions = Vec::with_capacity(o.maps.len());
    for (w, e, c) in o.maps {
        energy.push((run.to_string(), w, e));
        conditions.push((run.to_string(), w, c));
    }
    let batches = [
        ("energy_maps", energy_maps_batch(&energy)),
        (
            "condition_maps",
            crate::kpi::cpu::condition_map::side_table(&conditions),
        ),
        ("kpis", kpi_batch(&o.rows)),
    ];
    for (kind, batch) in batches {
        let path = staged_part(dataset, kind, key);
        crate::atomic::write_file(&path, |f| write_part_to(f, &batch))
            .map_err(|e| RunFault::Write(NightlyError::io(&path)(e)))?;
    }
    Ok(())
}

/// `dataset.json`'s text: pretty JSON ending with its checksum field
/// (`ingest::checksum::seal_json`), checked by [`read_manifest`].
fn manifest_text(m: &DatasetManifest) -> String {
    sealed(m)
}

fn write_manifest(dataset: &Path, m: &DatasetManifest) -> Result<(), NightlyError> {
    let path = dataset.join("dataset.json");
    let text = manifest_text(m);
    crate::atomic::write_bytes(&path, text.as_bytes()).map_err(NightlyError::io(&path))
}

/// The schema of each consolidated table when it has no rows.
fn empty_schema(kind: &str) -> arrow_schema::SchemaRef {
    match kind {
        "kpis" => kpi_batch(&[]).schema(),
        "energy_maps" => energy_maps_batch(&[]).schema(),
        "condition_maps" => crate::kpi::cpu::condition_map::side_table(&[]).schema(),
        _ => road_curves_batch(&[]).schema(),
    }
}

/// Each run's rows (offset, count) in a consolidated table.
type RunRanges = BTreeMap<String, (usize, usize)>;

/// Where a consolidated table takes one run's rows from.
enum Source {
    /// A part file (staged, or committed).
    Part(PathBuf),
    /// Rows `offset..offset + len` of the previous consolidated table.
    Previous { offset: usize, len: usize },
}

/// The previous commit's consolidated table at `path` and the rows of each
/// run in it, if it is that commit's (its id) and each run's rows are
/// contiguous; otherwise None, and the parts are read instead.
fn previous_table(path: &Path, dataset_id: &str) -> Option<(RecordBatch, RunRanges)> {
    use arrow_array::Array;
    if dataset_id.is_empty() || crate::kpi::table::read_extraction_id(path).ok()?? != dataset_id {
        return None;
    }
    let batches = read_batches(path).ok()?;
    let schema = batches.first()?.schema();
    let all = arrow_select::concat::concat_batches(&schema, &batches).ok()?;
    let runs = all
        .column_by_name("run")?
        .as_any()
        .downcast_ref::<arrow_array::StringArray>()?;
    let mut ranges = RunRanges::new();
    let mut i = 0;
    while i < runs.len() {
        let run = runs.value(i);
        let start = i;
        while i < runs.len() && runs.value(i) == run {
            i += 1;
        }
        if ranges.insert(run.to_string(), (start, i - start)).is_some() {
            return None; // not contiguous: not a table this module wrote
        }
    }
    Some((all, ranges))
}

/// One table from its sources, in order, tagged with the dataset id; also
/// the number of rows each source gave.
fn consolidate(
    kind: &str,
    sources: &[Source],
    previous: Option<&RecordBatch>,
    dataset_id: &str,
) -> Result<(arrow_schema::SchemaRef, Vec<RecordBatch>, Vec<usize>), NightlyError> {
    let schema = empty_schema(kind);
    let read = sources
        .par_iter()
        .map(|s| match s {
            Source::Part(p) => read_batches(p).map(|bs| (Some(p), bs)),
            Source::Previous { offset, len } => {
                let prev = previous.expect("previous rows come with the previous table");
                Ok((None, vec![prev.slice(*offset, *len)]))
            }
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut batches = Vec::new();
    let mut rows = Vec::with_capacity(sources.len());
    for (p, bs) in read {
        rows.push(bs.iter().map(|b| b.num_rows()).sum());
        for b in bs {
            // Parts carry no metadata; take the columns under the table's schema.
            let b = RecordBatch::try_new(schema.clone(), b.columns().to_vec()).map_err(|e| {
                let from = p.map_or("the previous table".to_string(), |p| {
                    p.display().to_string()
                });
                NightlyError::Invalid(format!("{from}: rows do not fit the {kind} table: {e}"))
            })?;
            batches.push(b);
        }
    }
    // The table's schema with the dataset id; the batches are written in
    // turn under it, not concatenated first (a copy of the whole table).
    let schema = with_extraction_id(RecordBatch::new_empty(schema), dataset_id).schema();
    Ok((schema, batches, rows))
}

/// The consolidated table of a kind.
fn table_path(dataset: &Path, kind: &str) -> PathBuf {
    dataset.join(match kind {
        "kpis" => "kpis.parquet".to_string(),
        k => format!("kpis.{k}.parquet"),
    })
}

/// Commits `new`: staged parts moved into place, consolidated tables
/// rebuilt from the parts, `dataset.json` last, all behind one journal;
/// then parts no longer named are removed.
fn commit(
    dataset: &Path,
    old: &DatasetManifest,
    new: &mut DatasetManifest,
    runs: &[(RunEntry, Option<&Planned>)],
) -> Result<(), NightlyError> {
    let journal = dataset.join(".commit.json");
    let mut set = OutputSet::new(&journal).map_err(NightlyError::io(&journal))?;
    let mkdir = |p: &Path| -> Result<(), NightlyError> {
        let dir = p.parent().expect("part paths have a folder");
        std::fs::create_dir_all(dir).map_err(NightlyError::io(dir))
    };
    // Each table takes an unchanged run's rows from the previous table (one
    // file read instead of a part per run), a new run's from its staged part.
    let previous: Vec<_> = PART_KINDS
        .par_iter()
        .map(|kind| previous_table(&table_path(dataset, kind), &old.dataset_id))
        .collect();
    let mut sources: Vec<(&str, Vec<Source>)> = Vec::with_capacity(4);
    for (kind, prev) in PART_KINDS.iter().zip(&previous) {
        let mut from = Vec::with_capacity(runs.len());
        for (e, staged) in runs {
            let dest = committed_part(dataset, kind, e);
            match (staged, prev) {
                (Some(p), _) => {
                    let part = staged_part(dataset, kind, &p.key);
                    mkdir(&dest)?;
                    set.add_move(&part, &dest);
                    from.push(Source::Part(part));
                }
                (None, Some((_, ranges))) if ranges.contains_key(&e.run) => {
                    let (offset, len) = ranges[&e.run];
                    from.push(Source::Previous { offset, len });
                }
                (None, _) => from.push(Source::Part(dest)),
            }
        }
        sources.push((kind, from));
    }
    let old_roads: BTreeMap<&str, &str> = old
        .roads
        .iter()
        .map(|r| (r.track.as_str(), r.key.as_str()))
        .collect();
    let mut road_sources = Vec::new();
    for r in &new.roads {
        let dest = committed_road(dataset, &r.track);
        let staged = staged_road(dataset, &r.key);
        if old_roads.get(r.track.as_str()) == Some(&r.key.as_str()) && dest.exists() {
            road_sources.push(Source::Part(dest));
        } else if staged.exists() {
            mkdir(&dest)?;
            set.add_move(&staged, &dest);
            road_sources.push(Source::Part(staged));
        } else {
            tracing::warn!(
                "track {}: no road part staged; its curves are left out of kpis.road.parquet",
                r.track
            );
        }
    }
    sources.push(("road", road_sources));
    // The four tables are read and encoded side by side.
    let id = new.dataset_id.clone();
    let tables = sources
        .par_iter()
        .enumerate()
        .map(|(i, (kind, parts))| {
            let t = Instant::now();
            let prev = previous.get(i).and_then(|p| p.as_ref()).map(|(b, _)| b);
            let (schema, batches, rows) = consolidate(kind, parts, prev, &id)?;
            let read_s = t.elapsed().as_secs_f64();
            let mut bytes = Vec::new();
            write_batches_to(&mut bytes, &schema, &batches)
                .map_err(|e| NightlyError::Invalid(format!("encoding {kind}: {e}")))?;
            tracing::debug!(
                "{kind}: {} sources read in {read_s:.2} s, {} rows encoded in {:.2} s",
                parts.len(),
                rows.iter().sum::<usize>(),
                t.elapsed().as_secs_f64() - read_s
            );
            Ok((*kind, bytes, rows))
        })
        .collect::<Result<Vec<_>, NightlyError>>()?;
    for (kind, bytes, rows) in tables {
        if kind == "kpis" {
            for (e, n) in new.runs.iter_mut().zip(rows) {
                e.rows = n;
            }
        }
        let dest = table_path(dataset, kind);
        set.add(&dest, |f| std::io::Write::write_all(f, &bytes))
            .map_err(NightlyError::io(&dest))?;
    }
    let path = dataset.join("dataset.json");
    let text = manifest_text(new);
    set.add(&path, |f| std::io::Write::write_all(f, text.as_bytes()))
        .map_err(NightlyError::io(&path))?;
    set.commit().map_err(NightlyError::io(&journal))
}

/// Removes committed parts that `m` no longer names (removed or renamed
/// runs, a kill between commit and clean-up) and empty partition folders.
fn remove_unnamed_parts(dataset: &Path, m: &DatasetManifest) -> Result<(), NightlyError> {
    let mut keep: BTreeSet<PathBuf> = BTreeSet::new();
    for e in &m.runs {
        for kind in PART_KINDS {
            keep.insert(committed_part(dataset, kind, e));
        }
    }
    for r in &m.roads {
        keep.insert(committed_road(dataset, &r.track));
    }
    for kind in PART_KINDS.iter().chain(&["road"]) {
        sweep(&dataset.join(kind), &keep)?;
    }
    Ok(())
}

fn sweep(dir: &Path, keep: &BTreeSet<PathBuf>) -> Result<(), NightlyError> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(());
    };
    for e in entries.flatten() {
        let p = e.path();
        if e.file_type().is_ok_and(|t| t.is_dir()) {
            sweep(&p, keep)?;
            // Only succeeds when empty.
            let _ = std::fs::remove_dir(&p);
        } else if !keep.contains(&p) {
            std::fs::remove_file(&p).map_err(NightlyError::io(&p))?;
        }
    }
    Ok(())
}

/// Empties `staging/` after a commit (parts were moved; what is left is
/// failures and shard records that the commit has read).
fn clean_staging(dataset: &Path) -> Result<(), NightlyError> {
    let dir = dataset.join("staging");
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Ok(());
    };
    for e in entries.flatten() {
        let p = e.path();
        std::fs::remove_file(&p).map_err(NightlyError::io(&p))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A part whose data no longer match its checksum is refused in the
    /// nightly form: the file named once, what was wrong, what to do.
    #[test]
    fn a_damaged_part_is_named_once_with_what_to_do() {
        use arrow_array::{Float64Array, RecordBatch};
        let values = Float64Array::from_iter_values((0..40).map(f64::from));
        let batch =
            RecordBatch::try_from_iter([("wear_pct", std::sync::Arc::new(values) as _)]).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("part.parquet");
        let mut bytes = Vec::new();
        crate::kpi::table::write_part_to(&mut bytes, &batch).unwrap();
        std::fs::write(&path, &bytes).unwrap();
        assert_eq!(read_batches(&path).unwrap(), [batch]);
        bytes[40] ^= 0x10;
        std::fs::write(&path, &bytes).unwrap();
        let e = read_batches(&path).unwrap_err().to_string();
        let name = path.display().to_string();
        assert!(
            e.starts_with(&format!("{name}: damaged part: data checksum: bytes 0..")),
            "{e}"
        );
        assert!(
            e.ends_with("(delete it and it is made again on the next run)"),
            "{e}"
        );
        assert_eq!(e.matches(&name).count(), 1, "{e}");
        std::fs::remove_file(&path).unwrap();
        assert!(matches!(read_batches(&path), Err(NightlyError::Io { .. })));
    }

    #[test]
    fn ids_become_safe_path_names() {
        assert_eq!(path_name("r001"), "r001");
        assert_eq!(path_name("a/b"), "a%2Fb");
        assert_eq!(path_name(".."), "%2E%2E");
        assert_eq!(path_name("x y"), "x%20y");
    }

    #[test]
    fn shards_split_the_runs_stably_and_evenly() {
        let count = 4;
        let mut sizes = [0usize; 4];
        for i in 0..4000 {
            let run = format!("r{i:04}");
            let s = shard_of("season", &run, count);
            assert_eq!(s, shard_of("season", &run, count), "stable");
            sizes[s as usize] += 1;
        }
        // A fair split puts 1000 ± 3·sqrt(750) ≈ 82 in each.
        assert!(
            sizes.iter().all(|&n| (900..=1100).contains(&n)),
            "{sizes:?}"
        );
    }
}
