//! The season manifest (`season.toml`): events, tracks, cars, runs and the
//! paths of every other file in the archive. Paths are relative to the
//! manifest's folder.

use super::{IngestError, Result, positive, read_toml, write_toml};
use crate::Wheel;
use serde::{Deserialize, Serialize};
use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// The only format version this build reads and writes.
pub(crate) const FORMAT_VERSION: u32 = 1;

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    pub format_version: u32,
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// Wear-reading CSV files (`docs/formats.md`, "Wear readings").
    pub wear_readings: Vec<String>,
    /// Bulk road-profile Parquet file, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub road_profiles: Option<String>,
    pub compounds: Vec<CompoundRef>,
    pub tracks: Vec<Track>,
    pub events: Vec<Event>,
    pub cars: Vec<Car>,
    pub runs: Vec<Run>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CompoundRef {
    pub id: String,
    /// Compound TOML file.
    pub file: String,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Track {
    pub id: String,
    pub name: String,
    pub length_m: f64,
    /// Road profiles stored one per CSV file (in addition to any in the bulk file).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub profiles: Vec<ProfileRef>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ProfileRef {
    pub location: String,
    pub file: String,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Event {
    pub id: String,
    pub track: String,
    /// ISO 8601 date, `YYYY-MM-DD`.
    pub date: String,
    pub air_temp_c: f64,
    pub track_temp_c: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Car {
    pub id: String,
    pub name: String,
    pub mass_kg: f64,
    pub wheelbase_m: f64,
    pub front_track_m: f64,
    pub rear_track_m: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Run {
    pub id: String,
    pub event: String,
    pub car: String,
    pub compound: String,
    /// Planned run distance (m); the telemetry's distance channel is the measurement.
    pub distance_m: f64,
    /// MCAP telemetry file.
    pub telemetry: String,
    pub tire_sets: TireSets,
}

/// Tire set identifiers by wheel position.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TireSets {
    #[serde(rename = "FL")]
    pub fl: String,
    #[serde(rename = "FR")]
    pub fr: String,
    #[serde(rename = "RL")]
    pub rl: String,
    #[serde(rename = "RR")]
    pub rr: String,
}

impl TireSets {
    pub fn get(&self, wheel: Wheel) -> &str {
        match wheel {
            Wheel::FL => &self.fl,
            Wheel::FR => &self.fr,
            Wheel::RL => &self.rl,
            Wheel::RR => &self.rr,
        }
    }
}

/// A manifest together with the folder its relative paths start from.
#[derive(Debug, Clone)]
pub struct Season {
    pub root: PathBuf,
    pub manifest_path: PathBuf,
    pub manifest: Manifest,
}

/// A folder with no `season.toml`, or a file that is no TOML text, named
/// for what it is and, where one is near, with the archive to give
/// instead: a `process` dataset, a folder inside an archive, a folder of
/// archives, the KPI table or a telemetry file (`extract demo/kpis.parquet`
/// once said only "stream did not contain valid UTF-8").
fn refuse_non_archive(path: &Path) -> Result<()> {
    let no_archive = |why: String| Err(IngestError::invalid(path, "season archive", why));
    let manifest_in = |dir: &Path| dir.join("season.toml").is_file();
    if path.is_dir() {
        // Whatever stands there, its reader names it (a FIFO, a folder).
        if path.join("season.toml").exists() {
            return Ok(());
        }
        if path.join("dataset.json").is_file() {
            return no_archive(format!(
                "is a dataset written by `tirewear process`, not a season archive (no \
                 season.toml): its KPI table is {}",
                path.join("kpis.parquet").display()
            ));
        }
        if let Some(up) = archive_above(path) {
            return no_archive(format!(
                "holds no season.toml; the season archive is {}, which holds this folder",
                up.display()
            ));
        }
        let mut inside: Vec<String> = std::fs::read_dir(path)
            .into_iter()
            .flatten()
            .flatten()
            .filter(|e| manifest_in(&e.path()))
            .map(|e| e.path().display().to_string())
            .collect();
        if !inside.is_empty() {
            inside.sort();
            let more = inside.len().saturating_sub(3);
            inside.truncate(3);
            let more = if more > 0 {
                format!(" and {more} more")
            } else {
                String::new()
            };
            return no_archive(format!(
                "holds no season.toml, but its folders {}{more} do: give each season \
                 archive's folder",
                inside.join(", ")
            ));
        }
        return no_archive(format!(
            "holds no season.toml: not a season archive ({HOW_TO_START})"
        ));
    }
    if std::fs::symlink_metadata(path).is_err_and(|e| e.kind() == std::io::ErrorKind::NotFound) {
        let hint = match archive_above(path) {
            Some(up) => format!("the season archive near it is {}", up.display()),
            None => HOW_TO_START.to_string(),
        };
        return no_archive(format!("does not exist ({hint})"));
    }
    let Ok(head) = super::read_head(path, 256) else {
        return Ok(()); // the manifest's reader names what is wrong
    };
    let what = super::checksum::what_it_is(&head);
    if head.is_empty() || what.starts_with("it is text") {
        return Ok(());
    }
    let folder = crate::atomic::folder_of(path);
    let hint = match archive_above(path) {
        Some(up) if up == folder => format!("give the archive's folder, {}", up.display()),
        Some(up) => format!("the season archive is {}", up.display()),
        None => "give a season archive's folder or its season.toml".to_string(),
    };
    no_archive(format!(
        "is not a season manifest (TOML text): {what}; {hint}"
    ))
}

/// Where a season archive comes from, for a path that holds none: `import`
/// adds runs to an archive and does not start one (its tracks and
/// compounds' master curves are the team's own).
const HOW_TO_START: &str = "`tirewear simulate` writes one; for a team's own logs, write its \
     season.toml by hand and then `tirewear import` the logs: docs/import.md, \"Starting an \
     archive\"";

/// The nearest folder above `path` (at most three levels) that holds a
/// `season.toml`.
fn archive_above(path: &Path) -> Option<PathBuf> {
    let start = std::path::absolute(path).ok()?;
    start
        .ancestors()
        .skip(1)
        .take(3)
        .find(|d| d.join("season.toml").is_file())
        .map(|d| {
            // Said as the user wrote it where the path allows.
            let mut rel = path.to_path_buf();
            for _ in 0..start.components().count() - d.components().count() {
                rel = match rel.parent() {
                    Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
                    _ => return d.to_path_buf(),
                };
            }
            rel
        })
}

impl Season {
    /// Reads and validates `DIR/season.toml` (or a manifest path given
    /// directly). Every path in it must stay inside the archive folder.
    pub fn open(path: &Path) -> Result<Season> {
        Self::open_with(path, false)
    }

    /// As [`Season::open`]; `allow_external_paths` accepts absolute paths and
    /// paths that leave the archive folder (`..`), which an archive copied
    /// from elsewhere should not be able to point at by itself.
    pub fn open_with(path: &Path, allow_external_paths: bool) -> Result<Season> {
        refuse_non_archive(path)?;
        let manifest_path = if path.is_dir() {
            path.join("season.toml")
        } else {
            path.to_path_buf()
        };
        let manifest: Manifest = read_toml(&manifest_path)?;
        manifest.validate(&manifest_path)?;
        if !allow_external_paths {
            manifest.check_paths_inside(&manifest_path)?;
        }
        let root = manifest_path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default();
        Ok(Season {
            root,
            manifest_path,
            manifest,
        })
    }

    /// Resolves a path from the manifest against the archive folder.
    pub fn path(&self, rel: &str) -> PathBuf {
        self.root.join(rel)
    }

    /// Files directly in the archive's `folder` (`wear`, `road`) with one of
    /// `extensions` that the manifest does not name, sorted: a file a user
    /// put there and did not list is never read, and says nothing.
    pub fn unlisted(&self, folder: &str, extensions: &[&str]) -> Vec<String> {
        let key = |p: &Path| -> PathBuf {
            p.components()
                .filter(|c| !matches!(c, std::path::Component::CurDir))
                .collect()
        };
        let named: HashSet<PathBuf> = self
            .input_files()
            .into_iter()
            .map(|(_, p)| key(&p))
            .collect();
        let Ok(entries) = std::fs::read_dir(self.path(folder)) else {
            return Vec::new();
        };
        let mut found: Vec<String> = entries
            .flatten()
            .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
            .map(|e| e.path())
            .filter(|p| {
                p.extension()
                    .and_then(|x| x.to_str())
                    .is_some_and(|x| extensions.iter().any(|e| x.eq_ignore_ascii_case(e)))
            })
            .filter(|p| !named.contains(&key(p)))
            .filter_map(|p| {
                let name = p.file_name()?.to_str()?.to_string();
                Some(format!("{folder}/{name}"))
            })
            .collect();
        found.sort();
        found
    }

    /// Every file the manifest names, with what it is: the manifest itself,
    /// compounds, wear readings, road profiles and each run's telemetry
    /// (the inputs an output must not replace).
    pub fn input_files(&self) -> Vec<(String, PathBuf)> {
        let m = &self.manifest;
        let mut files = vec![(
            "the season manifest".to_string(),
            self.manifest_path.clone(),
        )];
        let named = |what: String, rel: &str| (what, self.path(rel));
        files.extend(
            m.compounds
                .iter()
                .map(|c| named(format!("compound {}", c.id), &c.file)),
        );
        files.extend(
            m.wear_readings
                .iter()
                .map(|f| named("wear readings".into(), f)),
        );
        files.extend(
            m.road_profiles
                .iter()
                .map(|f| named("road profiles".into(), f)),
        );
        for t in &m.tracks {
            files.extend(
                t.profiles
                    .iter()
                    .map(|p| named(format!("road profile {} {}", t.id, p.location), &p.file)),
            );
        }
        files.extend(
            m.runs
                .iter()
                .map(|r| named(format!("telemetry of run {}", r.id), &r.telemetry)),
        );
        files
    }

    pub fn event(&self, id: &str) -> Option<&Event> {
        self.manifest.events.iter().find(|e| e.id == id)
    }

    pub fn track(&self, id: &str) -> Option<&Track> {
        self.manifest.tracks.iter().find(|t| t.id == id)
    }
}

impl Manifest {
    /// Every file path, with the record that holds it.
    fn paths(&self) -> Vec<(String, &str)> {
        let mut out: Vec<(String, &str)> = Vec::new();
        for (i, f) in self.wear_readings.iter().enumerate() {
            out.push((format!("wear_readings[{i}]"), f));
        }
        if let Some(f) = &self.road_profiles {
            out.push(("road_profiles".into(), f));
        }
        for (i, c) in self.compounds.iter().enumerate() {
            out.push((format!("compounds[{i}] id={}", c.id), &c.file));
        }
        for (i, t) in self.tracks.iter().enumerate() {
            for (j, p) in t.profiles.iter().enumerate() {
                out.push((format!("tracks[{i}] id={} profiles[{j}]", t.id), &p.file));
            }
        }
        for (i, r) in self.runs.iter().enumerate() {
            out.push((format!("runs[{i}] id={}", r.id), &r.telemetry));
        }
        out
    }

    /// Paths must be relative and stay inside the archive folder (no `..`,
    /// no root, no drive prefix).
    pub(crate) fn check_paths_inside(&self, path: &Path) -> Result<()> {
        use std::path::Component;
        for (record, p) in self.paths() {
            let outside = Path::new(p)
                .components()
                .any(|c| !matches!(c, Component::Normal(_) | Component::CurDir));
            if outside {
                return Err(IngestError::invalid(
                    path,
                    record,
                    format!(
                        "path '{p}' leaves the archive folder (absolute or '..'); \
                         --allow-external-paths accepts it"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Writes the manifest atomically.
    pub fn write(&self, path: &Path) -> Result<()> {
        write_toml(path, self)
    }

    /// Checks the version, unique ids, cross references and numeric ranges.
    pub fn validate<'a>(&'a self, path: &Path) -> Result<()> {
        let bad = |record: String, what: String| IngestError::invalid(path, record, what);
        if self.format_version != FORMAT_VERSION {
            return Err(bad(
                "format_version".into(),
                format!(
                    "is {}, this build reads version {FORMAT_VERSION}",
                    self.format_version
                ),
            ));
        }
        fn unique<'a>(
            kind: &str,
            ids: &[&'a str],
        ) -> std::result::Result<HashSet<&'a str>, (String, String)> {
            let mut seen = HashSet::new();
            for (i, &id) in ids.iter().enumerate() {
                if id.is_empty() {
                    return Err((format!("{kind}[{i}]"), "empty id".into()));
                }
                if !seen.insert(id) {
                    return Err((format!("{kind}[{i}] id={id}"), "duplicate id".into()));
                }
            }
            Ok(seen)
        }
        let ids = |kind: &str, ids: Vec<&'_ str>| {
            unique(kind, &ids).map(|_| ()).map_err(|(r, w)| bad(r, w))
        };
        ids(
            "compounds",
            self.compounds.iter().map(|c| c.id.as_str()).collect(),
        )?;
        ids(
            "tracks",
            self.tracks.iter().map(|c| c.id.as_str()).collect(),
        )?;
        ids(
            "events",
            self.events.iter().map(|c| c.id.as_str()).collect(),
        )?;
        ids("cars", self.cars.iter().map(|c| c.id.as_str()).collect())?;
        ids("runs", self.runs.iter().map(|c| c.id.as_str()).collect())?;
        let set = |v: Vec<&'a str>| -> HashSet<&'a str> { v.into_iter().collect() };
        let compounds = set(self.compounds.iter().map(|c| c.id.as_str()).collect());
        let tracks = set(self.tracks.iter().map(|c| c.id.as_str()).collect());
        let events = set(self.events.iter().map(|c| c.id.as_str()).collect());
        let cars = set(self.cars.iter().map(|c| c.id.as_str()).collect());

        for (i, t) in self.tracks.iter().enumerate() {
            if !positive(t.length_m) {
                return Err(bad(
                    format!("tracks[{i}] id={}", t.id),
                    format!("length_m must be > 0, got {}", t.length_m),
                ));
            }
        }
        for (i, e) in self.events.iter().enumerate() {
            let rec = format!("events[{i}] id={}", e.id);
            if !tracks.contains(e.track.as_str()) {
                return Err(bad(rec, format!("unknown track '{}'", e.track)));
            }
            if !valid_date(&e.date) {
                return Err(bad(
                    rec,
                    format!("date '{}' is not a calendar date YYYY-MM-DD", e.date),
                ));
            }
            for (name, v) in [
                ("air_temp_c", e.air_temp_c),
                ("track_temp_c", e.track_temp_c),
            ] {
                if !(-40.0..=90.0).contains(&v) {
                    return Err(bad(rec, format!("{name} = {v} is outside -40..90 degC")));
                }
            }
        }
        for (i, c) in self.cars.iter().enumerate() {
            let rec = format!("cars[{i}] id={}", c.id);
            for (name, v) in [
                ("mass_kg", c.mass_kg),
                ("wheelbase_m", c.wheelbase_m),
                ("front_track_m", c.front_track_m),
                ("rear_track_m", c.rear_track_m),
            ] {
                if !positive(v) {
                    return Err(bad(rec, format!("{name} must be > 0, got {v}")));
                }
            }
        }
        for (i, r) in self.runs.iter().enumerate() {
            let rec = format!("runs[{i}] id={}", r.id);
            if !events.contains(r.event.as_str()) {
                return Err(bad(rec, format!("unknown event '{}'", r.event)));
            }
            if !cars.contains(r.car.as_str()) {
                return Err(bad(rec, format!("unknown car '{}'", r.car)));
            }
            if !compounds.contains(r.compound.as_str()) {
                return Err(bad(rec, format!("unknown compound '{}'", r.compound)));
            }
            if !positive(r.distance_m) {
                return Err(bad(
                    rec,
                    format!("distance_m must be > 0, got {}", r.distance_m),
                ));
            }
            if r.telemetry.is_empty() {
                return Err(bad(rec, "telemetry path is empty".into()));
            }
            // Identifiers are non-empty (docs/formats.md); a wear reading
            // names its tire set, and an empty one matches nothing visibly.
            if let Some(w) = Wheel::ALL
                .into_iter()
                .find(|&w| r.tire_sets.get(w).trim().is_empty())
            {
                return Err(bad(rec, format!("tire_sets.{} is empty", w.name())));
            }
            let same = |o: &Run| Path::new(&o.telemetry) == Path::new(&r.telemetry);
            if let Some(o) = self.runs[..i].iter().find(|o| same(o)) {
                return Err(bad(
                    rec,
                    format!(
                        "telemetry '{}' is also run {}'s: each run needs its own file",
                        r.telemetry, o.id
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// A calendar date `YYYY-MM-DD` (Gregorian, leap years included).
fn valid_date(s: &str) -> bool {
    let b = s.as_bytes();
    if b.len() != 10 || b[4] != b'-' || b[7] != b'-' {
        return false;
    }
    let num = |r: std::ops::Range<usize>| {
        s.get(r)
            .filter(|d| d.bytes().all(|c| c.is_ascii_digit()))
            .and_then(|d| d.parse::<u32>().ok())
    };
    let (Some(y), Some(m), Some(d)) = (num(0..4), num(5..7), num(8..10)) else {
        return false;
    };
    let leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
    let days = match m {
        1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
        4 | 6 | 9 | 11 => 30,
        2 if leap => 29,
        2 => 28,
        _ => return false,
    };
    (1..=days).contains(&d)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A manifest that is a FIFO, given directly or in its folder, is left
    /// to the reader, which refuses it unopened: telling what a path is
    /// must not open it (the open would wait for a writer).
    #[cfg(unix)]
    #[test]
    fn a_manifest_that_is_a_fifo_is_refused_unopened() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("season.toml");
        crate::make_fifo(&fifo);
        for path in [dir.path(), fifo.as_path()] {
            let e = Season::open(path).unwrap_err().to_string();
            assert!(
                e.contains("season.toml") && e.contains("not a regular file"),
                "{e}"
            );
        }
    }

    /// What is given in an archive's place is named for what it is, with
    /// the archive near it; an archive and its manifest pass.
    #[test]
    fn what_is_no_archive_is_named_with_the_archive_near_it() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        for a in ["a1", "a2"] {
            std::fs::create_dir_all(d.join(a).join("telemetry")).unwrap();
            std::fs::write(d.join(a).join("season.toml"), "name = 'x'\n").unwrap();
        }
        std::fs::write(d.join("a1/telemetry/r.mcap"), b"\x89MCAP0\r\n").unwrap();
        std::fs::write(d.join("a1/kpis.parquet"), b"PAR1....PAR1").unwrap();
        std::fs::create_dir_all(d.join("ds")).unwrap();
        std::fs::write(d.join("ds/dataset.json"), "{}").unwrap();
        std::fs::create_dir_all(d.join("empty")).unwrap();
        let said = |p: &Path| refuse_non_archive(p).unwrap_err().to_string();
        let a1 = d.join("a1").display().to_string();
        for (p, parts) in [
            (
                d.join("a1/kpis.parquet"),
                vec!["it is a Parquet file", "give the archive's folder"],
            ),
            (
                d.join("a1/telemetry/r.mcap"),
                vec!["it is an MCAP file", "the season archive is"],
            ),
            (
                d.join("a1/telemetry"),
                vec!["holds no season.toml; the season archive is"],
            ),
            (
                d.join("ds"),
                vec![
                    "is a dataset written by `tirewear process`",
                    "ds/kpis.parquet",
                ],
            ),
            (d.to_path_buf(), vec!["but its folders", "a1", "a2"]),
            (
                d.join("empty"),
                vec![
                    "not a season archive",
                    "docs/import.md, \"Starting an archive\"",
                ],
            ),
            (
                d.join("missing"),
                vec![
                    "missing: season archive: does not exist",
                    "Starting an archive",
                ],
            ),
            (
                d.join("a1/telemetry/r2.mcap"),
                vec!["does not exist (the season archive near it is"],
            ),
        ] {
            let e = said(&p);
            for part in parts {
                assert!(e.contains(part), "{part} not in {e}");
            }
            if p.starts_with(d.join("a1")) {
                assert!(e.contains(&format!("is {a1}")) || e.ends_with(&a1), "{e}");
            }
        }
        for ok in [d.join("a1"), d.join("a1/season.toml")] {
            assert!(refuse_non_archive(&ok).is_ok(), "{}", ok.display());
        }
    }

    /// An empty tire set id is refused by run and wheel (identifiers are
    /// non-empty, docs/formats.md); the shipped hand-written one passes.
    #[test]
    fn an_empty_tire_set_is_refused_by_run_and_wheel() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/handwritten/season.toml");
        let text = std::fs::read_to_string(&path).unwrap();
        let parse = |t: &str| toml::from_str::<Manifest>(t).unwrap();
        assert!(parse(&text).validate(&path).is_ok());
        for blank in ["\"\"", "\"  \""] {
            let edited = text.replace("RR = \"HS-4\"", &format!("RR = {blank}"));
            let e = parse(&edited).validate(&path).unwrap_err().to_string();
            assert!(
                e.contains("runs[0] id=H1-car1-R1") && e.contains("tire_sets.RR is empty"),
                "{e}"
            );
        }
    }

    #[test]
    fn dates_follow_the_calendar() {
        for ok in ["2026-02-28", "2024-02-29", "2000-02-29", "2026-12-31"] {
            assert!(valid_date(ok), "{ok}");
        }
        for bad in [
            "2026-02-31",
            "2026-02-29",
            "1900-02-29",
            "2026-04-31",
            "2026-13-01",
            "2026-00-10",
            "2026-1-010",
            "+026-01-01",
        ] {
            assert!(!valid_date(bad), "{bad}");
        }
    }
}
