//! `tirewear process`: incremental, resumable, sharded reprocessing.
//!
//! The independent route is `extract`: a processed dataset must hold the
//! same KPI rows as one extraction of the same archive, whatever was
//! changed, killed or sharded on the way there.

use rand::{Rng, SeedableRng};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use tirewear::kpi::{ExtractOptions, KpiRow, extract, table};
use tirewear::nightly::{Mode, NightlyError, ProcessOptions, ProcessSummary, process};

mod common;

use common::simulate_tiny as tiny;

/// Holds the dataset's lock as another process would: its own open file.
fn hold_lock(dataset: &Path) -> std::fs::File {
    std::fs::create_dir_all(dataset).unwrap();
    let holder = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(dataset.join(".lock"))
        .unwrap();
    holder.lock().unwrap();
    holder
}

fn run(archive: &Path, dataset: &Path) -> ProcessSummary {
    process(&ProcessOptions::new(vec![archive.to_path_buf()], dataset)).unwrap()
}

/// Rows keyed by (run, wheel), every number as its bits (NaN equals NaN).
fn keyed(rows: Vec<KpiRow>) -> BTreeMap<(String, tirewear::Wheel), String> {
    rows.into_iter()
        .map(|r| ((r.run.clone(), r.wheel), format!("{r:?}")))
        .collect()
}

/// The rows one plain extraction of `archive` gives.
fn extracted(archive: &Path, scratch: &Path) -> BTreeMap<(String, tirewear::Wheel), String> {
    let out = scratch.join("extract.parquet");
    extract(&ExtractOptions::new(archive, &out)).unwrap();
    keyed(table::read_parquet(&out).unwrap())
}

fn processed_rows(dataset: &Path) -> BTreeMap<(String, tirewear::Wheel), String> {
    keyed(table::read_parquet(&dataset.join("kpis.parquet")).unwrap())
}

/// Every file under `dir` with its bytes, `summary.json` (timings) left out.
fn tree(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.file_name().unwrap() != "summary.json" {
                out.insert(
                    p.strip_prefix(dir).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                );
            }
        }
    }
    out
}

fn names(t: &BTreeMap<PathBuf, Vec<u8>>) -> Vec<String> {
    t.keys().map(|p| p.display().to_string()).collect()
}

#[test]
fn process_equals_extract_and_only_changed_runs_are_processed_again() {
    let dir = tempfile::tempdir().unwrap();
    let archive = dir.path().join("season");
    let dataset = dir.path().join("dataset");
    tiny(&archive, 11);

    let s = run(&archive, &dataset);
    assert_eq!((s.planned, s.processed, s.unchanged), (4, 4, 0));
    assert!(s.committed && s.failed.is_empty());
    assert_eq!(processed_rows(&dataset), extracted(&archive, dir.path()));
    // One id ties the consolidated tables together, and fit/gap's check passes.
    let kpis = dataset.join("kpis.parquet");
    for side in ["road", "energy_maps", "condition_maps"] {
        table::check_same_extraction(&kpis, &dataset.join(format!("kpis.{side}.parquet"))).unwrap();
    }
    assert_eq!(
        table::read_extraction_id(&kpis).unwrap().as_deref(),
        Some(s.dataset_id.as_str())
    );
    // The partitioned view: one part per run and kind, under event=….
    let t = tree(&dataset);
    let parts: Vec<String> = names(&t)
        .into_iter()
        .filter(|n| n.starts_with("kpis/event="))
        .collect();
    assert_eq!(parts.len(), 4, "{parts:?}");

    // A rerun processes nothing and rewrites nothing.
    let s = run(&archive, &dataset);
    assert_eq!((s.planned, s.processed, s.unchanged), (4, 0, 4));
    assert!(!s.committed);
    assert_eq!(s.hashed_bytes, 0, "unchanged stamps: no file is read again");
    assert_eq!(tree(&dataset), t);

    // A changed wear reading reprocesses its run only.
    let season = tirewear::ingest::manifest::Season::open(&archive).unwrap();
    let wear_path = season.path(&season.manifest.wear_readings[0]);
    let mut readings = tirewear::ingest::wear::read_wear_csv(&wear_path).unwrap();
    let target = readings[0].run.clone();
    readings[0].depth_mm -= 0.5;
    tirewear::ingest::wear::write_wear_csv(&wear_path, &readings).unwrap();
    let s = run(&archive, &dataset);
    assert_eq!(s.runs_processed, vec![target.clone()]);
    assert_eq!((s.processed, s.unchanged), (1, 3));
    assert_eq!(processed_rows(&dataset), extracted(&archive, dir.path()));

    // So does a changed telemetry file (another run's recording copied over it).
    let runs = &season.manifest.runs;
    let (a, b) = (&runs[1], &runs[2]);
    std::fs::copy(season.path(&b.telemetry), season.path(&a.telemetry)).unwrap();
    let s = run(&archive, &dataset);
    assert_eq!(s.runs_processed, vec![a.id.clone()]);
    assert_eq!(processed_rows(&dataset), extracted(&archive, dir.path()));
    // Those commits spliced the unchanged runs' rows from the previous
    // tables; a fresh dataset built from parts alone has the same bytes.
    let fresh = dir.path().join("fresh");
    run(&archive, &fresh);
    let (t, f) = (tree(&dataset), tree(&fresh));
    for table in [
        "kpis.parquet",
        "kpis.energy_maps.parquet",
        "kpis.condition_maps.parquet",
        "kpis.road.parquet",
    ] {
        let p = PathBuf::from(table);
        assert!(t[&p] == f[&p], "{table} differs from a rebuild from parts");
    }

    // A run removed from the archive leaves the dataset, parts and rows.
    let mut m = season.manifest.clone();
    let gone = m.runs.remove(3);
    m.write(&season.manifest_path).unwrap();
    let s = run(&archive, &dataset);
    assert_eq!((s.processed, s.removed), (0, 1));
    let rows = processed_rows(&dataset);
    assert!(rows.keys().all(|(r, _)| *r != gone.id));
    assert_eq!(rows.len(), 12);
    let t = tree(&dataset);
    assert_eq!(
        names(&t).iter().filter(|n| n.starts_with("kpis/")).count(),
        3
    );
    assert_eq!(
        names(&t)
            .iter()
            .filter(|n| n.starts_with("staging/"))
            .count(),
        0,
        "staging is emptied at commit"
    );
}

