//! Errors from reading and writing season-archive files. Every variant names
//! the file; record-level problems also name the record and what was wrong.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum IngestError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: invalid TOML: {source}")]
    Toml {
        path: PathBuf,
        source: Box<toml::de::Error>,
    },
    #[error("{path}: CSV: {source}")]
    Csv { path: PathBuf, source: csv::Error },
    #[error("{path}: Parquet: {source}")]
    Parquet {
        path: PathBuf,
        source: parquet::errors::ParquetError,
    },
    #[error("{path}: MCAP: {source}")]
    Mcap {
        path: PathBuf,
        source: mcap::McapError,
    },
    /// A record that parsed but whose content is wrong.
    #[error("{path}: {record}: {what}")]
    Invalid {
        path: PathBuf,
        record: String,
        what: String,
    },
}

impl IngestError {
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }

    pub(crate) fn invalid(
        path: impl Into<PathBuf>,
        record: impl Into<String>,
        what: impl Into<String>,
    ) -> Self {
        Self::Invalid {
            path: path.into(),
            record: record.into(),
            what: what.into(),
        }
    }
}

pub type Result<T> = std::result::Result<T, IngestError>;
