//! Errors of the HTML report.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Input { path: PathBuf, message: String },
    /// Where the page may not go (a folder, a file that is no HTML page).
    #[error("{path}: {message}")]
    Output { path: PathBuf, message: String },
    #[error("drawing a figure: {0}")]
    Figure(String),
}

impl ReportError {
    /// An input file's error, named once: the readers' own errors already
    /// begin with the file, which `Input` prints first.
    pub(crate) fn input(path: &std::path::Path, e: impl std::fmt::Display) -> ReportError {
        ReportError::Input {
            path: path.to_path_buf(),
            message: crate::ingest::unnamed(path, e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_input_file_is_named_once() {
        let p = std::path::Path::new("/d/kpis.road.parquet");
        let e = ReportError::input(p, "/d/kpis.road.parquet: Parquet: corrupt footer");
        assert_eq!(
            e.to_string(),
            "/d/kpis.road.parquet: Parquet: corrupt footer"
        );
        let e = ReportError::input(p, "Parquet: corrupt footer");
        assert_eq!(
            e.to_string(),
            "/d/kpis.road.parquet: Parquet: corrupt footer"
        );
    }
}