#[test]
fn dry_run_writes_nothing_and_force_reprocesses() {
    let dir = tempfile::tempdir().unwrap();
    let archive = dir.path().join("season");
    let dataset = dir.path().join("dataset");
    tiny(&archive, 12);
    let mut opts = ProcessOptions::new(vec![archive.clone()], &dataset);
    opts.dry_run = true;
    let s = process(&opts).unwrap();
    assert_eq!(s.runs_processed.len(), 4);
    assert!(!dataset.exists(), "a dry run creates nothing");
    // It names the run that needs the most memory, to size a job by.
    let season = tirewear::ingest::manifest::Season::open(&archive).unwrap();
    let (big, need, _) = common::hungriest_run(&season);
    let largest = s.largest_memory_need.unwrap();
    assert_eq!((largest.run, largest.bytes), (big.id, need));
    run(&archive, &dataset);
    let before = tree(&dataset);
    opts.dry_run = false;
    opts.force = true;
    let s = process(&opts).unwrap();
    assert_eq!(s.processed, 4);
    assert_eq!(tree(&dataset), before, "same inputs, same bytes");
}

/// A dataset folder that is the archive's folder, or holds it, is refused
/// before anything is written: `process demo --out demo` once swept the
/// archive's road profiles away as stale parts. A dataset inside the
/// archive's folder is allowed and leaves the archive's files as they were.
#[test]
fn a_dataset_in_the_archive_folder_or_around_it_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let archive = dir.path().join("season");
    tiny(&archive, 12);
    let before = tree(&archive);
    for (dataset, how) in [
        (archive.clone(), "is the season archive"),
        (archive.join("."), "is the season archive"),
        (dir.path().to_path_buf(), "holds the season archive"),
    ] {
        let mut opts = ProcessOptions::new(vec![archive.join("season.toml")], &dataset);
        for dry_run in [true, false] {
            opts.dry_run = dry_run;
            match process(&opts) {
                Err(NightlyError::Invalid(e)) => assert!(e.contains(how), "{e}"),
                other => panic!("{}: {:?}", dataset.display(), other.map(|s| s.processed)),
            }
        }
        assert_eq!(tree(&archive), before, "{}", dataset.display());
    }
    let inside = archive.join("dataset");
    assert_eq!(run(&archive, &inside).processed, 4);
    let after = tree(&archive);
    let archive_files: BTreeMap<_, _> = after
        .into_iter()
        .filter(|(p, _)| !p.starts_with("dataset"))
        .collect();
    assert_eq!(archive_files, before);
}

#[test]
fn a_second_writer_is_refused_while_the_dataset_is_locked() {
    let dir = tempfile::tempdir().unwrap();
    let archive = dir.path().join("season");
    let dataset = dir.path().join("dataset");
    tiny(&archive, 13);
    let holder = hold_lock(&dataset);
    std::fs::write(dataset.join(".lock"), "pid 42 on testhost").unwrap();
    match process(&ProcessOptions::new(vec![archive.clone()], &dataset)) {
        Err(NightlyError::Locked { holder, .. }) => assert!(holder.contains("pid 42"), "{holder}"),
        other => panic!("expected Locked, got {other:?}"),
    }
    // Shards share the lock with each other, not with a whole run.
    let mut shard = ProcessOptions::new(vec![archive.clone()], &dataset);
    shard.mode = Mode::Shard { index: 0, count: 2 };
    assert!(matches!(process(&shard), Err(NightlyError::Locked { .. })));
    holder.unlock().unwrap();
    let s = process(&ProcessOptions::new(vec![archive], &dataset)).unwrap();
    assert_eq!(s.processed, 4);
}

#[test]
fn shards_then_commit_equal_one_whole_run() {
    let dir = tempfile::tempdir().unwrap();
    let archive = dir.path().join("season");
    tiny(&archive, 14);
    let whole = dir.path().join("whole");
    run(&archive, &whole);
    let sharded = dir.path().join("sharded");
    let count = 3;
    let mut processed = 0;
    for index in 0..count {
        let mut o = ProcessOptions::new(vec![archive.clone()], &sharded);
        o.mode = Mode::Shard { index, count };
        let s = process(&o).unwrap();
        assert!(!s.committed);
        processed += s.processed;
    }
    assert_eq!(processed, 4, "every run in exactly one shard");
    assert!(
        !sharded.join("kpis.parquet").exists(),
        "shards commit nothing"
    );
    // The commit takes the archives from the shards' records.
    let mut c = ProcessOptions::new(vec![], &sharded);
    c.mode = Mode::Commit;
    let s = process(&c).unwrap();
    assert_eq!((s.processed, s.reused_staged), (0, 4));
    assert_eq!(tree(&sharded), tree(&whole));

    // A commit with a shard missing reports its runs and commits the rest.
    let partial = dir.path().join("partial");
    let mut o = ProcessOptions::new(vec![archive.clone()], &partial);
    o.mode = Mode::Shard { index: 0, count: 2 };
    let staged = process(&o).unwrap().processed;
    let mut c = ProcessOptions::new(vec![archive.clone()], &partial);
    c.mode = Mode::Commit;
    let s = process(&c).unwrap();
    assert_eq!(s.failed.len(), 4 - staged);
    assert!(s.failed[0].reason.contains("no shard"), "{:?}", s.failed);
    // The next whole run finishes the job.
    let s = run(&archive, &partial);
    assert_eq!(s.processed, 4 - staged);
    assert_eq!(tree(&partial), tree(&whole));
}

