//! Real logger data into a season archive (`tirewear import`,
//! `docs/import.md`): a log (MoTeC `.ld`, MoTeC CSV, generic CSV or
//! Parquet) is read ([`log`], [`ld`]), its channels named through the
//! channel map ([`channel_map`]) and put on one time base ([`align`]); what
//! the logger does not record is estimated from the vehicle description
//! ([`car`], [`estimate`]); the run is written as MCAP in the archive's
//! schema and entered in the manifest.

pub(crate) mod align;
pub mod car;
pub mod channel_map;
pub mod error;
pub mod estimate;
pub(crate) mod ld;
pub mod log;
pub mod units;

pub use car::CarDescription;
pub use channel_map::ChannelMap;
pub use error::ImportError;

use crate::ingest::manifest::{self, Season, TireSets};
use crate::ingest::telemetry::{Encoding, RunInfo, TelemetryWriter};
use estimate::{EventConditions, LateralMethod};
use std::collections::BTreeMap;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// A number as a message quotes it: plainly, or in exponent form where
/// plain digits would run long (`1e308` as such, not 309 digits).
pub(crate) fn shown(x: f64) -> String {
    if x.is_finite() && x != 0.0 && !(1e-4..1e9).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// Where an imported run goes when the manifest does not have it yet.
#[derive(Debug, Clone, Default)]
pub struct NewRun {
    /// Event id; created when absent (then `track` is needed).
    pub event: Option<String>,
    /// Track of a new event.
    pub track: Option<String>,
    pub compound: Option<String>,
    pub tire_sets: Option<TireSets>,
}

/// Settings of an import.
#[derive(Debug, Clone)]
pub struct ImportSettings {
    pub channels: ChannelMap,
    /// Vehicle descriptions: a run already in the manifest uses its car's;
    /// a new run the only one, or the one whose id is the log's vehicle.
    pub cars: Vec<CarDescription>,
    /// Rate (Hz) to put a `.ld` log's channels on (default: the fastest mapped one).
    pub rate_hz: Option<f64>,
    /// Scale the free-rolling wheels' radius so that their median slip
    /// while rolling freely is zero (`estimate::RadiusCheck`).
    pub calibrate_radius: bool,
    pub new_run: NewRun,
}

/// What one log became.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ImportedRun {
    pub log: PathBuf,
    pub run: String,
    /// Telemetry file written (relative to the archive).
    pub telemetry: String,
    pub replaced: bool,
    pub format: String,
    pub samples: usize,
    pub dropped_samples: u64,
    pub rate_hz: f64,
    pub duration_s: f64,
    pub distance_m: f64,
    pub lateral: Option<LateralMethod>,
    /// Channel map: tirewear quantity → source channels (and unit).
    pub mapping: BTreeMap<String, String>,
    pub estimated: Vec<String>,
    pub unmapped: Vec<String>,
    /// Beacon times (s from the log's start) from a `.ldx` sidecar.
    pub beacons_s: Vec<f64>,
    /// The free-rolling wheels' radius checks.
    pub radius_checks: Vec<estimate::RadiusCheck>,
}

/// Days since 1970-01-01 of a `YYYY-MM-DD` date (proleptic Gregorian).
fn days_from_civil(date: &str) -> Option<i64> {
    let p: Vec<i64> = date
        .split('-')
        .map(|x| x.parse().ok())
        .collect::<Option<_>>()?;
    let [y, m, d] = p[..] else {
        return None;
    };
    Some(crate::calendar::days_from_civil(y, m, d))
}

