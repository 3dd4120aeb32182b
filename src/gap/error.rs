//! Errors of the gap diagnosis and its validation.

#[derive(Debug, thiserror::Error)]
pub enum GapError {
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
    #[error("{file}: {effect}: {message}")]
    Effects {
        file: String,
        effect: String,
        message: String,
    },
    #[error("{path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
}
