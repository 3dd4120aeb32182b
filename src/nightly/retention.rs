//! How many dated result folders (`DATASET/models/STAMP/`, `gap/STAMP/`,
//! `report/STAMP/`, written by `process --then`) a dataset keeps, and what
//! becomes of one a stopped night left unfinished.
//!
//! Only folders named like a stamp ([`super::stamp`]) are counted and
//! removed; anything else a user put there is left alone. A folder is first
//! renamed to a hidden name, then removed, so a kill halfway leaves nothing
//! that looks like a result; the next prune removes such leftovers.

use super::stamp::{is_stamp, time_order};
use std::path::{Path, PathBuf};

/// The prefix of a folder being removed.
const REMOVING: &str = ".removing-";

/// Removes all but the `keep` newest stamp-named folders of `dir` (and the
/// leftovers of an earlier prune). Returns the folders removed. A missing
/// `dir` has nothing to prune.
pub fn prune_dated(dir: &Path, keep: usize) -> std::io::Result<Vec<PathBuf>> {
    let folders = folders(dir)?;
    let (mut stamps, others): (Vec<String>, Vec<String>) =
        folders.into_iter().partition(|n| is_stamp(n));
    let leftovers = others
        .into_iter()
        .filter(|n| n.starts_with(REMOVING))
        .map(|n| dir.join(n));
    stamps.sort_unstable_by_key(|n| time_order(n));
    let old = stamps.len().saturating_sub(keep);
    let mut removed = Vec::new();
    for name in &stamps[..old] {
        let from = dir.join(name);
        let hidden = dir.join(format!("{REMOVING}{name}"));
        std::fs::rename(&from, &hidden)?;
        std::fs::remove_dir_all(&hidden)?;
        removed.push(from);
    }
    for path in leftovers {
        std::fs::remove_dir_all(&path)?;
    }
    Ok(removed)
}

/// Finishes what a killed writer left in the stamp-named folders of `dir`
/// (a night stopped during its `--then` steps writes into its own folder,
/// which no later writer visits): an interrupted commit's journal
/// (`*.journal`) is completed, dead writers' temporary files removed, and
/// a folder left empty removed. Returns the folders removed.
pub fn tidy_dated(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut removed = Vec::new();
    for name in folders(dir)?.into_iter().filter(|n| is_stamp(n)) {
        let folder = dir.join(name);
        for file in std::fs::read_dir(&folder)? {
            let file = file?.path();
            if file.extension().is_some_and(|e| e == "journal") {
                crate::atomic::recover(&file)?;
            }
        }
        crate::atomic::remove_orphans(&folder)?;
        if std::fs::read_dir(&folder)?.next().is_none() {
            std::fs::remove_dir(&folder)?;
            removed.push(folder);
        }
    }
    Ok(removed)
}

/// The names of the folders in `dir` (none when `dir` is missing).
fn folders(dir: &Path) -> std::io::Result<Vec<String>> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(e),
    };
    let mut names = Vec::new();
    for entry in entries {
        let entry = entry?;
        if entry.file_type()?.is_dir() {
            names.push(entry.file_name().to_string_lossy().into_owned());
        }
    }
    Ok(names)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_the_newest_stamps_and_everything_else() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        for name in [
            "2026-11-28T0230Z",
            "2026-11-30T0230Z",
            "2025-12-31T2359Z",
            "2026-11-29T0230Z",
            // Seconds after the minute stamp above, though a plain
            // string order puts it first.
            "2026-11-29T023015Z",
            "baseline",
            ".removing-2026-01-01T0000Z",
        ] {
            std::fs::create_dir_all(d.join(name).join("sub")).unwrap();
            std::fs::write(d.join(name).join("sub/file"), name).unwrap();
        }
        // A plain file named like a stamp is not a result folder.
        std::fs::write(d.join("2020-01-01T0000Z"), "x").unwrap();
        let mut removed = prune_dated(d, 2).unwrap();
        removed.sort();
        assert_eq!(
            removed,
            [
                d.join("2025-12-31T2359Z"),
                d.join("2026-11-28T0230Z"),
                d.join("2026-11-29T0230Z")
            ]
        );
        let mut left: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(
            left,
            [
                "2020-01-01T0000Z",
                "2026-11-29T023015Z",
                "2026-11-30T0230Z",
                "baseline"
            ]
        );
        // Keeping more than there are removes nothing; a missing folder is empty.
        assert!(prune_dated(d, 5).unwrap().is_empty());
        assert!(prune_dated(&d.join("absent"), 0).unwrap().is_empty());
        // Keeping none removes every dated folder.
        assert_eq!(prune_dated(d, 0).unwrap().len(), 2);
        assert!(d.join("baseline/sub/file").exists());
    }

    /// What a killed `fit` leaves: a dead writer's temporary file (pid 0 is
    /// never a user process) and a journal naming a finished temporary file.
    #[test]
    fn a_killed_nights_folders_are_finished_or_removed() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let only_temp = d.join("2026-11-28T0230Z");
        std::fs::create_dir_all(&only_temp).unwrap();
        std::fs::write(only_temp.join(".tirewear-0-abc.tmp"), "half").unwrap();
        let journaled = d.join("2026-11-29T0230Z");
        std::fs::create_dir_all(&journaled).unwrap();
        let tmp = journaled.join(".tirewear-0-def.tmp");
        std::fs::write(&tmp, "whole").unwrap();
        let pairs = vec![(tmp.clone(), journaled.join("pca.json"))];
        std::fs::write(
            journaled.join(".models.journal"),
            serde_json::to_vec(&pairs).unwrap(),
        )
        .unwrap();
        // Not a stamp: left alone.
        let other = d.join("mine");
        std::fs::create_dir_all(&other).unwrap();
        std::fs::write(other.join(".tirewear-0-x.tmp"), "x").unwrap();
        assert_eq!(tidy_dated(d).unwrap(), std::slice::from_ref(&only_temp));
        assert!(!only_temp.exists());
        let left: Vec<String> = std::fs::read_dir(&journaled)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(left, ["pca.json"]);
        assert_eq!(
            std::fs::read_to_string(journaled.join("pca.json")).unwrap(),
            "whole"
        );
        assert!(other.join(".tirewear-0-x.tmp").exists());
        assert!(tidy_dated(&d.join("absent")).unwrap().is_empty());
    }
}
