//! One writer per dataset: an advisory lock on `DATASET/.lock`.
//!
//! A whole run or a commit takes it exclusively; shards take it shared, so
//! they run side by side but never beside a commit. The lock is the kernel's
//! (`flock`): it goes with the process, so a killed run leaves no stale lock.
//! On a network file system it holds only where the file system supports
//! `flock` across hosts (NFSv4, Lustre with `flock`); see docs/nightly.md.

use super::NightlyError;
use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, Write};
use std::path::Path;

/// The lock of a dataset, held until dropped.
#[derive(Debug)]
pub struct DatasetLock {
    _file: File,
}

/// Takes the lock of `dataset` (exclusive or shared) without waiting; the
/// error names the holder when it is held.
pub(crate) fn acquire(dataset: &Path, exclusive: bool) -> Result<DatasetLock, NightlyError> {
    let path = dataset.join(".lock");
    let mut file = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)
        .map_err(NightlyError::io(&path))?;
    let taken = if exclusive {
        file.try_lock()
    } else {
        file.try_lock_shared()
    };
    match taken {
        Ok(()) => {}
        Err(TryLockError::WouldBlock) => {
            let mut holder = String::new();
            let _ = file.read_to_string(&mut holder);
            let holder = match holder.trim() {
                "" => "a shard (shared lock)".to_string(),
                h => h.to_string(),
            };
            return Err(NightlyError::Locked {
                dataset: dataset.to_path_buf(),
                holder,
            });
        }
        Err(TryLockError::Error(e)) => return Err(NightlyError::io(&path)(e)),
    }
    if exclusive {
        // Who holds it, for the message of a second invocation.
        let who = format!(
            "pid {} on {} since {} (unix time)",
            std::process::id(),
            hostname(),
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs())
        );
        file.set_len(0)
            .and_then(|_| file.rewind())
            .and_then(|_| file.write_all(who.as_bytes()))
            .map_err(NightlyError::io(&path))?;
    }
    Ok(DatasetLock { _file: file })
}

impl Drop for DatasetLock {
    fn drop(&mut self) {
        // An exclusive holder leaves no name behind; shared holders wrote none.
        let _ = self._file.set_len(0);
        // Released explicitly, not by closing the file: a process spawned by
        // another thread holds a copy of every descriptor between its fork
        // and its exec, and a `flock` lives until the last copy is closed, so
        // closing alone could leave the dataset locked for a moment after
        // this holder is done (seen in CI as a commit refused by a finished
        // shard). Unlocking through any copy releases it for all.
        let _ = self._file.unlock();
    }
}

fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::fs::read_to_string("/etc/hostname"))
        .map(|s| s.trim().to_string())
        .unwrap_or_else(|_| "this host".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A copy of the descriptor, as a child process holds one between fork
    /// and exec, must not keep a released lock alive.
    #[test]
    fn a_released_lock_stays_released_while_a_copy_of_its_file_is_open() {
        let dir = tempfile::tempdir().unwrap();
        let shard = acquire(dir.path(), false).unwrap();
        let copy = shard._file.try_clone().unwrap();
        drop(shard);
        let commit = acquire(dir.path(), true);
        assert!(commit.is_ok(), "{commit:?}");
        drop(copy);
    }

    #[test]
    fn shards_share_the_lock_and_a_commit_is_refused_beside_them() {
        let dir = tempfile::tempdir().unwrap();
        let a = acquire(dir.path(), false).unwrap();
        let b = acquire(dir.path(), false).unwrap();
        match acquire(dir.path(), true) {
            Err(NightlyError::Locked { holder, .. }) => {
                assert!(holder.contains("shard"), "{holder}")
            }
            other => panic!("{other:?}"),
        }
        drop((a, b));
        let whole = acquire(dir.path(), true).unwrap();
        match acquire(dir.path(), false) {
            Err(NightlyError::Locked { holder, .. }) => {
                assert!(
                    holder.starts_with(&format!("pid {}", std::process::id())),
                    "{holder}"
                )
            }
            other => panic!("{other:?}"),
        }
        drop(whole);
    }
}
