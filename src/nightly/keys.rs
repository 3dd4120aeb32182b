//! What decides a run's rows, as one BLAKE3 key (docs/nightly.md, "Keys").
//!
//! A run's key hashes the content of its telemetry file, its own wear
//! readings, its compound file, its track's road profiles, its manifest
//! entries (run, event, car, track), the engine and the tirewear version.
//! Files are hashed only when their size or modification time changed since
//! the last commit (the stamps are kept in `dataset.json`).

use super::NightlyError;
use crate::ingest::manifest::{Run, Season};
use crate::ingest::wear::WearReading;
use crate::kpi::Engine;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// Changes whenever the parts' contents would change for the same inputs.
const KEY_VERSION: &str = concat!("tirewear-process-4 ", env!("CARGO_PKG_VERSION"));

/// Size, modification time and content hash of one input file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct FileStamp {
    pub size: u64,
    pub mtime_ns: u64,
    pub blake3: String,
}

/// Content hashes of input files: those of the last commit (trusted while a
/// file's size and mtime are unchanged) and those seen by this invocation.
#[derive(Debug, Default)]
pub(crate) struct FileHashes {
    pub old: BTreeMap<String, FileStamp>,
    pub seen: BTreeMap<String, FileStamp>,
    /// Bytes read to hash files whose stamp changed.
    pub bytes_hashed: u64,
}

impl FileHashes {
    /// The content hash of `path` (hex).
    pub fn hash(&mut self, path: &Path) -> Result<String, NightlyError> {
        let name = path.display().to_string();
        if let Some(s) = self.seen.get(&name) {
            return Ok(s.blake3.clone());
        }
        let meta = std::fs::metadata(path).map_err(NightlyError::io(path))?;
        if !meta.is_file() {
            // A FIFO's open waits for a writer; a device has no end to hash.
            return Err(NightlyError::Invalid(format!(
                "{}: is not a regular file (a device, FIFO or folder)",
                path.display()
            )));
        }
        let mtime_ns = meta
            .modified()
            .ok()
            .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
            .map_or(0, |d| d.as_nanos() as u64);
        let stamp = match self.old.get(&name) {
            Some(s) if s.size == meta.len() && s.mtime_ns == mtime_ns && mtime_ns != 0 => s.clone(),
            _ => {
                let mut h = blake3::Hasher::new();
                let file = std::fs::File::open(path).map_err(NightlyError::io(path))?;
                h.update_reader(file).map_err(NightlyError::io(path))?;
                self.bytes_hashed += meta.len();
                FileStamp {
                    size: meta.len(),
                    mtime_ns,
                    blake3: h.finalize().to_hex().to_string(),
                }
            }
        };
        let hex = stamp.blake3.clone();
        self.seen.insert(name, stamp);
        Ok(hex)
    }
}

/// A key under construction: labelled fields, each length-prefixed so no
/// two different inputs hash alike.
struct KeyHasher(blake3::Hasher);

impl KeyHasher {
    fn new(kind: &str, engine: Engine) -> Self {
        let mut k = KeyHasher(blake3::Hasher::new());
        k.field("version", KEY_VERSION.as_bytes());
        k.field("kind", kind.as_bytes());
        k.field("engine", format!("{engine:?}").as_bytes());
        k
    }
    fn field(&mut self, label: &str, bytes: &[u8]) {
        for part in [label.as_bytes(), bytes] {
            self.0.update(&(part.len() as u64).to_le_bytes());
            self.0.update(part);
        }
    }
    fn json(&mut self, label: &str, value: &impl Serialize) {
        let text = serde_json::to_vec(value).expect("manifest entries serialise");
        self.field(label, &text);
    }
    fn finish(self) -> String {
        self.0.finalize().to_hex().to_string()
    }
}

/// Hashes the road-profile files of a track into `k`.
fn road_fields(
    k: &mut KeyHasher,
    season: &Season,
    track: &str,
    files: &mut FileHashes,
) -> Result<(), NightlyError> {
    let m = &season.manifest;
    if let Some(bulk) = &m.road_profiles {
        // The bulk file holds every track: any change to it re-keys them all.
        k.field("road bulk", files.hash(&season.path(bulk))?.as_bytes());
    }
    if let Some(t) = season.track(track) {
        k.json("track", t);
        for p in &t.profiles {
            k.field("road csv", files.hash(&season.path(&p.file))?.as_bytes());
        }
    }
    Ok(())
}

/// The key of a track's road part (its profiles' curves).
pub(crate) fn road_key(
    season: &Season,
    track: &str,
    engine: Engine,
    files: &mut FileHashes,
) -> Result<String, NightlyError> {
    let mut k = KeyHasher::new("road", engine);
    road_fields(&mut k, season, track, files)?;
    Ok(k.finish())
}

/// The key of a run's parts (its KPI rows and maps).
pub(crate) fn run_key(
    season: &Season,
    run: &Run,
    readings: &[WearReading],
    engine: Engine,
    files: &mut FileHashes,
) -> Result<String, NightlyError> {
    let m = &season.manifest;
    let mut k = KeyHasher::new("run", engine);
    k.json("run", run);
    let event = season.event(&run.event).expect("validated manifest");
    k.json("event", event);
    k.json("car", &m.cars.iter().find(|c| c.id == run.car));
    k.field(
        "telemetry",
        files.hash(&season.path(&run.telemetry))?.as_bytes(),
    );
    k.json("wear", &readings);
    match m.compounds.iter().find(|c| c.id == run.compound) {
        Some(c) => k.field("compound", files.hash(&season.path(&c.file))?.as_bytes()),
        None => k.field("compound", b"missing"),
    }
    road_fields(&mut k, season, &event.track, files)?;
    Ok(k.finish())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_is_hashed_again_only_when_its_stamp_changes() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.bin");
        std::fs::write(&p, b"abc").unwrap();
        let mut f = FileHashes::default();
        let h = f.hash(&p).unwrap();
        // BLAKE3("abc"), from the reference implementation's test vectors.
        assert_eq!(
            h,
            "6437b3ac38465133ffb63b75273a8db548c558465d79db03fd359c6cd5bd9d85"
        );
        assert_eq!(f.bytes_hashed, 3);
        let mut again = FileHashes {
            old: f.seen.clone(),
            ..Default::default()
        };
        assert_eq!(again.hash(&p).unwrap(), h);
        assert_eq!(again.bytes_hashed, 0, "an unchanged stamp is trusted");
        // A stamp that differs (here: a forged size) makes it read the file.
        let mut forged = f.seen.clone();
        forged.values_mut().for_each(|s| s.size += 1);
        let mut third = FileHashes {
            old: forged,
            ..Default::default()
        };
        assert_eq!(third.hash(&p).unwrap(), h);
        assert_eq!(third.bytes_hashed, 3);
    }
}