/// Reads one log and writes its run into the archive's manifest copy
/// `manifest` (the caller writes the manifest once, after every log).
pub(crate) fn import_log(
    log_path: &Path,
    run_id: &str,
    season: &Season,
    manifest: &mut manifest::Manifest,
    settings: &ImportSettings,
) -> Result<ImportedRun, ImportError> {
    // Options that contradict the run's entry fail the log before it is
    // read: they were silently ignored, the entry kept as it was.
    if let Some(run) = manifest.runs.iter().find(|r| r.id == run_id)
        && let Some(why) = contradicted_entry(manifest, run, &settings.new_run)
    {
        return Err(ImportError::log(log_path, "run", why));
    }
    let raw = log::read_log(log_path)?;
    let mapping = settings
        .channels
        .map(log_path, &raw.names(), &raw.units())?;
    let aligned = align::align(&raw, &mapping, settings.rate_hz)?;
    if aligned.len() < 2 {
        return Err(ImportError::log(
            log_path,
            "data",
            "fewer than two complete samples",
        ));
    }
    let entry = run_entry(run_id, season, manifest, settings, &raw)?;
    let cond = EventConditions {
        air_c: entry.event.as_ref().map(|e| e.air_temp_c),
        track_c: entry.event.as_ref().map(|e| e.track_temp_c),
    };
    let car = entry.car;
    let est = estimate::estimate(log_path, &aligned, car, cond, settings.calibrate_radius)?;
    // A new run is entered (in the caller's copy of the manifest) before its
    // telemetry is written: what it lacks fails the log with no file left.
    let distance_m = est.vehicle.last().map_or(0.0, |v| v.distance_m);
    if entry.existing.is_none() {
        add_run(
            manifest,
            run_id,
            &entry.event_id,
            &entry.telemetry,
            distance_m,
            &raw.meta,
            &est,
            car,
            settings,
        )
        .map_err(|what| archive_error(season, what))?;
    }
    let info = RunInfo {
        run: run_id.to_string(),
        event: entry.event_id.clone(),
        car: car.id.clone(),
        sample_rate_hz: aligned.rate_hz,
    };
    let map_record = channel_map_record(&mapping, &raw);
    let mut metadata = vec![(
        crate::ingest::telemetry::IMPORT_METADATA,
        run_metadata(log_path, &raw, car, &est),
    )];
    if !raw.meta.beacons_s.is_empty() {
        metadata.push(("tirewear.laps", laps_record(&raw.meta.beacons_s)));
    }
    metadata.push(("tirewear.channel_map", map_record.clone()));
    let start_s = run_start_s(&raw.meta, entry.event.as_ref());
    write_telemetry(
        &season.path(&entry.telemetry),
        &info,
        &aligned,
        &est,
        start_s,
        metadata,
    )?;

    let duration_s = (aligned.index[aligned.len() - 1] - aligned.index[0]) as f64 / aligned.rate_hz;
    Ok(ImportedRun {
        log: log_path.to_path_buf(),
        run: run_id.to_string(),
        telemetry: entry.telemetry,
        replaced: entry.existing.is_some(),
        format: raw.meta.format.clone(),
        samples: aligned.len(),
        dropped_samples: aligned.dropped,
        rate_hz: aligned.rate_hz,
        duration_s,
        distance_m,
        lateral: est.lateral,
        mapping: map_record,
        estimated: est.estimated,
        unmapped: mapping.unmapped,
        beacons_s: raw.meta.beacons_s.clone(),
        radius_checks: est.radius_checks.clone(),
    })
}

/// An error of the archive (its manifest named) for a log's run.
fn archive_error(season: &Season, what: String) -> ImportError {
    ImportError::Archive {
        path: season.manifest_path.clone(),
        what,
    }
}

/// What the manifest has, or the options give, for a log's run.
struct RunEntry<'a> {
    /// The run's index in the manifest; None for a new run.
    existing: Option<usize>,
    event_id: String,
    /// The event's entry (None where the manifest has none yet).
    event: Option<manifest::Event>,
    car: &'a CarDescription,
    /// The run's telemetry file, relative to the archive.
    telemetry: String,
}

/// The run `run_id` of a log: its manifest entry's event, car and
/// telemetry file, or for a new run those the options give (its id must
/// name a file in telemetry/).
fn run_entry<'a>(
    run_id: &str,
    season: &Season,
    manifest: &manifest::Manifest,
    settings: &'a ImportSettings,
    raw: &log::RawLog,
) -> Result<RunEntry<'a>, ImportError> {
    let existing = manifest.runs.iter().position(|r| r.id == run_id);
    // A new run's telemetry goes to telemetry/RUN.mcap: its id must not
    // leave that folder.
    let unsafe_id =
        run_id.is_empty() || run_id.starts_with('.') || run_id.contains(['/', '\\', ':', '\0']);
    if existing.is_none() && unsafe_id {
        return Err(archive_error(
            season,
            format!(
                "run id '{run_id}' cannot name a file in telemetry/ (empty, a leading '.', or '/', '\\', ':')"
            ),
        ));
    }
    let event_id = match existing {
        Some(i) => manifest.runs[i].event.clone(),
        None => settings.new_run.event.clone().ok_or_else(|| {
            archive_error(
                season,
                format!(
                    "run '{run_id}' is not in the manifest: give --event, --compound and --tire-sets"
                ),
            )
        })?,
    };
    let event = manifest.events.iter().find(|e| e.id == event_id).cloned();
    let car = choose_car(
        settings,
        existing.map(|i| manifest.runs[i].car.as_str()),
        &raw.meta.vehicle,
    )
    .map_err(|what| archive_error(season, what))?;
    let telemetry = match existing {
        Some(i) => manifest.runs[i].telemetry.clone(),
        None => format!("telemetry/{run_id}.mcap"),
    };
    Ok(RunEntry {
        existing,
        event_id,
        event,
        car,
        telemetry,
    })
}

