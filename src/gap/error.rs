//! Errors of the gap diagnosis.

#[derive(Debug, thiserror::Error)]
pub enum GapError {
    #[error(transparent)]
    Model(#[from] crate::model::ModelError),
    #[error(transparent)]
    Ingest(#[from] crate::ingest::IngestError),
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
