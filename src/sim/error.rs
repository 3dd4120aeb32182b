//! Errors of the season simulator.

#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error(transparent)]
    Ingest(#[from] crate::ingest::IngestError),
    #[error("{0}")]
    Config(String),
}
