//! Atomic output files: write to a temporary file in the destination folder,
//! then rename over the destination. A crash or an error leaves either the
//! old file or the new one, never half of one.
//!
//! [`OutputSet`] does the same for several files that belong together (the
//! KPI table and its side tables): all are written first, then a journal
//! naming them is written, then they are renamed into place. A process killed
//! during the renames leaves the journal, and the next writer of that set
//! finishes them ([`recover`]). Temporary files carry their writer's process
//! id, so the next writer removes those of dead processes ([`remove_orphans`]).

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

/// The folder a path lies in ("." for a bare file name).
pub(crate) fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Temporary files are named `.tirewear-<pid>-<random>.tmp`.
const TMP_PREFIX: &str = ".tirewear-";
const TMP_SUFFIX: &str = ".tmp";

/// A file being written; it appears under its final name only on [`AtomicFile::commit`].
/// Dropping it without committing removes the temporary file.
pub(crate) struct AtomicFile {
    tmp: tempfile::NamedTempFile,
    dest: PathBuf,
}

impl AtomicFile {
    /// Starts writing `dest`, creating its parent folder if needed.
    pub fn create(dest: &Path) -> io::Result<Self> {
        let parent = folder_of(dest);
        std::fs::create_dir_all(parent)?;
        let mut builder = tempfile::Builder::new();
        let prefix = format!("{TMP_PREFIX}{}-", std::process::id());
        builder.prefix(&prefix).suffix(TMP_SUFFIX);
        // Temporary files are private (0600); the finished file gets ordinary permissions.
        #[cfg(unix)]
        builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o644));
        let tmp = builder.tempfile_in(parent)?;
        Ok(Self {
            tmp,
            dest: dest.to_path_buf(),
        })
    }

    /// The open temporary file (readable, writable and seekable).
    pub fn file(&mut self) -> &mut File {
        self.tmp.as_file_mut()
    }

    /// Flushes to disk and renames the file to its final name.
    pub fn commit(self) -> io::Result<()> {
        self.tmp.as_file().sync_all()?;
        self.tmp.persist(&self.dest).map_err(|e| e.error)?;
        Ok(())
    }
}

/// An output that cannot go where it was asked to, found before any work:
/// its destination is a folder, is named for two outputs, or is one of the
/// command's inputs (the rename would replace what is being read).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Clash {
    pub dest: PathBuf,
    pub reason: String,
}

impl std::fmt::Display for Clash {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.dest.display(), self.reason)
    }
}

impl std::error::Error for Clash {}

/// The directory entry a rename onto `path` replaces: the folder resolved
/// (symbolic links, `.`, `..`), the last name kept as it is, since a rename
/// replaces a link itself rather than what it points at.
pub(crate) fn entry_of(path: &Path) -> PathBuf {
    let folder = folder_of(path);
    let folder = std::fs::canonicalize(folder)
        .or_else(|_| std::path::absolute(folder))
        .unwrap_or_else(|_| folder.to_path_buf());
    match path.file_name() {
        Some(name) => folder.join(name),
        None => std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf()),
    }
}

/// Checks that the outputs (what each is, where it goes) can be written
/// without harm: none is an existing folder, no two share a destination,
/// none replaces an input (what it is, its path; a link counts for both
/// itself and the file it points at). Hard links need no check: the rename
/// gives the destination a new file and leaves the input's untouched.
pub fn check_destinations(
    outputs: &[(&str, &Path)],
    inputs: &[(String, PathBuf)],
) -> Result<(), Clash> {
    let clash = |dest: &Path, reason: String| Clash {
        dest: dest.to_path_buf(),
        reason,
    };
    let mut read = std::collections::HashMap::new();
    for (what, path) in inputs {
        read.entry(entry_of(path)).or_insert(what);
        if let Ok(target) = std::fs::canonicalize(path) {
            read.entry(target).or_insert(what);
        }
    }
    let mut written: std::collections::HashMap<PathBuf, &str> = std::collections::HashMap::new();
    for &(what, dest) in outputs {
        let is_folder = std::fs::symlink_metadata(dest).is_ok_and(|m| m.is_dir());
        if is_folder {
            return Err(clash(
                dest,
                format!("is a folder; the {what} is written to a file: give a file's path"),
            ));
        }
        if let Some(file) = file_above(dest) {
            return Err(clash(
                dest,
                format!(
                    "is inside {}, which is a file, not a folder: the {what} cannot be \
                     written there",
                    file.display()
                ),
            ));
        }
        let entry = entry_of(dest);
        if let Some(input) = read.get(&entry) {
            return Err(clash(
                dest,
                format!(
                    "is an input of this command ({input}): the {what} would replace it; \
                     give another path"
                ),
            ));
        }
        if let Some(first) = written.insert(entry, what) {
            return Err(clash(
                dest,
                format!("is named for both the {first} and the {what}: give them different paths"),
            ));
        }
    }
    Ok(())
}

