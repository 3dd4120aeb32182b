//! The season archive: the documented input formats (`docs/formats.md`),
//! their readers with clear errors, and the writers the simulator uses.

pub mod compound;
pub mod error;
pub mod manifest;
pub mod road;
pub mod telemetry;
pub mod wear;

pub use error::{IngestError, Result};

use std::path::Path;

/// True for a finite number above zero (false for NaN).
pub(crate) fn positive(x: f64) -> bool {
    x > 0.0 && x.is_finite()
}

/// Reads a TOML file into `T`, naming the file in any error.
pub(crate) fn read_toml<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| IngestError::io(path, e))?;
    toml::from_str(&text).map_err(|e| IngestError::Toml {
        path: path.to_path_buf(),
        source: Box::new(e),
    })
}

/// Writes `value` as TOML, atomically.
pub(crate) fn write_toml<T: serde::Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = toml::to_string_pretty(value)
        .map_err(|e| IngestError::invalid(path, "TOML", e.to_string()))?;
    crate::atomic::write_bytes(path, text.as_bytes()).map_err(|e| IngestError::io(path, e))
}
