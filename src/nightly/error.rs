//! Errors of `process`.

use crate::ingest::IngestError;
use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum NightlyError {
    /// Another invocation holds the dataset.
    #[error(
        "dataset {dataset} is locked by another tirewear process ({holder}); try again when it has finished"
    )]
    Locked { dataset: PathBuf, holder: String },
    #[error(transparent)]
    Ingest(#[from] IngestError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// Archives or options that cannot make one dataset.
    #[error("{0}")]
    Invalid(String),
    /// Object storage (`s3://`): what was being done, and the store's error.
    #[error("{url}: {what}: {source}")]
    Remote {
        url: String,
        what: String,
        source: object_store::Error,
    },
    /// Another process committed the remote dataset since this one read it.
    #[error("{url}: {what}")]
    Conflict { url: String, what: String },
}

impl NightlyError {
    pub(crate) fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.into();
        move |source| NightlyError::Io { path, source }
    }
}