/// The run's start (s since the epoch, UTC): the log's date, else its
/// event's, and the log's time of day; the epoch where neither has a date.
fn run_start_s(meta: &log::LogMeta, event: Option<&manifest::Event>) -> u64 {
    meta.date
        .as_deref()
        .or(event.map(|e| e.date.as_str()))
        .and_then(days_from_civil)
        .map_or(0, |d| d.max(0) as u64 * 86_400)
        + meta.time_of_day_s.unwrap_or(0.0) as u64
}

/// Each mapped quantity (with its corner) and the log's channels it was
/// read from, with their unit: the telemetry's `tirewear.channel_map`.
fn channel_map_record(
    mapping: &channel_map::Mapping,
    raw: &log::RawLog,
) -> BTreeMap<String, String> {
    let mut record = BTreeMap::new();
    for m in &mapping.mapped {
        let key = match m.corner {
            Some(w) => format!("{} {}", m.quantity.key(), w.name()),
            None => m.quantity.key().to_string(),
        };
        let names: Vec<&str> = m
            .sources
            .iter()
            .map(|&s| raw.channels[s].name.as_str())
            .collect();
        record.insert(key, format!("{} [{}]", names.join(" + "), m.unit));
    }
    record
}

/// The telemetry's import metadata: the source log, its details, the car
/// description used, what was estimated and the log's own header.
fn run_metadata(
    log_path: &Path,
    raw: &log::RawLog,
    car: &CarDescription,
    est: &estimate::Estimated,
) -> BTreeMap<String, String> {
    let mut meta = BTreeMap::from([
        ("source_file".to_string(), log_path.display().to_string()),
        ("source_format".to_string(), raw.meta.format.clone()),
        ("venue".to_string(), raw.meta.venue.clone()),
        ("vehicle".to_string(), raw.meta.vehicle.clone()),
        ("driver".to_string(), raw.meta.driver.clone()),
        ("session".to_string(), raw.meta.session.clone()),
        (
            "car_description".to_string(),
            toml::to_string(car).unwrap_or_default(),
        ),
    ]);
    meta.insert("estimated".to_string(), est.estimated.join("; "));
    // The log's own header (MoTeC CSV header block, `.ldx` details).
    for (k, v) in &raw.meta.header {
        meta.insert(format!("header: {k}"), v.clone());
    }
    meta
}

/// Beacons (lap markers) from the `.ldx`, in seconds from the log's start:
/// the telemetry's `tirewear.laps`.
fn laps_record(beacons_s: &[f64]) -> BTreeMap<String, String> {
    let beacons = beacons_s
        .iter()
        .map(|t| format!("{t:.6}"))
        .collect::<Vec<_>>()
        .join(",");
    BTreeMap::from([("beacons_s".to_string(), beacons)])
}

/// Writes the run's telemetry to `out_path` (block encoding, a block a
/// second): the metadata records in their order, then every sample.
fn write_telemetry(
    out_path: &Path,
    info: &RunInfo,
    aligned: &align::Aligned,
    est: &estimate::Estimated,
    start_s: u64,
    metadata: Vec<(&str, BTreeMap<String, String>)>,
) -> Result<(), ImportError> {
    if let Some(dir) = out_path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| ImportError::io(dir, e))?;
    }
    let mut writer = TelemetryWriter::create(
        out_path,
        info,
        Encoding::Block,
        aligned.rate_hz.round().max(1.0) as usize,
    )?;
    for (name, record) in metadata {
        writer.write_metadata(name, record)?;
    }
    let period_ns = (1e9 / aligned.rate_hz).round() as u64;
    for (i, k) in aligned.index.iter().enumerate() {
        writer.push(
            start_s * 1_000_000_000 + k * period_ns,
            &est.tires[i],
            &est.vehicle[i],
        )?;
    }
    writer.finish()?;
    Ok(())
}