/// What the shards leave for the commit is checked: a changed byte in a
/// shard's record or in a run's staged failure is named, and shards given
/// different archives are refused rather than half committed.
#[test]
fn damaged_or_disagreeing_shard_records_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let archive = dir.path().join("season");
    tiny(&archive, 16);
    let season = tirewear::ingest::manifest::Season::open(&archive).unwrap();
    let bad = &season.manifest.runs[0];
    std::fs::write(season.path(&bad.telemetry), b"not an mcap file").unwrap();
    let dataset = dir.path().join("dataset");
    let shard = |archive: &Path, index: u32| {
        let mut o = ProcessOptions::new(vec![archive.to_path_buf()], &dataset);
        o.mode = Mode::Shard { index, count: 2 };
        process(&o).unwrap()
    };
    let commit = || {
        let mut c = ProcessOptions::new(vec![], &dataset);
        c.mode = Mode::Commit;
        process(&c)
    };
    shard(&archive, 0);
    shard(&archive, 1);
    let staging = dataset.join("staging");
    let record = staging.join("shard-1-of-2.json");
    let failure = std::fs::read_dir(&staging)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.to_string_lossy().ends_with(".failed.json"))
        .expect("the bad run's failure is staged");
    let text = std::fs::read_to_string(&record).unwrap();
    let good_failure = std::fs::read_to_string(&failure).unwrap();

    // One letter of an archive's path changed: refused, naming the record.
    let path = archive.to_str().unwrap();
    assert!(text.contains(path));
    let moved = text.replacen(path, &path.replace("/season", "/seasoN"), 1);
    std::fs::write(&record, moved).unwrap();
    let e = commit().unwrap_err().to_string();
    assert!(e.contains("shard-1-of-2.json"), "{e}");
    assert!(e.contains("damaged or edited"), "{e}");
    assert!(!dataset.join("kpis.parquet").exists(), "nothing committed");

    // The failure's reason edited: the commit still fails that run, and
    // says its record is damaged instead of repeating the edited reason.
    std::fs::write(&record, &text).unwrap();
    std::fs::write(&failure, good_failure.replacen("mcap", "MCAP", 1)).unwrap();
    let s = commit().unwrap();
    assert_eq!(s.failed.len(), 1);
    assert_eq!(s.failed[0].run, bad.id);
    assert!(s.failed[0].reason.contains("is damaged"), "{:?}", s.failed);
    assert_eq!(processed_rows(&dataset).len(), 12);

    // Shard 2 given another archive (a copy, so its runs are the same):
    // the records disagree, and the commit says so.
    let copy = dir.path().join("copy");
    common::copy_dir(&archive, &copy);
    shard(&archive, 0);
    shard(&copy, 1);
    let e = commit().unwrap_err().to_string();
    assert!(e.contains("name different archives"), "{e}");
    assert!(e.contains("shard-2-of-2.json"), "{e}");
}

#[test]
fn a_failed_run_is_reported_and_the_rest_committed() {
    let dir = tempfile::tempdir().unwrap();
    let archive = dir.path().join("season");
    let dataset = dir.path().join("dataset");
    tiny(&archive, 15);
    let season = tirewear::ingest::manifest::Season::open(&archive).unwrap();
    let bad = &season.manifest.runs[2];
    std::fs::write(season.path(&bad.telemetry), b"not an mcap file").unwrap();
    let s = run(&archive, &dataset);
    assert_eq!(s.failed.len(), 1);
    assert_eq!(s.failed[0].run, bad.id);
    assert!(s.committed);
    assert_eq!(processed_rows(&dataset).len(), 12);
    // Retried the next night, and still failing it changes nothing else.
    let s = run(&archive, &dataset);
    assert_eq!((s.processed, s.unchanged, s.failed.len()), (1, 3, 1));
}

/// Before 2026-12-02 a committed run that failed on a later night (its
/// telemetry cut short by a sync half done, gone with a mount) was dropped
/// from the dataset: with every file damaged the night committed an empty
/// dataset. Now a failed run keeps its last committed rows (`kept`, and
/// the reason says so) and, its key still the old one, is tried again; the
/// files put back, it is unchanged. A kept run whose parts are damaged is
/// left out, with a warning naming the part. Sharded, the commit does the
/// same.
#[test]
fn a_committed_run_that_fails_later_keeps_its_rows() {
    let dir = tempfile::tempdir().unwrap();
    let archive = dir.path().join("season");
    let dataset = dir.path().join("dataset");
    tiny(&archive, 21);
    run(&archive, &dataset);
    let before = processed_rows(&dataset);
    assert_eq!(before.len(), 16);
    let season = tirewear::ingest::manifest::Season::open(&archive).unwrap();
    let runs = &season.manifest.runs;
    let originals: Vec<(PathBuf, Vec<u8>)> = runs
        .iter()
        .map(|r| {
            let p = season.path(&r.telemetry);
            let bytes = std::fs::read(&p).unwrap();
            (p, bytes)
        })
        .collect();
    let damage = |i: usize| {
        let (p, bytes) = &originals[i];
        std::fs::write(p, &bytes[..bytes.len() / 2]).unwrap();
    };
    let restore = || {
        for (p, bytes) in &originals {
            std::fs::write(p, bytes).unwrap();
        }
    };

    // Every file cut short: four failures, every row kept.
    (0..4).for_each(damage);
    let s = run(&archive, &dataset);
    assert_eq!(
        (s.processed, s.failed.len(), s.rows),
        (4, 4, 16),
        "{:?}",
        s.failed
    );
    for f in &s.failed {
        assert!(f.kept, "{f:?}");
        assert!(
            f.reason.contains("is truncated") || f.reason.contains("past the end"),
            "{f:?}"
        );
        assert!(
            f.reason
                .ends_with("its rows from the last commit are kept until it is processed")
        );
    }
    assert_eq!(processed_rows(&dataset), before);
    // Tried again the next night, still failing.
    let s = run(&archive, &dataset);
    assert_eq!((s.processed, s.failed.len()), (4, 4));
    // One file gone altogether (fails before processing): kept as well.
    std::fs::remove_file(&originals[0].0).unwrap();
    let s = run(&archive, &dataset);
    assert_eq!((s.processed, s.failed.len()), (3, 4));
    assert!(s.failed.iter().all(|f| f.kept), "{:?}", s.failed);
    assert_eq!(processed_rows(&dataset), before);
    // The files put back: nothing to process, the dataset as it was.
    restore();
    let s = run(&archive, &dataset);
    assert_eq!((s.processed, s.unchanged, s.failed.len()), (0, 4, 0));
    assert_eq!(processed_rows(&dataset), before);

    // A failed run whose committed part is damaged too: left out, named.
    damage(1);
    let part = std::fs::read_dir(dataset.join("kpis"))
        .unwrap()
        .flatten()
        .flat_map(|e| std::fs::read_dir(e.path()).unwrap().flatten())
        .map(|e| e.path())
        .find(|p| {
            p.file_name()
                .unwrap()
                .to_str()
                .unwrap()
                .starts_with(&runs[1].id)
        })
        .unwrap();
    std::fs::write(&part, b"not parquet").unwrap();
    let s = run(&archive, &dataset);
    assert_eq!((s.failed.len(), s.rows), (1, 12), "{:?}", s.failed);
    assert!(!s.failed[0].kept);
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains(&format!("run {} failed", runs[1].id))
                && w.contains(&part.display().to_string())
                && w.contains("left out")),
        "{:?}",
        s.warnings
    );
    assert!(
        !processed_rows(&dataset)
            .keys()
            .any(|(r, _)| *r == runs[1].id)
    );
    restore();
    let s = run(&archive, &dataset);
    assert_eq!((s.processed, s.failed.len(), s.rows), (1, 0, 16));
    assert_eq!(processed_rows(&dataset), before);

    // Sharded: the run fails in its shard and the commit keeps its rows.
    damage(2);
    for index in 0..2 {
        let mut o = ProcessOptions::new(vec![archive.clone()], &dataset);
        o.mode = Mode::Shard { index, count: 2 };
        process(&o).unwrap();
    }
    let mut c = ProcessOptions::new(vec![], &dataset);
    c.mode = Mode::Commit;
    let s = process(&c).unwrap();
    assert_eq!(s.failed.len(), 1, "{:?}", s.failed);
    assert_eq!(s.failed[0].run, runs[2].id);
    assert!(s.failed[0].kept);
    assert_eq!(processed_rows(&dataset), before);
}