/// As [`check_destinations`] for one output, which may replace an existing
/// regular file only where `replaceable` says so from its first bytes
/// (`Err` says what the file is instead): a page replaces only a page, a
/// bench result only an earlier one. A FIFO or device is not opened (the
/// open would wait); the rename replaces its entry.
pub(crate) fn check_replaceable(
    dest: &Path,
    output: &str,
    inputs: &[(String, PathBuf)],
    kind: &str,
    replaceable: impl FnOnce(&[u8]) -> Result<(), String>,
) -> Result<(), Clash> {
    check_destinations(&[(output, dest)], inputs)?;
    if !std::fs::metadata(dest).is_ok_and(|m| m.is_file()) {
        return Ok(());
    }
    let refuse = |reason: String| Clash {
        dest: dest.to_path_buf(),
        reason,
    };
    // Enough to tell a file's kind by its magic or first line.
    const HEAD_BYTES: u64 = 256;
    let head = crate::ingest::read_head(dest, HEAD_BYTES)
        .map_err(|e| refuse(crate::ingest::unnamed(dest, e)))?;
    replaceable(&head).map_err(|what| {
        refuse(format!(
            "exists and is not {kind} ({what}): the {output} would replace it; give another path"
        ))
    })
}

/// The nearest existing folder above `dest` when it is something else (a
/// file): the folders a write would make cannot be made there.
pub fn file_above(dest: &Path) -> Option<&Path> {
    let existing = folder_of(dest)
        .ancestors()
        .find(|a| a.as_os_str().is_empty() || std::fs::metadata(a).is_ok())?;
    let is_folder = existing.as_os_str().is_empty() || existing.is_dir();
    (!is_folder).then_some(existing)
}

/// Writes a whole file atomically through a buffered writer.
pub(crate) fn write_with(
    dest: &Path,
    body: impl FnOnce(&mut BufWriter<&mut File>) -> io::Result<()>,
) -> io::Result<()> {
    let mut out = AtomicFile::create(dest)?;
    {
        let mut w = BufWriter::new(out.file());
        body(&mut w)?;
        w.flush()?;
    }
    out.commit()
}

/// Writes a whole file atomically through the open file itself (for writers
/// that need to seek, such as Parquet's).
pub(crate) fn write_file(
    dest: &Path,
    body: impl FnOnce(&mut File) -> io::Result<()>,
) -> io::Result<()> {
    let mut out = AtomicFile::create(dest)?;
    body(out.file())?;
    out.commit()
}

/// Rows as CSV (header from the field names) into a writer.
pub(crate) fn csv_to<T: serde::Serialize>(w: impl Write, rows: &[T]) -> io::Result<()> {
    let mut c = csv::Writer::from_writer(w);
    for r in rows {
        c.serialize(r)?;
    }
    c.flush()
}

/// Writes serialisable rows as CSV (header from the field names), atomically.
pub fn write_csv<T: serde::Serialize>(dest: &Path, rows: &[T]) -> io::Result<()> {
    write_with(dest, |w| csv_to(w, rows))
}

/// Writes bytes to `dest` atomically.
pub fn write_bytes(dest: &Path, bytes: &[u8]) -> io::Result<()> {
    write_with(dest, |w| w.write_all(bytes))
}

/// Files that become visible together: each is written to a temporary file
/// by [`OutputSet::add`]; [`OutputSet::commit`] renames them all into place
/// behind a journal. Dropped without commit, the temporary files are removed
/// and the destinations keep their old contents.
pub struct OutputSet {
    journal: PathBuf,
    /// (temporary path, destination), written and synced.
    files: Vec<(tempfile::TempPath, PathBuf)>,
    /// (finished file, destination): renamed at commit, kept if dropped.
    moves: Vec<(PathBuf, PathBuf)>,
}

