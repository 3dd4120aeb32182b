//! Which `process --then` steps (`fit`, `gap`, `report`) have been done on
//! the dataset as committed: `DATASET/then.json`.
//!
//! A step that failed, or a night killed between the commit and the steps,
//! would otherwise leave the dataset without its models, gap or report
//! until its data next changed: the next night runs the steps not recorded
//! here for the current `dataset_id`, even when nothing changed.

use super::{NightlyError, read_sealed, sealed};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The record's file name in the dataset folder.
pub const STEPS_FILE: &str = "then.json";

/// The steps done on one committed dataset.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StepsDone {
    /// `dataset.json`'s `dataset_id` the steps ran on.
    pub dataset_id: String,
    /// The steps that succeeded on it, by name, in the order they did.
    pub done: Vec<String>,
}

impl StepsDone {
    /// The steps done on `dataset_id` in `dataset`: none when there is no
    /// record or it is of another dataset. A damaged record counts as none
    /// (the steps run again), with a warning that names it.
    pub fn read(dataset: &Path, dataset_id: &str) -> (StepsDone, Option<String>) {
        let path = dataset.join(STEPS_FILE);
        let empty = StepsDone {
            dataset_id: dataset_id.to_string(),
            done: Vec::new(),
        };
        match read_sealed::<StepsDone>(&path) {
            Ok(Some(r)) if r.dataset_id == dataset_id => (r, None),
            Ok(_) => (empty, None),
            Err(why) => (
                empty,
                Some(format!(
                    "{}: {why}; every --then step runs again",
                    path.display()
                )),
            ),
        }
    }

    pub fn is_done(&self, step: &str) -> bool {
        self.done.iter().any(|d| d == step)
    }

    /// Records `step` as done and writes the record.
    pub fn mark_done(&mut self, dataset: &Path, step: &str) -> Result<PathBuf, NightlyError> {
        if !self.is_done(step) {
            self.done.push(step.to_string());
        }
        self.write(dataset)
    }

    /// Writes the record into `dataset` (atomically).
    pub fn write(&self, dataset: &Path) -> Result<PathBuf, NightlyError> {
        let path = dataset.join(STEPS_FILE);
        crate::atomic::write_bytes(&path, sealed(self).as_bytes())
            .map_err(NightlyError::io(&path))?;
        Ok(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_of_this_dataset_only_and_a_damaged_record_reruns_them() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let (mut r, warning) = StepsDone::read(d, "a1");
        assert_eq!((r.done.len(), warning), (0, None));
        r.mark_done(d, "fit").unwrap();
        r.mark_done(d, "gap").unwrap();
        r.mark_done(d, "fit").unwrap();
        let (back, _) = StepsDone::read(d, "a1");
        assert_eq!(back.done, ["fit", "gap"]);
        assert!(back.is_done("gap") && !back.is_done("report"));
        // Another dataset: nothing done on it yet.
        assert!(StepsDone::read(d, "b2").0.done.is_empty());
        // One changed byte: refused by its checksum, named, nothing done.
        let path = d.join(STEPS_FILE);
        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::write(&path, text.replace("\"gap\"", "\"gaq\"")).unwrap();
        let (r, warning) = StepsDone::read(d, "a1");
        assert!(r.done.is_empty());
        let warning = warning.unwrap();
        assert!(
            warning.contains("then.json") && warning.contains("data_crc32"),
            "{warning}"
        );
    }
}
