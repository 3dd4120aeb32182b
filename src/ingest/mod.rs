//! The season archive: the documented input formats (`docs/formats.md`),
//! their readers with clear errors, and the writers the simulator uses.

pub(crate) mod checksum;
pub mod compound;
pub mod error;
pub mod manifest;
mod protowire;
pub mod road;
pub mod telemetry;
pub mod wear;

pub use error::{IngestError, Result};

use std::path::Path;

/// True for a finite number above zero (false for NaN).
pub(crate) fn positive(x: f64) -> bool {
    x > 0.0 && x.is_finite()
}

/// Largest TOML file read (manifests, compounds): far above any real one.
const MAX_TOML_BYTES: u64 = 64 << 20;

/// Opens a regular file of at most `limit` bytes for reading: a device
/// (`/dev/zero`), a FIFO or an oversized file is an error before any byte is
/// buffered, and the reader stops at `limit` should the file grow meanwhile.
pub(crate) fn open_bounded(path: &Path, limit: u64) -> Result<std::io::Take<std::fs::File>> {
    use std::io::Read;
    let (file, meta) = open_regular(path)?;
    if meta.len() > limit {
        return Err(IngestError::invalid(
            path,
            "file",
            format!("is {} bytes, more than the {limit} read", meta.len()),
        ));
    }
    Ok(file.take(limit))
}

/// Opens a regular file for reading, with its metadata. The path's
/// metadata is read before it is opened: opening a FIFO waits for a
/// writer, so `season.toml` or a KPI table given as a FIFO hung the
/// command before its check (2026-12-01); a device or folder is refused
/// the same way.
pub(crate) fn open_regular(path: &Path) -> Result<(std::fs::File, std::fs::Metadata)> {
    let not_regular = || {
        IngestError::invalid(
            path,
            "file",
            "is not a regular file (a device, FIFO or folder)",
        )
    };
    let stated = std::fs::metadata(path).map_err(|e| IngestError::io(path, e))?;
    if stated.is_dir() {
        return Err(IngestError::invalid(
            path,
            "file",
            "is a folder, not a regular file",
        ));
    }
    if !stated.is_file() {
        return Err(not_regular());
    }
    let file = std::fs::File::open(path).map_err(|e| IngestError::io(path, e))?;
    // The file opened: the path may have been replaced since.
    let meta = file.metadata().map_err(|e| IngestError::io(path, e))?;
    if !meta.is_file() {
        return Err(not_regular());
    }
    Ok((file, meta))
}

/// The first `limit` bytes of a regular file, to tell what it is; opened
/// only after its metadata says it is one (a FIFO's open would wait).
pub(crate) fn read_head(path: &Path, limit: u64) -> Result<Vec<u8>> {
    use std::io::Read;
    let (file, _) = open_regular(path)?;
    let mut head = Vec::new();
    file.take(limit)
        .read_to_end(&mut head)
        .map_err(|e| IngestError::io(path, e))?;
    Ok(head)
}

/// Largest JSON file read whole (a model, a bench file, an extraction's or
/// a diagnosis's report): far above the largest season's `gap.json`.
pub(crate) const MAX_JSON_BYTES: u64 = 1 << 30;

/// A regular text file of at most `limit` bytes, read whole: a FIFO (whose
/// open waits for a writer), a device (`/dev/zero` has no end) or a larger
/// file is an error naming it.
pub(crate) fn read_text(path: &Path, limit: u64) -> Result<String> {
    use std::io::Read;
    let mut text = String::new();
    open_bounded(path, limit)?
        .read_to_string(&mut text)
        .map_err(|e| IngestError::io(path, e))?;
    Ok(text)
}

/// A reader's error without its leading path, for an error type of its
/// own that names the file once.
pub(crate) fn unnamed(path: &Path, e: impl std::fmt::Display) -> String {
    let message = e.to_string();
    let named = format!("{}: ", path.display());
    message
        .strip_prefix(&named)
        .map_or(message.clone(), str::to_string)
}

/// Reads a TOML file into `T`, naming the file in any error.
pub(crate) fn read_toml<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text = read_text(path, MAX_TOML_BYTES)?;
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