impl OutputSet {
    /// A set whose journal is `journal`; an earlier set's interrupted commit
    /// is finished first and dead writers' temporary files are removed.
    pub fn new(journal: &Path) -> io::Result<Self> {
        recover(journal)?;
        remove_orphans(folder_of(journal))?;
        Ok(Self {
            journal: journal.to_path_buf(),
            files: Vec::new(),
            moves: Vec::new(),
        })
    }

    /// Writes `dest`'s new contents to a temporary file beside it.
    pub(crate) fn add(
        &mut self,
        dest: &Path,
        body: impl FnOnce(&mut File) -> io::Result<()>,
    ) -> io::Result<()> {
        self.check_new(dest)?;
        let mut f = AtomicFile::create(dest)?;
        body(f.file())?;
        f.file().sync_all()?;
        self.files
            .push((f.tmp.into_temp_path(), dest.to_path_buf()));
        Ok(())
    }

    /// Moves the finished, synced file `from` to `dest` at commit (a part
    /// staged by an earlier process); dropped without commit, `from` stays.
    pub(crate) fn add_move(&mut self, from: &Path, dest: &Path) {
        self.moves.push((from.to_path_buf(), dest.to_path_buf()));
    }

    /// Refuses a destination already written in the set: its second file
    /// would silently replace the first at commit. (Staged parts, moved
    /// under names their writer makes unique and many thousands in a large
    /// night, are not compared: a path resolved for each would slow the
    /// commit for no case a user can cause.)
    fn check_new(&self, dest: &Path) -> io::Result<()> {
        let entry = entry_of(dest);
        if self.files.iter().any(|(_, d)| entry_of(d) == entry) {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("{}: named twice in one set of outputs", dest.display()),
            ));
        }
        Ok(())
    }

    /// Renames every file into place: the journal first, so a kill at any
    /// moment leaves either the old set (no journal) or a journal that the
    /// next writer completes.
    pub fn commit(self) -> io::Result<()> {
        let pairs: Vec<(PathBuf, PathBuf)> = self
            .moves
            .iter()
            .cloned()
            .chain(self.files.iter().map(|(t, d)| (t.to_path_buf(), d.clone())))
            .collect();
        // A folder in a file's place would fail its rename halfway through
        // the set: refused before the journal, nothing is replaced.
        for (_, dest) in &pairs {
            if std::fs::symlink_metadata(dest).is_ok_and(|m| m.is_dir()) {
                return Err(io::Error::new(
                    io::ErrorKind::IsADirectory,
                    format!(
                        "{}: is a folder, not a file; nothing was replaced",
                        dest.display()
                    ),
                ));
            }
        }
        let text = serde_json::to_vec(&pairs).map_err(io::Error::other)?;
        write_bytes(&self.journal, &text)?;
        for (from, dest) in &self.moves {
            std::fs::rename(from, dest)?;
        }
        for (tmp, dest) in self.files {
            tmp.persist(&dest).map_err(|e| e.error)?;
        }
        std::fs::remove_file(&self.journal)
    }
}

/// Writes whole files (destination, bytes) as one [`OutputSet`] behind
/// `journal`: they become visible together.
pub(crate) fn write_set(journal: &Path, files: &[(&Path, &[u8])]) -> io::Result<()> {
    let mut set = OutputSet::new(journal)?;
    for (dest, bytes) in files {
        set.add(dest, |f| f.write_all(bytes))?;
    }
    set.commit()
}

/// Finishes a commit that a killed process left half done: every temporary
/// file its journal names that still exists is renamed into place.
pub(crate) fn recover(journal: &Path) -> io::Result<()> {
    let text = match std::fs::read(journal) {
        Ok(t) => t,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(e),
    };
    let pairs: Vec<(PathBuf, PathBuf)> = serde_json::from_slice(&text).map_err(|e| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!("{}: damaged commit journal: {e}", journal.display()),
        )
    })?;
    for (tmp, dest) in pairs {
        if tmp.exists() {
            std::fs::rename(&tmp, &dest)?;
        }
    }
    tracing::info!("{}: finished an interrupted commit", journal.display());
    std::fs::remove_file(journal)
}

