//! Errors of the validation: a season that cannot be simulated, extracted
//! or diagnosed, or a truth file that cannot be read.

#[derive(Debug, thiserror::Error)]
pub enum ValidateError {
    #[error(transparent)]
    Model(#[from] crate::model::ModelError),
    #[error(transparent)]
    Ingest(#[from] crate::ingest::IngestError),
    #[error(transparent)]
    Sim(#[from] crate::sim::SimError),
    #[error("{file}, line {line}: {message}")]
    Truth {
        file: String,
        line: usize,
        message: String,
    },
    /// A panic met while simulating, extracting or diagnosing one season.
    #[error("internal error ({0}); please report it")]
    Internal(String),
    #[error("{path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
}