/// A run that alone needs more memory than the budget fails by name (its
/// file, its need, the budget and the flag to raise it) instead of the
/// night being killed; the others commit, and the next night, with the
/// budget found from the machine, processes it and equals an extraction.
#[test]
fn a_run_above_the_memory_budget_fails_by_name_and_the_rest_commit() {
    use tirewear::memory::MemoryLimit;
    let dir = tempfile::tempdir().unwrap();
    let archive = dir.path().join("season");
    let dataset = dir.path().join("dataset");
    tiny(&archive, 16);
    let season = tirewear::ingest::manifest::Season::open(&archive).unwrap();
    let (big, largest, next) = common::hungriest_run(&season);
    assert!(next < largest);
    let s = process(&ProcessOptions {
        memory_limit: MemoryLimit::Bytes(largest - 1),
        ..ProcessOptions::new(vec![archive.clone()], &dataset)
    })
    .unwrap();
    assert_eq!(s.failed.len(), 1, "{:?}", s.failed);
    assert_eq!(s.failed[0].run, big.id);
    let why = &s.failed[0].reason;
    for part in [big.telemetry.as_str(), "of memory", "--memory-limit"] {
        assert!(why.contains(part), "{why}");
    }
    assert!(s.committed);
    assert_eq!(
        processed_rows(&dataset).len(),
        4 * (season.manifest.runs.len() - 1)
    );
    let s = run(&archive, &dataset);
    assert_eq!((s.processed, s.failed.len()), (1, 0), "{:?}", s.failed);
    assert_eq!(processed_rows(&dataset), extracted(&archive, dir.path()));
}