/// Removes this module's temporary files in `dir` whose writer process is
/// gone (Linux: no `/proc/<pid>`); returns how many. Elsewhere nothing is
/// removed, since a live writer cannot be told apart.
pub(crate) fn remove_orphans(dir: &Path) -> io::Result<usize> {
    if !Path::new("/proc/self").exists() {
        return Ok(0);
    }
    let mut removed = 0;
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(0),
        Err(e) => return Err(e),
    };
    for entry in entries {
        let entry = entry?;
        let name = entry.file_name();
        let Some(rest) = name
            .to_str()
            .and_then(|n| n.strip_prefix(TMP_PREFIX))
            .filter(|n| n.ends_with(TMP_SUFFIX))
        else {
            continue;
        };
        let pid = rest.split('-').next().and_then(|p| p.parse::<u32>().ok());
        // Files from before the pid was part of the name: no writer can claim them.
        let alive = pid.is_some_and(|p| Path::new(&format!("/proc/{p}")).exists());
        if !alive {
            std::fs::remove_file(entry.path())?;
            removed += 1;
        }
    }
    if removed > 0 {
        tracing::info!(
            "{}: removed {removed} temporary files left by killed runs",
            dir.display()
        );
    }
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uncommitted_file_never_appears() {
        let dir = tempfile::tempdir().unwrap();
        let dest = dir.path().join("out.txt");
        {
            let mut f = AtomicFile::create(&dest).unwrap();
            f.file().write_all(b"half").unwrap();
        }
        assert!(!dest.exists());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        write_bytes(&dest, b"whole").unwrap();
        assert_eq!(std::fs::read(&dest).unwrap(), b"whole");
    }

    #[test]
    fn failed_body_keeps_old_file() {
        let dir = tempfile::tempdir().unwrap();
        let dest = dir.path().join("out.txt");
        write_bytes(&dest, b"old").unwrap();
        let r = write_with(&dest, |w| {
            w.write_all(b"new")?;
            Err(io::Error::other("boom"))
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read(&dest).unwrap(), b"old");
    }

    #[test]
    fn output_set_appears_together_and_recovers_after_a_kill() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.txt"), dir.path().join("b.txt"));
        let journal = dir.path().join(".set.commit.json");
        write_bytes(&a, b"old a").unwrap();
        write_bytes(&b, b"old b").unwrap();
        // Dropped before commit: nothing changes, nothing is left.
        {
            let mut set = OutputSet::new(&journal).unwrap();
            set.add(&a, |f| f.write_all(b"new a")).unwrap();
        }
        assert_eq!(std::fs::read(&a).unwrap(), b"old a");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
        // A kill after the first rename: the journal names the second file's
        // temporary, and the next set finishes the commit.
        let mut set = OutputSet::new(&journal).unwrap();
        set.add(&a, |f| f.write_all(b"new a")).unwrap();
        set.add(&b, |f| f.write_all(b"new b")).unwrap();
        let pairs: Vec<(PathBuf, PathBuf)> = set
            .files
            .iter()
            .map(|(t, d)| (t.to_path_buf(), d.clone()))
            .collect();
        write_bytes(&journal, &serde_json::to_vec(&pairs).unwrap()).unwrap();
        std::fs::rename(&pairs[0].0, &pairs[0].1).unwrap();
        for (t, _) in set.files {
            t.keep().unwrap();
        }
        assert_eq!(std::fs::read(&a).unwrap(), b"new a");
        assert_eq!(std::fs::read(&b).unwrap(), b"old b");
        drop(OutputSet::new(&journal).unwrap());
        assert_eq!(std::fs::read(&b).unwrap(), b"new b");
        assert!(!journal.exists());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
    }

    #[test]
    fn orphans_of_dead_writers_are_removed_and_live_ones_kept() {
        let dir = tempfile::tempdir().unwrap();
        // pid 0 is never a user process; our own pid is alive.
        let dead = dir.path().join(".tirewear-0-abc.tmp");
        let live = dir
            .path()
            .join(format!(".tirewear-{}-abc.tmp", std::process::id()));
        let other = dir.path().join("kpis.parquet");
        for p in [&dead, &live, &other] {
            std::fs::write(p, b"x").unwrap();
        }
        if Path::new("/proc/self").exists() {
            assert_eq!(remove_orphans(dir.path()).unwrap(), 1);
            assert!(!dead.exists() && live.exists() && other.exists());
        }
    }

    /// Each way an output can go wrong, each named with its file; spellings
    /// of one entry (`./a`, a folder reached through a link) are one entry.
    #[test]
    fn destinations_that_are_folders_twice_named_or_inputs_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        std::fs::create_dir(d.join("sub")).unwrap();
        std::fs::write(d.join("season.toml"), b"input").unwrap();
        let inputs = [("the season manifest".to_string(), d.join("season.toml"))];
        let ok = [
            ("KPI table", &*d.join("k.parquet")),
            ("CSV copy", &*d.join("k.csv")),
        ];
        assert_eq!(check_destinations(&ok, &inputs), Ok(()));

        let folder = check_destinations(&[("KPI table", &*d.join("sub"))], &inputs).unwrap_err();
        assert_eq!(folder.dest, d.join("sub"));
        assert!(folder.reason.starts_with("is a folder"), "{folder}");

        // A file where a folder of the path would be made: refused before
        // the work, not when the write's create_dir_all fails after it.
        for below in ["season.toml/k.parquet", "season.toml/new/k.parquet"] {
            let e = check_destinations(&[("KPI table", &*d.join(below))], &inputs).unwrap_err();
            let expected = format!(
                "is inside {}, which is a file",
                d.join("season.toml").display()
            );
            assert!(e.reason.starts_with(&expected), "{e}");
        }
        assert_eq!(
            check_destinations(
                &[("KPI table", &*d.join("sub/new/deeper/k.parquet"))],
                &inputs
            ),
            Ok(())
        );

        let twice = [
            ("KPI table", &*d.join("k.parquet")),
            ("CSV copy", &*d.join("sub/../k.parquet")),
        ];
        let e = check_destinations(&twice, &inputs).unwrap_err();
        assert_eq!(e.dest, d.join("sub/../k.parquet"));
        assert!(
            e.reason.contains("both the KPI table and the CSV copy"),
            "{e}"
        );

        let e =
            check_destinations(&[("KPI table", &*d.join("./season.toml"))], &inputs).unwrap_err();
        assert!(
            e.reason
                .contains("input of this command (the season manifest)"),
            "{e}"
        );

        #[cfg(unix)]
        {
            // The input read through a link, the output named by its target
            // or through a linked folder: the input would be replaced.
            std::os::unix::fs::symlink(d, d.join("via")).unwrap();
            std::os::unix::fs::symlink(d.join("season.toml"), d.join("link.toml")).unwrap();
            let linked = [("the season manifest".to_string(), d.join("link.toml"))];
            assert!(
                check_destinations(&[("KPI table", &*d.join("season.toml"))], &linked).is_err()
            );
            assert!(
                check_destinations(&[("KPI table", &*d.join("via/season.toml"))], &inputs).is_err()
            );
            // A hard link is another entry: the rename leaves the input alone.
            std::fs::hard_link(d.join("season.toml"), d.join("hard.toml")).unwrap();
            assert_eq!(
                check_destinations(&[("KPI table", &*d.join("hard.toml"))], &inputs),
                Ok(())
            );
            write_bytes(&d.join("hard.toml"), b"output").unwrap();
            assert_eq!(std::fs::read(d.join("season.toml")).unwrap(), b"input");
        }
    }

    /// The set itself refuses a destination named twice, and a folder in a
    /// file's place before its journal: nothing replaced, no journal left.
    #[test]
    fn a_set_refuses_a_twice_named_file_and_a_folder_before_any_rename() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let journal = d.join(".set.commit.json");
        let mut set = OutputSet::new(&journal).unwrap();
        set.add(&d.join("a"), |f| f.write_all(b"one")).unwrap();
        let e = set
            .add(&d.join("./a"), |f| f.write_all(b"two"))
            .unwrap_err();
        assert!(e.to_string().contains("named twice"), "{e}");
        drop(set);

        std::fs::write(d.join("a"), b"old a").unwrap();
        std::fs::create_dir(d.join("b")).unwrap();
        let mut set = OutputSet::new(&journal).unwrap();
        set.add(&d.join("a"), |f| f.write_all(b"new a")).unwrap();
        set.add(&d.join("b"), |f| f.write_all(b"new b")).unwrap();
        let e = set.commit().unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::IsADirectory);
        assert!(e.to_string().contains("is a folder"), "{e}");
        assert_eq!(std::fs::read(d.join("a")).unwrap(), b"old a");
        assert!(!journal.exists());
        // The two we made, and no temporary file.
        assert_eq!(std::fs::read_dir(d).unwrap().count(), 2);
    }
}
