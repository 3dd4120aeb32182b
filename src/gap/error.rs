//! Errors of the gap diagnosis.

#[derive(Debug, thiserror::Error)]
pub enum GapError {
    #[error(transparent)]
    Model(#[from] crate::model::ModelError),
    #[error(transparent)]
    Ingest(#[from] crate::ingest::IngestError),
    /// The hypotheses file is not TOML of the documented shape.
    #[error("{file}: {message}")]
    EffectsFile { file: String, message: String },
    /// One hypothesis of the file is wrong.
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