/// A part that cannot be written (a full disk; here a file-size limit,
/// which makes writes past 8 KiB fail with EFBIG) ends the night with an
/// error naming it, before any commit. The run is not reported or recorded
/// as failed (its inputs are fine: before, it was, and a run whose inputs
/// had changed was dropped from the commit); the committed dataset is left
/// as it was; the next night, with room, commits the change.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[test]
fn a_part_that_cannot_be_written_fails_the_night_not_the_run() {
    use std::os::unix::process::CommandExt;
    let dir = tempfile::tempdir().unwrap();
    let archive = dir.path().join("season");
    let dataset = dir.path().join("dataset");
    tiny(&archive, 23);
    run(&archive, &dataset);
    let committed = |d: &Path| {
        let mut t = tree(d);
        t.retain(|p, _| !p.starts_with("staging") && !p.ends_with("summary.json"));
        t
    };
    let before = committed(&dataset);
    // One run's wear reading changed: that run is processed again.
    let season = tirewear::ingest::manifest::Season::open(&archive).unwrap();
    let wear = season.path(&season.manifest.wear_readings[0]);
    let mut readings = tirewear::ingest::wear::read_wear_csv(&wear).unwrap();
    readings[0].depth_mm -= 0.25;
    tirewear::ingest::wear::write_wear_csv(&wear, &readings).unwrap();
    let mut night = std::process::Command::new(env!("CARGO_BIN_EXE_tirewear"));
    night
        .args([
            "--quiet", "--log", "error", "process", "--engine", "cpu", "--out",
        ])
        .arg(&dataset)
        .arg(&archive);
    // SAFETY: between fork and exec only async-signal-safe calls
    // (signal, setrlimit); ignoring SIGXFSZ makes an oversized write fail
    // with EFBIG instead of killing the process.
    unsafe {
        night.pre_exec(|| {
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            let limit = libc::rlimit {
                rlim_cur: 8192,
                rlim_max: 8192,
            };
            if libc::setrlimit(libc::RLIMIT_FSIZE, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let out = night.output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("staging") && err.contains("os error 27"),
        "the part and the OS's error named: {err}"
    );
    assert!(!err.contains("failed:"), "{err}");
    let records: Vec<_> = std::fs::read_dir(dataset.join("staging"))
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().ends_with(".failed.json"))
        .collect();
    assert!(records.is_empty(), "no failure recorded: {records:?}");
    assert_eq!(committed(&dataset), before, "the last commit stands");
    // The next night, with room: the change is committed.
    let s = run(&archive, &dataset);
    assert!(s.committed && s.failed.is_empty(), "{:?}", s.failed);
    assert_eq!(s.processed, 1);
    assert_eq!(
        processed_rows(&dataset),
        extracted(&archive, dir.path()),
        "the dataset is the plain extraction's"
    );
}

/// SIGKILL at random moments, then a run to the end: the dataset is the
/// uninterrupted run's, byte for byte, with no temporary file left.
#[cfg(unix)]
#[test]
fn killed_at_random_moments_and_rerun_is_byte_identical() {
    let dir = tempfile::tempdir().unwrap();
    let archive = dir.path().join("season");
    tiny(&archive, 16);
    let exe = env!("CARGO_BIN_EXE_tirewear");
    let cmd = |dataset: &Path| {
        let mut c = std::process::Command::new(exe);
        c.args([
            "--quiet", "--log", "error", "process", "--engine", "cpu", "--out",
        ])
        .arg(dataset)
        .arg(&archive)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null());
        c
    };
    let whole = dir.path().join("whole");
    let t0 = std::time::Instant::now();
    assert!(cmd(&whole).status().unwrap().success());
    let full = t0.elapsed();
    let reference = tree(&whole);

    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2026);
    // Kills that left a dataset begun but not finished: the case under test.
    let mut interrupted = 0;
    for attempt in 0..6 {
        let killed = dir.path().join(format!("killed{attempt}"));
        // Several kills in a row on the same dataset, each at a random moment.
        for _ in 0..3 {
            let mut child = cmd(&killed).spawn().unwrap();
            let wait = full.mul_f64(rng.random_range(0.0..1.2));
            std::thread::sleep(wait);
            let _ = child.kill();
            child.wait().unwrap();
            if killed.exists() && tree(&killed) != reference {
                interrupted += 1;
            }
        }
        assert!(cmd(&killed).status().unwrap().success());
        let t = tree(&killed);
        let leftovers: Vec<String> = names(&t)
            .into_iter()
            .filter(|n| n.contains(".tmp") || n.starts_with("staging/") || n.contains("commit"))
            .collect();
        assert!(leftovers.is_empty(), "left behind: {leftovers:?}");
        assert_eq!(names(&t), names(&reference));
        assert!(t == reference, "attempt {attempt}: bytes differ");
    }
    eprintln!("{interrupted} of 18 kills left an unfinished dataset");
    assert!(interrupted >= 3, "only {interrupted} kills landed mid-run");
}

#[test]
fn an_unreadable_archive_or_file_fails_only_its_own_runs() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    tiny(&a, 17);
    tiny(&b, 18);
    // Two seasons in one dataset need distinct run ids: rename b's.
    let season_b = tirewear::ingest::manifest::Season::open(&b).unwrap();
    let mut m = season_b.manifest.clone();
    for r in &mut m.runs {
        r.id = format!("b-{}", r.id);
    }
    m.write(&season_b.manifest_path).unwrap();
    let wear_b = season_b.path(&m.wear_readings[0]);
    let mut readings = tirewear::ingest::wear::read_wear_csv(&wear_b).unwrap();
    for r in &mut readings {
        r.run = format!("b-{}", r.run);
    }
    tirewear::ingest::wear::write_wear_csv(&wear_b, &readings).unwrap();

    let dataset = dir.path().join("dataset");
    let both = || ProcessOptions::new(vec![a.clone(), b.clone()], &dataset);
    let s = process(&both()).unwrap();
    assert_eq!((s.processed, s.failed.len()), (8, 0), "{:?}", s.failed);
    let before = processed_rows(&dataset);

    // Archive b unreadable (its manifest gone): a's run still processed,
    // b's committed rows kept, the failure named.
    let manifest = season_b.manifest_path.clone();
    std::fs::rename(&manifest, manifest.with_extension("away")).unwrap();
    let season_a = tirewear::ingest::manifest::Season::open(&a).unwrap();
    let wear_a = season_a.path(&season_a.manifest.wear_readings[0]);
    let mut ra = tirewear::ingest::wear::read_wear_csv(&wear_a).unwrap();
    ra[0].depth_mm -= 0.25;
    tirewear::ingest::wear::write_wear_csv(&wear_a, &ra).unwrap();
    let s = process(&both()).unwrap();
    assert_eq!(s.processed, 1);
    assert_eq!(s.removed, 0);
    assert_eq!(s.failed.len(), 1);
    assert!(s.failed[0].season.ends_with("b"), "{:?}", s.failed);
    let rows = processed_rows(&dataset);
    assert_eq!(rows.len(), 32);
    let b_rows = |r: &BTreeMap<(String, tirewear::Wheel), String>| {
        r.iter()
            .filter(|((run, _), _)| run.starts_with("b-"))
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect::<Vec<_>>()
    };
    assert_eq!(b_rows(&rows), b_rows(&before));
    std::fs::rename(manifest.with_extension("away"), &manifest).unwrap();

    // A telemetry file gone: that run fails (its committed rows kept),
    // every other one is unchanged.
    let gone = &season_a.manifest.runs[0];
    std::fs::remove_file(season_a.path(&gone.telemetry)).unwrap();
    let s = process(&both()).unwrap();
    assert_eq!((s.processed, s.unchanged, s.failed.len()), (0, 7, 1));
    assert_eq!(s.failed[0].run, gone.id);
    assert!(s.failed[0].kept);
    assert_eq!(processed_rows(&dataset).len(), 32);
    assert!(
        s.failed[0].reason.contains(&gone.telemetry),
        "{}",
        s.failed[0].reason
    );

    // A committed part deleted by hand is made again.
    let part = std::fs::read_dir(dataset.join("kpis"))
        .unwrap()
        .flatten()
        .flat_map(|e| std::fs::read_dir(e.path()).unwrap().flatten())
        .map(|e| e.path())
        .find(|p| p.file_name().unwrap().to_str().unwrap().starts_with("b-"))
        .unwrap();
    std::fs::remove_file(&part).unwrap();
    let s = process(&both()).unwrap();
    assert_eq!(s.processed, 1);
    assert!(part.exists());
}