/// The vehicle description of a run: its manifest car's for a run in the
/// manifest, else the only one given, else the one named by the log.
fn choose_car<'a>(
    settings: &'a ImportSettings,
    manifest_car: Option<&str>,
    log_vehicle: &str,
) -> Result<&'a CarDescription, String> {
    let ids = || {
        settings
            .cars
            .iter()
            .map(|c| c.id.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    };
    match manifest_car {
        Some(id) => settings.cars.iter().find(|c| c.id == id).ok_or_else(|| {
            format!(
                "the run is on car '{id}' in the manifest; no --car describes it (given: {})",
                ids()
            )
        }),
        None if settings.cars.len() == 1 => Ok(&settings.cars[0]),
        None => settings
            .cars
            .iter()
            .find(|c| c.id == log_vehicle.trim())
            .ok_or_else(|| {
                format!(
                    "the log's vehicle is '{log_vehicle}'; no --car has that id (given: {})",
                    ids()
                )
            }),
    }
}

/// What a new run's option (`--event`, `--track`, `--compound`,
/// `--tire-sets`) says against the entry of `run`, already in the
/// manifest, where the two differ: an import replaces only the telemetry
/// of such a run, so a differing option would be dropped without a word.
fn contradicted_entry(
    manifest: &manifest::Manifest,
    run: &manifest::Run,
    new: &NewRun,
) -> Option<String> {
    let track = manifest
        .events
        .iter()
        .find(|e| e.id == run.event)
        .map(|e| e.track.as_str());
    let shown = |t: &manifest::TireSets| format!("FL={},FR={},RL={},RR={}", t.fl, t.fr, t.rl, t.rr);
    let differs = [
        ("--event", new.event.clone(), Some(run.event.clone())),
        ("--track", new.track.clone(), track.map(str::to_string)),
        (
            "--compound",
            new.compound.clone(),
            Some(run.compound.clone()),
        ),
        (
            "--tire-sets",
            new.tire_sets.as_ref().map(shown),
            Some(shown(&run.tire_sets)),
        ),
    ]
    .into_iter()
    .filter_map(|(option, given, entry)| {
        let given = given?;
        (Some(&given) != entry.as_ref()).then(|| {
            format!(
                "{option} {given} (the entry: {})",
                entry.unwrap_or_default()
            )
        })
    })
    .collect::<Vec<_>>();
    if differs.is_empty() {
        return None;
    }
    Some(format!(
        "run '{}' is in the manifest already and an import replaces only its telemetry, \
         but {} differ{}: leave the option out to replace the telemetry, or change the \
         run's entry in season.toml (or import the log under a new --run id)",
        run.id,
        differs.join(", "),
        if differs.len() == 1 { "s" } else { "" }
    ))
}

/// Enters a new run (and, when missing, its event and car) in the manifest.
#[allow(clippy::too_many_arguments)]
fn add_run(
    manifest: &mut manifest::Manifest,
    run_id: &str,
    event_id: &str,
    telemetry: &str,
    distance_m: f64,
    meta: &log::LogMeta,
    est: &estimate::Estimated,
    car: &CarDescription,
    settings: &ImportSettings,
) -> Result<(), String> {
    let nr = &settings.new_run;
    let compound = nr.compound.clone().ok_or("a new run needs --compound")?;
    if !manifest.compounds.iter().any(|c| c.id == compound) {
        return Err(format!("compound '{compound}' is not in the manifest"));
    }
    let tire_sets = nr
        .tire_sets
        .clone()
        .ok_or("a new run needs --tire-sets FL=..,FR=..,RL=..,RR=..")?;
    let known = manifest.events.iter().find(|e| e.id == event_id);
    if let (Some(e), Some(track)) = (known, &nr.track)
        && &e.track != track
    {
        return Err(format!(
            "event '{event_id}' is at track '{}' in the manifest, not '{track}' (--track): \
             leave --track out for a run of a known event, or give the event of that track",
            e.track
        ));
    }
    if known.is_none() {
        let track = nr.track.clone().ok_or(format!(
            "event '{event_id}' is not in the manifest: give --track to create it"
        ))?;
        if !manifest.tracks.iter().any(|t| t.id == track) {
            return Err(format!("track '{track}' is not in the manifest"));
        }
        let date = meta
            .date
            .clone()
            .ok_or("the log has no date to create the event with")?;
        let mean = |f: fn(&crate::ingest::telemetry::proto::VehicleSample) -> f32| {
            est.vehicle.iter().map(|v| f(v) as f64).sum::<f64>() / est.vehicle.len().max(1) as f64
        };
        manifest.events.push(manifest::Event {
            id: event_id.to_string(),
            track,
            date,
            air_temp_c: mean(|v| v.t_air_c),
            track_temp_c: mean(|v| v.t_track_c),
        });
    }
    if !manifest.cars.iter().any(|c| c.id == car.id) {
        let c = car;
        manifest.cars.push(manifest::Car {
            id: c.id.clone(),
            name: if c.name.is_empty() {
                c.id.clone()
            } else {
                c.name.clone()
            },
            mass_kg: c.mass_kg,
            wheelbase_m: c.wheelbase_m,
            front_track_m: c.front_track_m,
            rear_track_m: c.rear_track_m,
        });
    }
    manifest.runs.push(manifest::Run {
        id: run_id.to_string(),
        event: event_id.to_string(),
        car: car.id.clone(),
        compound,
        distance_m: distance_m.max(1.0),
        telemetry: telemetry.to_string(),
        tire_sets,
    });
    Ok(())
}

