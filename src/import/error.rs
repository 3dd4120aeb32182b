//! Errors of `tirewear import`: each names the file and, where there is
//! one, the channel, row or setting that was wrong.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// The log itself: its header, a row, its layout.
    #[error("{}: {record}: {what}", path.display())]
    Log {
        path: PathBuf,
        record: String,
        what: String,
    },
    /// One channel of the log.
    #[error("{}: channel '{channel}': {what}", path.display())]
    Channel {
        path: PathBuf,
        channel: String,
        what: String,
    },
    /// A required quantity that no channel provides.
    #[error("{}: no channel for {quantity} (tried {tried}); the file has: {available}", path.display())]
    Missing {
        path: PathBuf,
        quantity: String,
        tried: String,
        available: String,
    },
    /// The channel map.
    #[error("{}: {what}", path.display())]
    Map { path: PathBuf, what: String },
    /// The vehicle description.
    #[error("{}: {what}", path.display())]
    Car { path: PathBuf, what: String },
    /// Where the run goes in the archive.
    #[error("{}: {what}", path.display())]
    Archive { path: PathBuf, what: String },
    #[error(transparent)]
    Ingest(#[from] crate::ingest::IngestError),
}

impl ImportError {
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }

    pub fn log(
        path: impl Into<PathBuf>,
        record: impl Into<String>,
        what: impl Into<String>,
    ) -> Self {
        Self::Log {
            path: path.into(),
            record: record.into(),
            what: what.into(),
        }
    }
}