/// A committed part or consolidated table damaged after its commit (cut
/// short, overwritten) costs only its run: the next run reports it by name,
/// processes that run again and leaves the dataset byte-identical to the
/// undamaged one. Before, it stopped every later commit.
#[test]
fn a_damaged_part_or_table_is_made_again() {
    let dir = tempfile::tempdir().unwrap();
    let archive = dir.path().join("season");
    let dataset = dir.path().join("dataset");
    tiny(&archive, 19);
    run(&archive, &dataset);
    let t = tree(&dataset);
    let part = |kind: &str, i: usize| -> PathBuf {
        let n = names(&t)
            .into_iter()
            .filter(|n| n.starts_with(&format!("{kind}/event=")))
            .nth(i)
            .unwrap();
        dataset.join(n)
    };
    let cut = |p: &Path| {
        let bytes = std::fs::read(p).unwrap();
        std::fs::write(p, &bytes[..bytes.len() / 2]).unwrap();
    };
    let zero = |p: &Path| {
        let len = std::fs::metadata(p).unwrap().len() as usize;
        std::fs::write(p, vec![0u8; len]).unwrap();
    };
    let named = |s: &ProcessSummary, p: &Path| {
        let p = p.display().to_string();
        assert!(
            s.warnings.iter().any(|w| w.starts_with(&p)),
            "no warning names {p}: {:?}",
            s.warnings
        );
    };

    // Two runs' parts: one cut short, one overwritten with zeros.
    let (kpi_part, map_part) = (part("kpis", 0), part("energy_maps", 2));
    cut(&kpi_part);
    zero(&map_part);
    let s = run(&archive, &dataset);
    assert_eq!((s.processed, s.unchanged, s.failed.len()), (2, 2, 0));
    named(&s, &kpi_part);
    named(&s, &map_part);
    assert_eq!(tree(&dataset), t);

    // The consolidated table alone: nothing to process, but it is rebuilt.
    let kpis = dataset.join("kpis.parquet");
    cut(&kpis);
    let s = run(&archive, &dataset);
    assert_eq!((s.processed, s.unchanged), (0, 4));
    assert!(s.committed);
    named(&s, &kpis);
    assert_eq!(tree(&dataset), t);

    // Both at once: the commit cannot splice from the table, and the
    // damaged part is not read but made again.
    let cond_part = part("condition_maps", 1);
    cut(&kpis);
    zero(&cond_part);
    let s = run(&archive, &dataset);
    assert_eq!((s.processed, s.unchanged, s.failed.len()), (1, 3, 0));
    named(&s, &cond_part);
    assert_eq!(tree(&dataset), t);
    assert_eq!(processed_rows(&dataset), extracted(&archive, dir.path()));

    // One bit flipped inside a part's data, then inside the table's: the
    // footers still parse, the checksums tell; the run is processed again
    // and the table rebuilt.
    let flip = |p: &Path| {
        use parquet::file::reader::{FileReader, SerializedFileReader};
        let reader = SerializedFileReader::new(std::fs::File::open(p).unwrap()).unwrap();
        let covered: usize = reader
            .metadata()
            .file_metadata()
            .key_value_metadata()
            .and_then(|kv| {
                kv.iter()
                    .find(|kv| kv.key == "tirewear.data_crc32")
                    .cloned()
            })
            .and_then(|kv| kv.value)
            .and_then(|v| v.split(' ').next()?.parse().ok())
            .unwrap();
        let mut bytes = std::fs::read(p).unwrap();
        bytes[covered / 2] ^= 0x04;
        std::fs::write(p, bytes).unwrap();
    };
    let flipped = part("kpis", 3);
    flip(&flipped);
    let s = run(&archive, &dataset);
    assert_eq!((s.processed, s.unchanged, s.failed.len()), (1, 3, 0));
    named(&s, &flipped);
    assert_eq!(tree(&dataset), t);
    flip(&kpis);
    let s = run(&archive, &dataset);
    assert_eq!((s.processed, s.unchanged), (0, 4));
    named(&s, &kpis);
    assert_eq!(tree(&dataset), t);

    // The manifest itself: refused by name with what to do, nothing
    // changed; once it is moved aside, the next run makes the same dataset.
    let manifest = dataset.join("dataset.json");
    cut(&manifest);
    let damaged = tree(&dataset);
    let e = process(&ProcessOptions::new(vec![archive.clone()], &dataset))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("dataset.json: not a tirewear dataset manifest"),
        "{e}"
    );
    assert!(e.contains("move the file aside"), "{e}");
    assert_eq!(tree(&dataset), damaged);
    std::fs::remove_file(&manifest).unwrap();
    let s = run(&archive, &dataset);
    assert_eq!(s.processed, 4);
    assert_eq!(tree(&dataset), t);

    // A digit changed in the manifest is still a valid manifest: its
    // checksum refuses it, nothing changed.
    let text = std::fs::read_to_string(&manifest).unwrap();
    let at = text.find("\"rows\": ").unwrap() + "\"rows\": ".len();
    let mut changed = text.into_bytes();
    changed[at] = if changed[at] == b'9' {
        b'8'
    } else {
        changed[at] + 1
    };
    std::fs::write(&manifest, &changed).unwrap();
    let damaged = tree(&dataset);
    let e = process(&ProcessOptions::new(vec![archive.clone()], &dataset))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("dataset.json: not a tirewear dataset manifest: data_crc32"),
        "{e}"
    );
    assert_eq!(tree(&dataset), damaged);
}

