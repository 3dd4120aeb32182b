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
    /// The mcap crate's message with its cause: its I/O errors' text
    /// ("I/O error from writing, or reading a compression stream") does
    /// not say what the system reported (a full disk, a failing read).
    #[error("{path}: MCAP: {}", with_cause(source))]
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

/// An error's text followed by its cause's, where the text leaves it out.
fn with_cause(e: &dyn std::error::Error) -> String {
    let text = e.to_string();
    match e.source().map(|c| c.to_string()) {
        Some(cause) if !text.contains(&cause) => format!("{text}: {cause}"),
        _ => text,
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_mcap_io_error_says_what_the_system_reported() {
        let full = std::io::Error::from_raw_os_error(28); // ENOSPC
        let e = IngestError::Mcap {
            path: PathBuf::from("t/r.mcap"),
            source: mcap::McapError::from(full),
        };
        let text = e.to_string();
        assert!(
            text.starts_with("t/r.mcap: MCAP: ") && text.ends_with("(os error 28)"),
            "{text}"
        );
        // A message that holds its cause already is not repeated.
        let e = IngestError::Mcap {
            path: PathBuf::from("t/r.mcap"),
            source: mcap::McapError::BadMagic,
        };
        assert_eq!(
            e.to_string(),
            format!("t/r.mcap: MCAP: {}", mcap::McapError::BadMagic)
        );
    }
}
