//! Errors of model fitting and evaluation.

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ModelError {
    #[error("{what}: need more observations than {needed}, got {got}")]
    TooFewObservations {
        what: String,
        needed: usize,
        got: usize,
    },
    #[error("{0}: lengths differ")]
    LengthMismatch(String),
    #[error("{0}: the design matrix is singular (collinear or constant inputs)")]
    Singular(String),
    #[error("{0}: total sum of squares is zero (constant target)")]
    ConstantTarget(String),
    #[error("{0}")]
    Invalid(String),
    /// A model file that cannot be read (I/O), named.
    #[error("{path}: {message}")]
    Io { path: String, message: String },
    /// A model file that is not a tirewear model this version reads.
    #[error("{path}: {what}")]
    File { path: String, what: String },
    /// A setting out of its range (`FitSettings::check`).
    #[error("setting {name} = {value}: {expected}")]
    Setting {
        name: &'static str,
        value: String,
        expected: &'static str,
    },
}