/// The documented exit codes: 4 while another process holds the dataset,
/// 3 when some runs failed and the rest were committed, 0 otherwise.
#[test]
fn exit_codes_of_the_binary() {
    let dir = tempfile::tempdir().unwrap();
    let archive = dir.path().join("season");
    let dataset = dir.path().join("dataset");
    tiny(&archive, 19);
    let exe = env!("CARGO_BIN_EXE_tirewear");
    let run = || {
        std::process::Command::new(exe)
            .args([
                "--quiet", "--log", "error", "process", "--engine", "cpu", "--out",
            ])
            .arg(&dataset)
            .arg(&archive)
            .output()
            .unwrap()
    };
    let holder = hold_lock(&dataset);
    let out = run();
    assert_eq!(out.status.code(), Some(4));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("locked by another tirewear process"), "{err}");
    holder.unlock().unwrap();

    let season = tirewear::ingest::manifest::Season::open(&archive).unwrap();
    let bad = &season.manifest.runs[1];
    std::fs::write(season.path(&bad.telemetry), b"garbage").unwrap();
    let out = run();
    assert_eq!(out.status.code(), Some(3));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains(&format!("failed run {}", bad.id)), "{text}");
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dataset.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["failed"][0]["run"], bad.id.as_str());
    assert_eq!(summary["processed"], 4);

    let out = std::process::Command::new(exe)
        .args(["process", "--shard", "5/4", "--out"])
        .arg(&dataset)
        .arg(&archive)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "a bad --shard is a usage error");
    for bad in [
        &["--keep-results", "0", "--then", "gap"][..],
        &["--keep-results", "2"],
        &["--memory-limit", "0"],
        &["--memory-limit", "8X"],
        &["--memory-limit", "-1G"],
    ] {
        let out = std::process::Command::new(exe)
            .arg("process")
            .args(bad)
            .arg("--out")
            .arg(&dataset)
            .arg(&archive)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{bad:?} is a usage error");
    }
}

/// The names of the folders under `dir/sub`, in name order.
fn stamp_folders(dir: &Path, sub: &str) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir.join(sub))
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// The files directly under `dir/sub/*/` (the dated folders `--then`
/// writes), by name.
fn dated_files(dir: &Path, sub: &str) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir.join(sub))
        .into_iter()
        .flatten()
        .flatten()
        .flat_map(|stamp| std::fs::read_dir(stamp.path()).unwrap().flatten())
        .map(|f| f.file_name().to_string_lossy().into_owned())
        .filter(|n| !n.starts_with('.'))
        .collect();
    names.sort();
    names
}

/// `--then fit,gap,report`: a step that fails stops neither the commit nor
/// the other steps; the report is skipped rather than shown beside an older
/// night's models or gap; exit 3 names what was not done; the next night
/// runs what was not done, though nothing changed.
#[test]
fn a_failed_then_step_stops_neither_the_commit_nor_the_others() {
    let dir = tempfile::tempdir().unwrap();
    let exe = env!("CARGO_BIN_EXE_tirewear");
    let process = |archive: &Path, dataset: &Path| {
        let out = std::process::Command::new(exe)
            .args(["--quiet", "--log", "error", "process", "--engine", "cpu"])
            .args(["--then", "fit,gap,report", "--keep-results", "1", "--out"])
            .arg(dataset)
            .arg(archive)
            .output()
            .unwrap();
        let text = |b: &[u8]| String::from_utf8_lossy(b).into_owned();
        (out.status.code(), text(&out.stdout), text(&out.stderr))
    };
    let dry_run = |archive: &Path, dataset: &Path| {
        let out = std::process::Command::new(exe)
            .args(["--quiet", "--log", "error", "process", "--dry-run"])
            .args(["--then", "fit,gap,report", "--out"])
            .arg(dataset)
            .arg(archive)
            .output()
            .unwrap();
        String::from_utf8_lossy(&out.stdout).into_owned()
    };

    // The tiny season (4 runs, 16 tires on two events): the physical
    // model's design is singular and the gap diagnosis needs more than 20
    // tires; the network and PCA fit.
    let archive = dir.path().join("tiny");
    let dataset = dir.path().join("tiny-dataset");
    tiny(&archive, 19);
    // An earlier night's results, which a failed step does not prune.
    let earlier = |dataset: &Path, sub: &str, stamp: &str| {
        let d = dataset.join(sub).join(stamp);
        std::fs::create_dir_all(&d).unwrap();
        std::fs::write(d.join("earlier.json"), "{}").unwrap();
    };
    earlier(&dataset, "gap", "2020-01-01T0000Z");
    earlier(&dataset, "models", "2020-01-01T0000Z");
    let (code, out, err) = process(&archive, &dataset);
    assert_eq!(code, Some(3), "{out}\n{err}");
    assert!(!out.contains("--keep-results"), "nothing pruned: {out}");
    assert_eq!(
        processed_rows(&dataset),
        extracted(&archive, dir.path()),
        "the commit stands"
    );
    // Physical fails, PCA fits; each model written is one not named as failed.
    assert!(out.contains("Physical model not fitted"), "{out}");
    let written = dated_files(&dataset, "models");
    assert!(written.contains(&"pca.json".to_string()), "{written:?}");
    assert!(written.contains(&"earlier.json".to_string()), "{written:?}");
    // The network keeps 15 inputs for 16 rows: its adjusted R² is
    // undefined ("–"), and the model is written all the same.
    assert!(written.contains(&"ffnn.json".to_string()), "{out}");
    for (method, file) in [
        ("Ffnn", "ffnn.json"),
        ("Pca", "pca.json"),
        ("Physical", "physical.json"),
    ] {
        let failed = out.contains(&format!("{method} model not fitted"));
        assert_eq!(
            written.contains(&file.to_string()),
            !failed,
            "{method}: {out}"
        );
    }
    assert!(err.contains("--then gap failed"), "{err}");
    assert_eq!(dated_files(&dataset, "gap"), ["earlier.json"]);
    assert!(err.contains("--then report skipped: gap failed"), "{err}");
    assert!(!dataset.join("report").exists());
    assert!(
        out.contains("--then: not done: fit (some methods), gap, report (skipped)"),
        "{out}"
    );
    // The next night, seconds later: `fit` runs again, into a folder of
    // its own (the same minute's folder, before stamps had seconds).
    let tonight = stamp_folders(&dataset, "models");
    let (code, out, err) = process(&archive, &dataset);
    assert_eq!(code, Some(3), "{out}\n{err}");
    let next = stamp_folders(&dataset, "models");
    assert_eq!(next.len(), 3, "{tonight:?} then {next:?}");
    assert!(tonight.iter().all(|s| next.contains(s)), "{next:?}");
    // `fit` alone: the same two models, exit 3.
    let fit = std::process::Command::new(exe)
        .args(["--quiet", "--log", "error", "fit"])
        .arg(dataset.join("kpis.parquet"))
        .arg("--out")
        .arg(dir.path().join("models"))
        .output()
        .unwrap();
    assert_eq!(fit.status.code(), Some(3));
    assert!(dir.path().join("models/pca.json").exists());
    assert!(!dir.path().join("models/physical.json").exists());

    // The demo season into a dataset whose `models` is a plain file: `fit`
    // fails before fitting, and the gap diagnosis is still written.
    let archive = dir.path().join("demo");
    let dataset = dir.path().join("demo-dataset");
    common::simulate_demo(&archive);
    std::fs::create_dir_all(&dataset).unwrap();
    std::fs::write(dataset.join("models"), "not a folder").unwrap();
    earlier(&dataset, "gap", "2020-01-01T0000Z");
    earlier(&dataset, "gap", "2020-01-02T0000Z");
    let (code, out, err) = process(&archive, &dataset);
    assert_eq!(code, Some(3), "{out}\n{err}");
    assert!(dataset.join("dataset.json").exists());
    assert!(
        err.contains("--then fit failed: ")
            && err.contains(
                "models, which is a file, not a folder: fit cannot make its folder there"
            ),
        "{err}"
    );
    // The gap succeeded: tonight's folder is the one kept.
    assert_eq!(dated_files(&dataset, "gap"), ["gap.json", "gap.md"]);
    assert!(
        out.contains("--keep-results 1: removed") && out.contains("2020-01-02T0000Z"),
        "{out}"
    );
    assert!(err.contains("--then report skipped: fit failed"), "{err}");
    assert!(!dataset.join("report").exists());

    // The next night, nothing changed: the steps the first did not finish
    // on this dataset run now, the gap is not diagnosed again (a dry run
    // says so first).
    std::fs::remove_file(dataset.join("models")).unwrap();
    let dry_out = dry_run(&archive, &dataset);
    assert!(
        dry_out.contains("--then: would run fit, report (not done on dataset"),
        "{dry_out}"
    );
    let (code, out, err) = process(&archive, &dataset);
    assert_eq!(code, Some(0), "{out}\n{err}");
    assert!(out.contains("nothing to commit"), "{out}");
    assert!(out.contains("--then: gap already done on dataset"), "{out}");
    assert!(
        out.contains("--then: fit, report not done on dataset") && out.contains("running now"),
        "{out}"
    );
    assert_eq!(
        dated_files(&dataset, "models"),
        ["ffnn.json", "pca.json", "physical.json"]
    );
    assert_eq!(dated_files(&dataset, "report"), ["report.html"]);
    // And the night after: nothing left to do.
    let (code, out, err) = process(&archive, &dataset);
    assert_eq!(code, Some(0), "{out}\n{err}");
    assert!(
        out.contains("--then: fit, gap, report already done on dataset"),
        "{out}"
    );
    assert!(!out.contains("running now"), "{out}");
    let dry_out = dry_run(&archive, &dataset);
    assert!(dry_out.contains("--then: nothing to run"), "{dry_out}");
}