/// The outcome of importing several logs.
#[derive(Debug, Default, serde::Serialize)]
pub struct ImportSummary {
    pub imported: Vec<ImportedRun>,
    /// Logs that failed, with the error (which begins with the log's path).
    pub failed: Vec<(PathBuf, String)>,
}

/// Imports `logs` (run ids from `run_ids`, same length) into the archive at
/// `archive`, then writes its manifest once (atomically) if any run was
/// imported. One log's failure does not stop the others.
pub fn import_logs(
    archive: &Path,
    logs: &[PathBuf],
    run_ids: &[String],
    settings: &ImportSettings,
) -> Result<ImportSummary, ImportError> {
    let season = Season::open(archive)?;
    let mut manifest = season.manifest.clone();
    let mut summary = ImportSummary::default();
    // Two logs of one run (`logger/*` with both the .ld and the .csv
    // export): the second would silently replace the first's telemetry.
    let mut imported_from: HashMap<&str, &Path> = HashMap::new();
    for (log, run) in logs.iter().zip(run_ids) {
        if let Some(first) = imported_from.get(run.as_str()) {
            let e = ImportError::log(
                log,
                "run",
                format!(
                    "run '{run}' is imported from {} in this call already: give one log per run",
                    first.display()
                ),
            );
            // Debug, not error: the summary carries it, and `tirewear
            // import` prints each failure once (it printed them twice).
            tracing::debug!("{e}");
            summary.failed.push((log.clone(), e.to_string()));
            continue;
        }
        let before = manifest.clone();
        // A panic is this log's error: the others are still imported.
        let outcome =
            crate::guard::catch_panic(|| import_log(log, run, &season, &mut manifest, settings))
                .unwrap_or_else(|msg| {
                    Err(ImportError::log(
                        log,
                        "import",
                        format!(
                            "internal error while importing this log ({msg}); please report it"
                        ),
                    ))
                });
        match outcome {
            Ok(r) => {
                tracing::info!(log = %log.display(), run = %r.run, samples = r.samples, "imported");
                imported_from.insert(run, log);
                summary.imported.push(r);
            }
            Err(e) => {
                // Named by the log even where the error is the manifest's
                // (an unknown compound): in a batch, which log failed.
                let named = log.display().to_string();
                let message = e.to_string();
                let message = if message.starts_with(&named) {
                    message
                } else {
                    format!("{named}: {message}")
                };
                tracing::debug!("{message}");
                manifest = before;
                summary.failed.push((log.clone(), message));
            }
        }
    }
    if summary.imported.iter().any(|r| !r.replaced) {
        manifest.validate(&season.manifest_path)?;
        manifest.write(&season.manifest_path)?;
    }
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn civil_days_by_hand() {
        assert_eq!(days_from_civil("1970-01-01"), Some(0));
        assert_eq!(days_from_civil("2000-03-01"), Some(11_017));
        assert_eq!(days_from_civil("2026-03-02"), Some(20_514));
    }

    #[test]
    fn long_numbers_are_quoted_in_exponent_form() {
        assert_eq!(shown(1e308), "1e308");
        assert_eq!(shown(-3e12), "-3e12");
        assert_eq!(shown(2.5e-7), "2.5e-7");
        assert_eq!(shown(1200.5), "1200.5");
        assert_eq!(shown(0.001), "0.001");
        assert_eq!(shown(0.0), "0");
        assert_eq!(shown(f64::NAN), "NaN");
        assert_eq!(shown(f64::INFINITY), "inf");
    }
}