/// A night stopped during its `--then` steps (SIGKILL once its commit is
/// done): the next night, with nothing changed, runs every step and tidies
/// what a stopped night leaves in a dated folder of its own. While the
/// steps run, the dataset stays locked.
#[cfg(unix)]
#[test]
fn a_night_stopped_during_its_steps_is_finished_by_the_next() {
    let dir = tempfile::tempdir().unwrap();
    let archive = dir.path().join("demo");
    let dataset = dir.path().join("dataset");
    common::simulate_demo(&archive);
    let exe = env!("CARGO_BIN_EXE_tirewear");
    let cmd = || {
        let mut c = std::process::Command::new(exe);
        c.args(["--quiet", "--log", "error", "process", "--engine", "cpu"])
            .args(["--then", "fit,gap,report", "--keep-results", "1", "--out"])
            .arg(&dataset)
            .arg(&archive);
        c
    };
    let mut child = cmd()
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // then.json is written once the commit is done, before the first step.
    let record = dataset.join("then.json");
    let t0 = std::time::Instant::now();
    while !record.exists() {
        assert!(
            child.try_wait().unwrap().is_none(),
            "ended before its commit"
        );
        assert!(t0.elapsed().as_secs() < 600, "no commit in 10 min");
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    // The lock is held through the steps: a second writer is refused.
    let second = std::process::Command::new(exe)
        .args([
            "--quiet", "--log", "error", "process", "--engine", "cpu", "--out",
        ])
        .arg(&dataset)
        .arg(&archive)
        .output()
        .unwrap();
    assert_eq!(second.status.code(), Some(4), "a writer beside the steps");
    child.kill().unwrap();
    assert!(!child.wait().unwrap().success(), "the steps ended first");
    assert!(dataset.join("dataset.json").exists());
    // What a kill inside a write leaves: a dead writer's temporary file
    // (pid 0 is never a user process) in a folder no later night writes to.
    let stopped = dataset.join("models/2020-01-01T0000Z");
    std::fs::create_dir_all(&stopped).unwrap();
    std::fs::write(stopped.join(".tirewear-0-abc.tmp"), "half").unwrap();

    let out = cmd().output().unwrap();
    let (text, err) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert_eq!(out.status.code(), Some(0), "{text}\n{err}");
    assert!(text.contains("nothing to commit"), "{text}");
    assert!(
        text.contains("--then: fit, gap, report not done on dataset")
            && text.contains("running now"),
        "{text}"
    );
    assert!(
        text.contains(&format!("removed {}", stopped.display())),
        "{text}"
    );
    assert!(!stopped.exists());
    assert_eq!(
        dated_files(&dataset, "models"),
        ["ffnn.json", "pca.json", "physical.json"]
    );
    assert_eq!(dated_files(&dataset, "gap"), ["gap.json", "gap.md"]);
    assert_eq!(dated_files(&dataset, "report"), ["report.html"]);
}
