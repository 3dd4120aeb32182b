//! `tirewear extract`: a season archive in, the KPI database out.
//!
//! Outputs (all written atomically), for `--out kpis.parquet`:
//! - `kpis.parquet` (and `--csv`): one row per tire and run;
//! - `kpis.road.parquet`: per track and location, the PSD and HDC curves;
//! - `kpis.energy_maps.parquet`: per tire and run, the non-empty bins of both energy maps;
//! - `kpis.condition_maps.parquet`: per tire and run, the non-empty bins of the
//!   condition energy maps (`condition_map::side_table`);
//! - `kpis.report.json`: what was skipped and why, cleaning counts, timings.

use super::cpu::condition_map::ConditionMaps;
use super::cpu::telemetry_reduce::{ReduceBatch, merge};
use super::energy_maps::{EnergyMaps, SLIDING_SPEED_BINS, T_INNER_BINS, T_SURFACE_BINS};
use super::road::{RoadCurves, RoadIndices, mean_indices};
use super::table::{
    KpiRow, kpi_batch, quality, side_table_path, with_estimated, with_extraction_id, write_batch_to,
};
use super::telemetry::{
    CleaningReport, LateralAcceleration, VehicleIndices, finish_wheel, prepare_wheel_into,
    vehicle_indices,
};
use super::viscoelastic::{ViscoelasticIndices, viscoelastic_indices};
use super::wear::{mean_wear, worn_through_readings};
use crate::Wheel;
use crate::engine::{CpuEngine, GpuEngine, ReduceEngine, Reductions};
use crate::ingest::IngestError;
use crate::ingest::compound::Compound;
use crate::ingest::manifest::{Run, Season};
use crate::ingest::road::{Profile, read_profile_csv, read_profiles_parquet_each};
use crate::ingest::telemetry::read_telemetry;
use crate::ingest::wear::{WearReading, check_against_manifest, read_wear_csv};
use crate::memory::{Admission, Held, MemoryBudget, MemoryLimit};
use arrow_array::{Float64Array, RecordBatch, StringArray, UInt32Array};
use arrow_schema::{DataType, Field, Schema};
use rayon::prelude::*;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Which engine reduces the telemetry and roughness.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Engine {
    /// The CPU engine (the library's default, as `ExtractOptions::new`).
    #[default]
    Cpu,
    Gpu,
    /// The GPU when one is usable, else the CPU (with a message saying so).
    Auto,
}

#[derive(Debug, Clone)]
pub struct ExtractOptions {
    pub season: PathBuf,
    pub out: PathBuf,
    pub csv: Option<PathBuf>,
    pub engine: Engine,
    pub progress: bool,
    /// Accept manifest paths outside the archive folder (absolute or `..`).
    pub allow_external_paths: bool,
    /// GPU engine: decode the next runs while the GPU reduces (true, the
    /// default); false decodes and reduces each run in turn, the route
    /// `tirewear bench` compares with.
    pub pipeline: bool,
    /// How much memory the runs decoded at once may need together
    /// (`crate::memory`).
    pub memory_limit: MemoryLimit,
}

impl ExtractOptions {
    /// Extracting `season` into the KPI database `out` on the CPU engine,
    /// without CSV or progress bar, manifest paths kept inside the archive;
    /// set the fields to change any of that.
    pub fn new(season: impl Into<PathBuf>, out: impl Into<PathBuf>) -> Self {
        ExtractOptions {
            season: season.into(),
            out: out.into(),
            csv: None,
            engine: Engine::Cpu,
            progress: false,
            allow_external_paths: false,
            pipeline: true,
            memory_limit: MemoryLimit::Auto,
        }
    }
}

/// A run that produced no rows, and why.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Skipped {
    pub run: String,
    pub file: String,
    pub reason: String,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct ExtractSummary {
    /// Ties this report to the Parquet files written with it (their schema
    /// metadata `tirewear.extraction_id`).
    pub extraction_id: String,
    pub engine: Engine,
    /// The device that ran the reductions.
    pub device: String,
    /// GPU upload / compute / readback time, summed over runs (GPU engine only).
    pub gpu_timings: Option<crate::gpu::GpuTimings>,
    pub rows: usize,
    pub runs: usize,
    pub skipped: Vec<Skipped>,
    /// Problems that left rows in place but a KPI missing (NaN), e.g. no wear readings.
    pub warnings: Vec<String>,
    pub telemetry_samples: u64,
    pub telemetry_bytes: u64,
    pub seconds: f64,
    /// Wall time of decoding and reducing the runs (the rest of `seconds`:
    /// opening the engine, the road profiles, writing the outputs).
    pub runs_seconds: f64,
    /// Seconds summed over runs (all threads): decoding MCAP vs reducing samples.
    pub decode_seconds: f64,
    pub reduce_seconds: f64,
    /// The part of `reduce_seconds` spent cleaning the decoded samples and
    /// laying them out for the engine (derived conditions included).
    pub prepare_seconds: f64,
    pub cleaning: BTreeMap<String, CleaningReport>,
}

impl ExtractSummary {
    pub fn samples_per_second(&self) -> f64 {
        self.telemetry_samples as f64 / self.seconds
    }
}

/// Road indices of every track (mean over its usable profiles) and, for a
/// track whose indices are missing or incomplete, why.
#[derive(Default)]
pub(crate) struct TrackRoads {
    means: HashMap<String, RoadIndices>,
    notes: HashMap<String, String>,
}

/// Reads every road profile. A profile that fails its checks is reported
/// (warning) and left out: it costs its track's road KPIs, not the season.
fn read_profiles(season: &Season, warnings: &mut Vec<String>) -> Result<Vec<Profile>, IngestError> {
    let mut profiles: Vec<Profile> = Vec::new();
    let mut bad = |track: &str, e: IngestError| {
        warnings.push(format!("track {track}: road profile left out: {e}"));
    };
    if let Some(bulk) = &season.manifest.road_profiles {
        for p in read_profiles_parquet_each(&season.path(bulk))? {
            match p {
                Ok(p) => profiles.push(p),
                Err((track, e)) => bad(&track, e),
            }
        }
    }
    // Parsed at once (a serial 50-80 ms of the demo's extraction otherwise),
    // kept and warned about in the manifest's order.
    let files: Vec<_> = season
        .manifest
        .tracks
        .iter()
        .flat_map(|t| t.profiles.iter().map(move |p| (t, p)))
        .collect();
    let read: Vec<_> = files
        .par_iter()
        .map(|(t, p)| read_profile_csv(&season.path(&p.file), &t.id, &p.location))
        .collect();
    for ((t, _), r) in files.iter().zip(read) {
        match r {
            Ok(p) => profiles.push(p),
            Err(e) => bad(&t.id, e),
        }
    }
    Ok(profiles)
}

/// Road indices of every track (mean over locations) and the curves of
/// every profile; with `only`, of those tracks alone.
pub(crate) fn road_kpis(
    season: &Season,
    only: Option<&std::collections::BTreeSet<&str>>,
    warnings: &mut Vec<String>,
    engine: &dyn ReduceEngine,
) -> Result<(TrackRoads, Vec<(Profile, RoadCurves)>), IngestError> {
    let wanted = |track: &str| only.is_none_or(|o| o.contains(track));
    let mut profiles = read_profiles(season, warnings)?;
    profiles.retain(|p| wanted(&p.track));
    let results = engine.road_indices(profiles).map_err(|e| {
        IngestError::invalid(
            &season.root,
            "road profiles",
            format!("{} engine: {e}", engine.name()),
        )
    })?;
    let mut by_track: HashMap<String, Vec<RoadIndices>> = HashMap::new();
    for (p, i, _) in &results {
        by_track.entry(p.track.clone()).or_default().push(*i);
    }
    let mut roads = TrackRoads::default();
    for t in season.manifest.tracks.iter().filter(|t| wanted(&t.id)) {
        let note = match by_track.get(&t.id) {
            Some(v) => {
                let mean = mean_indices(v);
                roads.means.insert(t.id.clone(), mean);
                let undefined = mean.undefined();
                (!undefined.is_empty()).then(|| {
                    format!(
                        "road indices {} undefined: the profiles are too short or too coarse \
                         for them (docs/kpis.md)",
                        undefined.join(", ")
                    )
                })
            }
            None => Some("no usable road profile, its road KPIs are NaN".to_string()),
        };
        if let Some(note) = note {
            warnings.push(format!("track {}: {note}", t.id));
            roads.notes.insert(t.id.clone(), note);
        }
    }
    if season
        .manifest
        .tracks
        .iter()
        .any(|t| wanted(&t.id) && !by_track.contains_key(&t.id))
    {
        let key = "road_profiles or a track's [[tracks.profiles]]";
        warnings.extend(unlisted_warning(season, "road", &["csv", "parquet"], key));
    }
    Ok((roads, results.into_iter().map(|(p, _, c)| (p, c)).collect()))
}

pub(crate) struct RunOutput {
    pub rows: Vec<KpiRow>,
    pub maps: Vec<(Wheel, EnergyMaps, ConditionMaps)>,
    pub cleaning: Vec<(String, CleaningReport)>,
    pub samples: u64,
    pub bytes: u64,
    pub decode_s: f64,
    /// Cleaning, reductions and rows; `prepare_s` of it the cleaning.
    pub reduce_s: f64,
    pub prepare_s: f64,
}

impl RunOutput {
    /// One warning per tire of the run without wear readings.
    pub(crate) fn missing_wear_warnings(&self) -> Vec<String> {
        self.rows
            .iter()
            .filter(|r| r.wear_mean_pct.is_nan())
            .map(|r| {
                format!(
                    "run {} wheel {}: no wear readings, wear_mean_pct is NaN",
                    r.run, r.wheel
                )
            })
            .collect()
    }
}

/// A run decoded and cleaned, its four wheels in one batch: what an engine
/// reduces. Kept apart from the reduction so that the GPU engine reduces
/// one run while the next is decoded (`extract`'s pipelined route).
pub(crate) struct PreparedRun {
    path: PathBuf,
    vehicle: VehicleIndices,
    /// Channels `tirewear import` estimated (the quality flag).
    estimated: Option<String>,
    reports: Vec<CleaningReport>,
    batch: ReduceBatch,
    samples: u64,
    bytes: u64,
    decode_s: f64,
    /// Cleaning and batching, after the decode.
    prepare_s: f64,
}

/// Decodes, checks and cleans one run's telemetry into its batch; a run
/// that cannot make rows (its wear readings contradict the manifest, its
/// compound file is unusable) is refused before its telemetry is read.
fn prepare_run(ctx: &RunContext, run: &Run) -> Result<PreparedRun, String> {
    if let Some(why) = refused_before_read(ctx, run) {
        return Err(why);
    }
    let path = ctx.season.path(&run.telemetry);
    let t0 = Instant::now();
    let tel = read_telemetry(&path).map_err(|e| e.to_string())?;
    let decode_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let vehicle = vehicle_indices(&tel.vehicle).map_err(|e| format!("{}: {e}", path.display()))?;
    let bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
    // Each wheel is cleaned straight into the run's batch, sized once for
    // every sample (a copy per wheel cost 5 % of a one-core extraction).
    let mut batch = ReduceBatch::default();
    batch
        .samples
        .reserve_exact(tel.wheels.iter().map(|s| s.len()).sum());
    let mut reports = Vec::with_capacity(4);
    let mut samples = 0;
    let lateral = ctx
        .season
        .manifest
        .cars
        .iter()
        .find(|c| c.id == run.car)
        .map(|car| LateralAcceleration::new(&tel.wheels, car.mass_kg));
    for w in Wheel::ALL {
        let series = &tel.wheels[w.index()];
        if series.is_empty() {
            return Err(format!(
                "{}: topic {} is missing or empty",
                path.display(),
                w.topic()
            ));
        }
        samples += series.len() as u64;
        let report = batch
            .push_wheel_with(|out| {
                let accel = lateral.as_ref().map_or(&[][..], |a| a.of(w.index()));
                prepare_wheel_into(series, accel, out)
            })
            .map_err(|e| format!("{}: topic {}: {e}", path.display(), w.topic()))?;
        reports.push(report);
    }
    Ok(PreparedRun {
        path,
        vehicle,
        estimated: tel.estimated,
        reports,
        batch,
        samples,
        bytes,
        decode_s,
        prepare_s: t1.elapsed().as_secs_f64(),
    })
}

/// Why a run cannot make rows whatever its telemetry holds: its wear
/// readings contradict the manifest, or its compound file is unusable.
fn refused_before_read(ctx: &RunContext, run: &Run) -> Option<String> {
    if let Some(p) = ctx.wear_problems.get(&run.id) {
        return Some(p.clone());
    }
    if let Some(Err(e)) = ctx.compounds.get(&run.compound) {
        return Some(format!("compound {}: {e}", run.compound));
    }
    None
}

/// Heap bytes a run in block form needs per byte of its decompressed
/// messages, while [`prepare_run`] holds both the decoded columns (a wheel
/// sample's 11 floats and its time: 52 bytes for the 44 it takes in a
/// block) and the engine's batch (80 bytes a wheel sample), then the
/// reductions. Measured by `tests/robustness.rs`
/// (`a_runs_memory_need_bounds_its_peak_heap`): 2.8 of heap, some 3.1
/// resident; a block cannot hold a sample in fewer bytes.
const HEAP_PER_MESSAGE_BYTE: f64 = 3.5;

/// Heap a run in per-sample form needs per message (one sample of one
/// topic, which may take only a few bytes in the file): a wheel sample's
/// decoded 52 bytes and batched 80, and room for the lateral acceleration
/// (a vehicle message needs 28). Measured: 104 a message on average.
const HEAP_PER_SAMPLE_MESSAGE: u64 = 144;

/// Heap a run needs whatever its length: the reductions' histograms and
/// tables, the decoders' buffers (a whole 5 Hz extraction takes 2.6 MB).
const HEAP_PER_RUN: u64 = 8 << 20;

/// The memory a run needs to be decoded and reduced, estimated from its
/// telemetry's headers before it is read; or why it cannot be admitted.
/// A run refused on other grounds, or whose file cannot be opened, needs
/// nothing (reading it fails at once, with the reason).
fn memory_need(ctx: &RunContext, run: &Run) -> Result<u64, String> {
    if refused_before_read(ctx, run).is_some() {
        return Ok(0);
    }
    let path = ctx.season.path(&run.telemetry);
    let Ok(need) = run_memory_need(&path) else {
        return Ok(0);
    };
    match ctx.memory.refuses(need) {
        Some(why) => Err(format!("{}: {why}", path.display())),
        None => Ok(need),
    }
}

/// The heap, in bytes, that extracting the run whose telemetry is `path`
/// needs, estimated from the MCAP file's record headers without reading
/// its messages: [`HEAP_PER_RUN`] plus [`HEAP_PER_MESSAGE_BYTE`] per byte
/// of its decompressed messages, or [`HEAP_PER_SAMPLE_MESSAGE`] per message
/// of a per-sample file. `extract` and `process` admit runs by it;
/// a scheduler can size a machine or a job by it too.
pub fn run_memory_need(path: &Path) -> Result<u64, IngestError> {
    let volume = crate::ingest::telemetry::message_volume(path)?;
    let messages = match volume.per_sample_messages {
        Some(n) => n.saturating_mul(HEAP_PER_SAMPLE_MESSAGE),
        None => (volume.bytes as f64 * HEAP_PER_MESSAGE_BYTE) as u64,
    };
    Ok(HEAP_PER_RUN.saturating_add(messages))
}

/// What every run's rows are built from, apart from its own telemetry.
pub(crate) struct RunContext<'a> {
    pub season: &'a Season,
    pub compounds: &'a HashMap<String, Result<Compound, String>>,
    pub roads: &'a TrackRoads,
    /// (mean wear %, worn-through readings) per tire.
    pub wear: &'a BTreeMap<(String, Wheel), (f64, f64)>,
    /// Runs whose wear readings contradict the manifest, and how.
    pub wear_problems: &'a HashMap<String, String>,
    /// How much memory the runs in flight may need together.
    pub memory: &'a MemoryBudget,
}

/// Reduces a prepared run on `engine`.
fn reduce_run(
    ctx: &RunContext,
    run: &Run,
    p: PreparedRun,
    engine: &dyn ReduceEngine,
) -> Result<RunOutput, String> {
    let t = Instant::now();
    let all = engine
        .reductions(&p.batch)
        .map_err(|e| format!("{}: {} engine: {e}", p.path.display(), engine.name()))?;
    let reduce_s = t.elapsed().as_secs_f64();
    finish_run(ctx, run, p, all, reduce_s)
}

/// A run's rows from its reductions.
fn finish_run(
    ctx: &RunContext,
    run: &Run,
    p: PreparedRun,
    all: Reductions,
    reduce_s: f64,
) -> Result<RunOutput, String> {
    let t = Instant::now();
    let PreparedRun {
        path,
        vehicle,
        estimated,
        reports,
        batch,
        samples,
        bytes,
        decode_s,
        prepare_s,
    } = p;
    let compound = ctx.compounds[&run.compound]
        .as_ref()
        .map_err(|e| format!("compound {}: {e}", run.compound))?;
    let event = ctx.season.event(&run.event).expect("validated manifest");
    let roads = ctx.roads;
    let road = roads
        .means
        .get(&event.track)
        .copied()
        .unwrap_or(RoadIndices::UNDEFINED);
    let mut out = RunOutput {
        rows: vec![],
        maps: vec![],
        cleaning: vec![],
        samples,
        bytes,
        decode_s,
        reduce_s: 0.0,
        prepare_s,
    };
    let sums = merge(&batch, &all.partials);
    let maps = all.energy_maps.into_iter().zip(all.condition_maps);
    for (i, ((w, rep), (maps, conditions))) in
        Wheel::ALL.into_iter().zip(reports).zip(maps).enumerate()
    {
        let k = finish_wheel(&sums[i], &batch.refs[i])
            .map_err(|e| format!("{}: topic {}: {e}", path.display(), w.topic()))?;
        let sliding_speed = k.sliding_distance_m / k.duration_s;
        let mut reasons = Vec::new();
        if let Some(note) = roads.notes.get(&event.track) {
            reasons.push(format!("track {}: {note}", event.track));
        }
        let ve = viscoelastic_indices(
            compound,
            sliding_speed,
            road.macro_wavelength_mm,
            k.t_surface_avg_c,
        )
        .unwrap_or_else(|e| {
            reasons.push(format!("viscoelastic: {e}"));
            ViscoelasticIndices::UNDEFINED
        });
        let wear_of_tire = ctx.wear.get(&(run.id.clone(), w));
        if wear_of_tire.is_none() {
            reasons.push("no wear readings".into());
        }
        let mut row = KpiRow {
            event: run.event.clone(),
            track: event.track.clone(),
            car: run.car.clone(),
            run: run.id.clone(),
            wheel: w,
            axle: w.axle(),
            compound: run.compound.clone(),
            tire_set: run.tire_sets.get(w).into(),
            quality: String::new(),
            t_surface_avg_c: k.t_surface_avg_c,
            t_surface_std_c: k.t_surface_std_c,
            t_inner_avg_c: k.t_inner_avg_c,
            t_inner_std_c: k.t_inner_std_c,
            t_track_avg_c: vehicle.t_track_avg_c,
            t_air_avg_c: vehicle.t_air_avg_c,
            fx_avg_n: k.fx_avg_n,
            fx_std_n: k.fx_std_n,
            fy_avg_n: k.fy_avg_n,
            fy_std_n: k.fy_std_n,
            fz_avg_n: k.fz_avg_n,
            fz_std_n: k.fz_std_n,
            vsx_avg_mps: k.vsx_avg_mps,
            vsx_std_mps: k.vsx_std_mps,
            vsy_avg_mps: k.vsy_avg_mps,
            vsy_std_mps: k.vsy_std_mps,
            friction_energy_x_j: k.friction_energy_x_j,
            friction_energy_y_j: k.friction_energy_y_j,
            friction_energy_j: k.friction_energy_j,
            sliding_distance_m: k.sliding_distance_m,
            camber_avg_deg: k.camber_avg_deg,
            pressure_avg_pa: k.pressure_avg_pa,
            contact_patch_mm2: k.contact_patch_mm2,
            distance_m: vehicle.distance_m,
            macro_wavelength_mm: road.macro_wavelength_mm,
            micro_wavelength_mm: road.micro_wavelength_mm,
            hurst: road.hurst,
            hurst_hdc: road.hurst_hdc,
            ra_macro_mm: road.ra_macro_mm,
            ra_micro_mm: road.ra_micro_mm,
            peakyness_mm: road.peakyness_mm,
            skewness: road.skewness,
            kurtosis: road.kurtosis,
            rq_mm: road.rq_mm,
            ra_mm: road.ra_mm,
            solicitation_frequency_hz: ve.solicitation_frequency_hz,
            shifted_temperature_c: ve.shifted_temperature_c,
            storage_modulus_mpa: ve.storage_modulus_mpa,
            loss_factor: ve.loss_factor,
            wear_mean_pct: wear_of_tire.map_or(f64::NAN, |t| t.0),
            telemetry_duration_s: k.duration_s,
            dropout_time_s: rep.dropout_time_s,
            invalid_samples: (rep.samples - rep.kept) as f64,
            worn_through_readings: wear_of_tire.map_or(0.0, |t| t.1),
        };
        row.quality = quality(&row, &reasons);
        if let Some(est) = &estimated {
            row.quality = with_estimated(&row.quality, est);
        }
        out.rows.push(row);
        out.maps.push((w, maps, conditions));
        out.cleaning.push((format!("{}/{}", run.id, w), rep));
    }
    out.reduce_s = prepare_s + reduce_s + t.elapsed().as_secs_f64();
    Ok(out)
}

/// What every run of a season shares: its compounds, its wear readings
/// reduced per tire, and the problems found while reading them.
pub(crate) struct SeasonInputs {
    /// Each compound, or why its file could not be used.
    pub compounds: HashMap<String, Result<Compound, String>>,
    /// (mean wear %, worn-through readings) per tire.
    pub wear: BTreeMap<(String, Wheel), (f64, f64)>,
    /// Runs whose wear readings contradict the manifest, and how.
    pub wear_problems: HashMap<String, String>,
    /// The raw readings of each run, in file order.
    pub readings: HashMap<String, Vec<WearReading>>,
    pub warnings: Vec<String>,
}

/// Where some tires or tracks lack their data: the files of the archive's
/// `folder` the manifest does not list (under `key`), which are not read.
fn unlisted_warning(
    season: &Season,
    folder: &str,
    extensions: &[&str],
    key: &str,
) -> Option<String> {
    let files = season.unlisted(folder, extensions);
    (!files.is_empty()).then(|| {
        format!(
            "{}: in the archive's {folder}/ folder but not listed in {} ({key}), so not read",
            files.join(", "),
            season.manifest_path.display()
        )
    })
}

/// Reads a season's compounds and wear readings. A bad compound file fails
/// the runs on that compound, not the season.
pub(crate) fn season_inputs(season: &Season) -> Result<SeasonInputs, IngestError> {
    let m = &season.manifest;
    let mut warnings = Vec::new();
    let compounds: HashMap<String, Result<Compound, String>> = m
        .compounds
        .iter()
        .map(|c| {
            let loaded = Compound::load(&season.path(&c.file))
                .and_then(|k| k.check_id(&c.id, &season.path(&c.file)).map(|_| k))
                .map_err(|e| e.to_string());
            if let Err(e) = &loaded {
                warnings.push(format!("compound {}: {e}", c.id));
            }
            (c.id.clone(), loaded)
        })
        .collect();
    let mut wear_problems: HashMap<String, String> = HashMap::new();
    let mut readings = Vec::new();
    for f in &m.wear_readings {
        let path = season.path(f);
        let file_readings = read_wear_csv(&path)?;
        for p in check_against_manifest(&path, &file_readings, m) {
            match p.run {
                Some(run) => {
                    wear_problems.entry(run).or_insert(p.what);
                }
                None => warnings.push(p.what),
            }
        }
        readings.extend(file_readings);
    }
    let worn = worn_through_readings(&readings);
    let wear: BTreeMap<(String, Wheel), (f64, f64)> = mean_wear(&readings)
        .into_iter()
        .map(|(k, m)| {
            let z = worn.get(&k).copied().unwrap_or(0.0);
            (k, (m, z))
        })
        .collect();
    let without_readings = m.runs.iter().any(|r| {
        Wheel::ALL
            .iter()
            .any(|&w| !wear.contains_key(&(r.id.clone(), w)))
    });
    if without_readings {
        warnings.extend(unlisted_warning(season, "wear", &["csv"], "wear_readings"));
    }
    let mut by_run: HashMap<String, Vec<WearReading>> = HashMap::new();
    for r in readings {
        by_run.entry(r.run.clone()).or_default().push(r);
    }
    Ok(SeasonInputs {
        compounds,
        wear,
        wear_problems,
        readings: by_run,
        warnings,
    })
}

/// Runs in flight between the decoding threads and the GPU: enough that
/// the GPU finds the next batch ready, few enough to bound the memory
/// (each is one run's cleaned samples, 48 bytes a wheel sample).
const PIPELINE_DEPTH: usize = 2;

/// Every run's rows and maps, or why it was skipped (a panic met by a run's
/// data skips that run too), handed to `done` as each run finishes, whose
/// answers come back in the order of `runs`.
///
/// The CPU engine decodes and reduces each run on the rayon threads. With
/// `pipelined` (meant for the GPU engine) the rayon threads decode and
/// clean while one more thread feeds the engine: the GPU reduces one run
/// while the next is decoded, instead of the decoding thread waiting for
/// the device (`tirewear bench` measures both routes).
///
/// Runs start in order, each once its memory need fits beside those in
/// flight ([`crate::memory::Admission`]; a run is in flight from its start
/// until `done` has its outputs); a run that alone needs more than the
/// budget is skipped, saying so.
pub(crate) fn extract_runs<T: Send>(
    ctx: &RunContext,
    runs: &[&Run],
    engine: &dyn ReduceEngine,
    pipelined: bool,
    done: impl Fn(usize, Result<RunOutput, String>) -> T + Sync,
) -> Vec<T> {
    // A panic in the estimate (a bug) costs the run its estimate only: its
    // read then meets the same bytes under the run's own net.
    let needs: Vec<Result<u64, String>> = runs
        .par_iter()
        .map(|r| crate::guard::catch_panic(|| memory_need(ctx, r)).unwrap_or(Ok(0)))
        .collect();
    let admission = Admission::new(ctx.memory);
    let (admission, done) = (&admission, &done);
    if !pipelined {
        let out: Vec<Mutex<Option<T>>> = runs.iter().map(|_| Mutex::new(None)).collect();
        let put = |i: usize, t: T| *out[i].lock().unwrap_or_else(|p| p.into_inner()) = Some(t);
        rayon::in_place_scope(|s| {
            for (i, (run, need)) in runs.iter().zip(&needs).enumerate() {
                let need = match need {
                    Ok(need) => *need,
                    Err(why) => {
                        put(i, done(i, Err(why.clone())));
                        continue;
                    }
                };
                let held = admission.admit(need);
                let put = &put;
                s.spawn(move |_| {
                    let r = guarded(|| reduce_run(ctx, run, prepare_run(ctx, run)?, engine));
                    let t = done(i, r);
                    drop(held);
                    put(i, t);
                });
            }
        });
        return out
            .into_iter()
            .map(|m| m.into_inner().unwrap_or_else(|p| p.into_inner()))
            .map(|t| t.expect("every run done once"))
            .collect();
    }
    // Each prepared run travels with its admitted need, given back once
    // the reducer has handed its outputs on (or dropped with the channel).
    type Prepared<'a> = (usize, Result<PreparedRun, String>, Option<Held<'a>>);
    let (tx, rx) = std::sync::mpsc::sync_channel::<Prepared>(PIPELINE_DEPTH);
    std::thread::scope(|scope| {
        let reducer = scope.spawn(move || {
            let mut out: Vec<Option<T>> = (0..runs.len()).map(|_| None).collect();
            for (i, prepared, held) in rx {
                let r = prepared.and_then(|p| guarded(|| reduce_run(ctx, runs[i], p, engine)));
                out[i] = Some(done(i, r));
                drop(held);
            }
            out
        });
        rayon::in_place_scope(|s| {
            for (i, (run, need)) in runs.iter().zip(&needs).enumerate() {
                // A send fails only when the reducer has stopped (its own
                // panic, resumed below); the run is then lost with it.
                let need = match need {
                    Ok(need) => *need,
                    Err(why) => {
                        let _ = tx.send((i, Err(why.clone()), None));
                        continue;
                    }
                };
                let held = admission.admit(need);
                let tx = tx.clone();
                s.spawn(move |_| {
                    let _ = tx.send((i, guarded(|| prepare_run(ctx, run)), Some(held)));
                });
            }
        });
        drop(tx);
        reducer
            .join()
            .unwrap_or_else(|p| std::panic::resume_unwind(p))
            .into_iter()
            .map(|t| t.expect("every run sent once"))
            .collect()
    })
}

/// The engine to use: `gpu` needs an adapter; `auto` takes a hardware GPU
/// and otherwise the CPU engine (a software adapter such as lavapipe is
/// slower than the CPU engine it emulates), saying why.
pub(crate) fn open_engine(
    choice: Engine,
) -> Result<(Engine, Option<GpuEngine>), crate::gpu::GpuError> {
    match choice {
        Engine::Cpu => Ok((Engine::Cpu, None)),
        Engine::Gpu => Ok((Engine::Gpu, Some(GpuEngine::new()?))),
        // A software adapter is refused before its device and kernels are
        // built: that cost 0.1–0.35 s of every extraction on a machine with
        // lavapipe and no GPU.
        Engine::Auto => match GpuEngine::new_hardware() {
            Ok(Ok(g)) => Ok((Engine::Gpu, Some(g))),
            Ok(Err(software)) => {
                tracing::info!(
                    "engine auto: the only GPU adapter is a software one ({}); using the CPU engine (the gpu engine forces it)",
                    software.name
                );
                Ok((Engine::Cpu, None))
            }
            Err(e) => {
                tracing::info!("engine auto: {e}; using the CPU engine");
                Ok((Engine::Cpu, None))
            }
        },
    }
}

/// Extracts the KPI database of a season. One damaged run fails only itself.
pub fn extract(opts: &ExtractOptions) -> Result<ExtractSummary, IngestError> {
    let start = Instant::now();
    let (engine, reducer) = open_engine(opts.engine).map_err(|e| {
        IngestError::invalid(
            &opts.season,
            "gpu engine",
            format!("{e} (the cpu and auto engines need no GPU)"),
        )
    })?;
    let reducer_gpu = reducer.as_ref();
    let reducer: &dyn ReduceEngine = match reducer_gpu {
        Some(g) => g,
        None => &CpuEngine,
    };
    let season = Season::open_with(&opts.season, opts.allow_external_paths)?;
    check_outputs(opts, &season)?;
    let m = &season.manifest;
    if m.runs.is_empty() {
        return Err(IngestError::invalid(
            &season.manifest_path,
            "runs",
            "the manifest lists no runs, so there is nothing to extract and nothing was \
             written (`tirewear import` adds runs from logs: docs/import.md)",
        ));
    }
    let SeasonInputs {
        compounds,
        wear,
        wear_problems,
        mut warnings,
        ..
    } = season_inputs(&season)?;
    let (roads, curves) = road_kpis(&season, None, &mut warnings, reducer)?;

    let pb = crate::progress::bar(opts.progress, m.runs.len() as u64, "extracting runs");
    let memory = MemoryBudget::resolve(opts.memory_limit);
    let ctx = RunContext {
        season: &season,
        compounds: &compounds,
        roads: &roads,
        wear: &wear,
        wear_problems: &wear_problems,
        memory: &memory,
    };
    let runs: Vec<&Run> = m.runs.iter().collect();
    let pipelined = reducer_gpu.is_some() && opts.pipeline;
    let runs_start = Instant::now();
    let results: Vec<(&Run, Result<RunOutput, String>)> =
        extract_runs(&ctx, &runs, reducer, pipelined, |i, r| {
            pb.inc(1);
            (runs[i], r)
        });
    pb.finish_and_clear();
    let runs_seconds = runs_start.elapsed().as_secs_f64();

    let mut rows = Vec::new();
    let mut maps = Vec::new();
    let mut conditions = Vec::new();
    let mut skipped = Vec::new();
    let mut cleaning = BTreeMap::new();
    let (mut samples, mut bytes) = (0, 0);
    let (mut decode_s, mut reduce_s, mut prepare_s) = (0.0, 0.0, 0.0);
    for (run, r) in results {
        match r {
            Ok(o) => {
                warnings.extend(o.missing_wear_warnings());
                for (w, mp, c) in o.maps {
                    maps.push((run.id.clone(), w, mp));
                    conditions.push((run.id.clone(), w, c));
                }
                rows.extend(o.rows);
                cleaning.extend(o.cleaning);
                samples += o.samples;
                bytes += o.bytes;
                decode_s += o.decode_s;
                reduce_s += o.reduce_s;
                prepare_s += o.prepare_s;
            }
            Err(reason) => {
                tracing::warn!("run {} skipped: {reason}", run.id);
                skipped.push(Skipped {
                    run: run.id.clone(),
                    file: run.telemetry.clone(),
                    reason,
                });
            }
        }
    }
    if skipped.len() == m.runs.len() {
        // No summary will carry the season's warnings (a file not listed,
        // a compound left out), and they may say why.
        for w in &warnings {
            tracing::warn!("{w}");
        }
        return Err(nothing_read(opts, &skipped));
    }
    let extraction_id = new_extraction_id();
    let summary = ExtractSummary {
        extraction_id: extraction_id.clone(),
        engine,
        device: reducer.device(),
        gpu_timings: reducer_gpu.map(GpuEngine::timings),
        rows: rows.len(),
        runs: m.runs.len(),
        skipped,
        warnings,
        telemetry_samples: samples,
        telemetry_bytes: bytes,
        seconds: start.elapsed().as_secs_f64(),
        runs_seconds,
        decode_seconds: decode_s,
        reduce_seconds: reduce_s,
        prepare_seconds: prepare_s,
        cleaning,
    };
    let maps = SideMaps {
        energy: &maps,
        conditions: &conditions,
    };
    write_outputs(opts, &extraction_id, &rows, &curves, maps, &summary)?;
    Ok(summary)
}

/// The error for an extraction that could read none of its runs: an empty
/// table written over the last good one would lose it (a telemetry mount
/// down, a sync half done), and no later step has anything to work on.
fn nothing_read(opts: &ExtractOptions, skipped: &[Skipped]) -> IngestError {
    const SHOWN: usize = 3;
    let mut why: Vec<String> = skipped
        .iter()
        .take(SHOWN)
        .map(|k| format!("run {}: {}", k.run, k.reason))
        .collect();
    if skipped.len() > SHOWN {
        why.push(format!(
            "and {} more (each logged as a warning)",
            skipped.len() - SHOWN
        ));
    }
    IngestError::invalid(
        &opts.season,
        "runs",
        format!(
            "none of its {} runs could be read, so nothing was written ({} and its side \
             tables are as they were): {}",
            skipped.len(),
            opts.out.display(),
            why.join("; ")
        ),
    )
}

/// Runs `f`, turning a panic into an error: a bug met by one run's data
/// skips that run (with the panic's message) instead of ending the season.
fn guarded<T>(f: impl FnOnce() -> Result<T, String>) -> Result<T, String> {
    crate::guard::catch_panic(f).unwrap_or_else(|msg| {
        Err(format!(
            "internal error while extracting this run ({msg}); please report it"
        ))
    })
}

/// A fresh id for one extraction's outputs (time and process, hex).
fn new_extraction_id() -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    format!("{nanos:x}-{:x}", std::process::id())
}

/// Every file an extraction writes, with what it is.
fn output_paths(opts: &ExtractOptions) -> Vec<(&'static str, PathBuf)> {
    let side = |suffix| side_table_path(&opts.out, suffix);
    let mut outputs = vec![
        ("KPI table", opts.out.clone()),
        ("road side table", side("road.parquet")),
        ("energy-map side table", side("energy_maps.parquet")),
        ("condition-map side table", side("condition_maps.parquet")),
        ("extraction report", side("report.json")),
    ];
    outputs.extend(opts.csv.iter().map(|c| ("CSV copy", c.clone())));
    outputs
}

/// Refuses, before any run is read, outputs that would replace one of the
/// season's files or each other, or that name a folder.
fn check_outputs(opts: &ExtractOptions, season: &Season) -> Result<(), IngestError> {
    let outputs = output_paths(opts);
    let outputs: Vec<(&str, &Path)> = outputs.iter().map(|(w, p)| (*w, p.as_path())).collect();
    crate::atomic::check_destinations(&outputs, &season.input_files()).map_err(|c| {
        let hint = if c.dest == opts.out && c.dest.is_dir() {
            format!(" such as {}", opts.out.join("kpis.parquet").display())
        } else {
            String::new()
        };
        IngestError::invalid(&c.dest, "output", format!("{}{hint}", c.reason))
    })
}

/// The per-tire maps of one extraction.
struct SideMaps<'a> {
    energy: &'a [(String, Wheel, EnergyMaps)],
    conditions: &'a [(String, Wheel, ConditionMaps)],
}

/// Writes every output of one extraction as one set: all become visible
/// together, each Parquet file and the report carrying `extraction_id`.
fn write_outputs(
    opts: &ExtractOptions,
    extraction_id: &str,
    rows: &[KpiRow],
    curves: &[(Profile, RoadCurves)],
    maps: SideMaps,
    summary: &ExtractSummary,
) -> Result<(), IngestError> {
    let stem = opts
        .out
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("kpis");
    let journal = opts.out.with_file_name(format!(".{stem}.commit.json"));
    let io = |p: &Path| {
        let p = p.to_path_buf();
        move |e| IngestError::io(p, e)
    };
    let mut set = crate::atomic::OutputSet::new(&journal).map_err(io(&journal))?;
    let tables = encode_tables(opts, extraction_id, rows, curves, maps);
    for (dest, bytes) in tables {
        set.add(&dest, |f| std::io::Write::write_all(f, &bytes?))
            .map_err(io(&dest))?;
    }
    if let Some(csv) = &opts.csv {
        set.add(csv, |f| {
            crate::atomic::csv_to(std::io::BufWriter::new(f), rows)
        })
        .map_err(io(csv))?;
    }
    let report = side_table_path(&opts.out, "report.json");
    let text = serde_json::to_string_pretty(summary)
        .map_err(|e| IngestError::invalid(&report, "report", e.to_string()))?;
    let text = crate::ingest::checksum::seal_json(&text);
    set.add(&report, |f| std::io::Write::write_all(f, text.as_bytes()))
        .map_err(io(&report))?;
    set.commit().map_err(io(&journal))
}

/// The extraction's four Parquet tables (KPIs, road curves, energy maps,
/// condition maps), each built and encoded on a thread of its own: after
/// the runs, this is the serial part of an extraction, and the condition
/// maps' table alone took 140–180 ms of the demo's 200 ms there
/// (docs/performance.md). Returned in that order, as (file, bytes).
fn encode_tables(
    opts: &ExtractOptions,
    extraction_id: &str,
    rows: &[KpiRow],
    curves: &[(Profile, RoadCurves)],
    maps: SideMaps,
) -> Vec<(PathBuf, std::io::Result<Vec<u8>>)> {
    let encode = |build: &(dyn Fn() -> RecordBatch + Sync)| {
        let mut bytes = Vec::new();
        write_batch_to(&mut bytes, &with_extraction_id(build(), extraction_id)).map(|()| bytes)
    };
    let tables: [(PathBuf, &(dyn Fn() -> RecordBatch + Sync)); 4] = [
        (opts.out.clone(), &|| kpi_batch(rows)),
        (side_table_path(&opts.out, "road.parquet"), &|| {
            road_curves_batch(curves)
        }),
        (side_table_path(&opts.out, "energy_maps.parquet"), &|| {
            energy_maps_batch(maps.energy)
        }),
        (
            side_table_path(&opts.out, "condition_maps.parquet"),
            &|| crate::kpi::cpu::condition_map::side_table(maps.conditions),
        ),
    ];
    tables
        .into_par_iter()
        .map(|(dest, build)| (dest, encode(build)))
        .collect()
}

/// Side table of road curves: track, location, curve ("psd" or "hdc"), x, y.
pub(crate) fn road_curves_batch(curves: &[(Profile, RoadCurves)]) -> RecordBatch {
    let (mut t, mut l, mut k, mut x, mut y) = (vec![], vec![], vec![], vec![], vec![]);
    for (p, c) in curves {
        for (kind, xs, ys) in [
            ("psd", &c.psd_q, &c.psd_c),
            ("hdc", &c.hdc_lag_mm, &c.hdc_c),
        ] {
            for (a, b) in xs.iter().zip(ys.iter()) {
                t.push(p.track.clone());
                l.push(p.location.clone());
                k.push(kind);
                x.push(*a);
                y.push(*b);
            }
        }
    }
    let schema = Arc::new(Schema::new(vec![
        Field::new("track", DataType::Utf8, false),
        Field::new("location", DataType::Utf8, false),
        Field::new("curve", DataType::Utf8, false),
        Field::new("x", DataType::Float64, false),
        Field::new("y", DataType::Float64, false),
    ]));
    RecordBatch::try_new(
        schema,
        vec![
            Arc::new(StringArray::from(t)),
            Arc::new(StringArray::from(l)),
            Arc::new(StringArray::from(k)),
            Arc::new(Float64Array::from(x)),
            Arc::new(Float64Array::from(y)),
        ],
    )
    .expect("columns match the schema")
}

/// One point of a road curve read back from `NAME.road.parquet`.
#[derive(Debug, Clone, PartialEq)]
pub struct RoadCurvePoint {
    pub track: String,
    pub location: String,
    /// `psd` (x: wavenumber q in rad/mm, y: C(q) in mm⁴) or `hdc` (x: lag in
    /// mm, y: height-difference correlation in mm²).
    pub curve: String,
    pub x: f64,
    pub y: f64,
}

/// Reads the road-curve side table (`NAME.road.parquet`, as
/// [`road_curves_batch`] writes it); a missing column or a null is an
/// error naming the file, column and row.
pub(crate) fn read_road_curves(path: &std::path::Path) -> Result<Vec<RoadCurvePoint>, IngestError> {
    let mut out = Vec::new();
    for batch in super::table::side_batches(path)? {
        let batch = batch?;
        let col = |name: &str, ty: &DataType| {
            super::table::checked_column(path, &batch, name, ty, out.len())
        };
        let text = |name: &str| -> Result<StringArray, IngestError> {
            Ok(col(name, &DataType::Utf8)?
                .as_any()
                .downcast_ref::<StringArray>()
                .expect("cast to Utf8")
                .clone())
        };
        let number = |name: &str| -> Result<Float64Array, IngestError> {
            Ok(col(name, &DataType::Float64)?
                .as_any()
                .downcast_ref::<Float64Array>()
                .expect("cast to Float64")
                .clone())
        };
        let (t, l, c) = (text("track")?, text("location")?, text("curve")?);
        let (x, y) = (number("x")?, number("y")?);
        for k in 0..batch.num_rows() {
            out.push(RoadCurvePoint {
                track: t.value(k).to_string(),
                location: l.value(k).to_string(),
                curve: c.value(k).to_string(),
                x: x.value(k),
                y: y.value(k),
            });
        }
    }
    Ok(out)
}

/// Columns of the energy-map side table.
#[derive(Default)]
struct MapRows {
    run: Vec<String>,
    wheel: Vec<&'static str>,
    map: Vec<&'static str>,
    i: Vec<u32>,
    j: Vec<u32>,
    x_lo: Vec<f64>,
    y_lo: Vec<f64>,
    energy_j: Vec<f64>,
}

/// Side table of energy maps: run, wheel, map, i, j, x_lo, y_lo, energy_j (non-empty bins).
pub(crate) fn energy_maps_batch(maps: &[(String, Wheel, EnergyMaps)]) -> RecordBatch {
    let mut c = MapRows::default();
    for (run, w, m) in maps {
        for (name, data, xb, yb) in [
            (
                "surface_inner",
                &m.surface_inner,
                T_SURFACE_BINS,
                T_INNER_BINS,
            ),
            (
                "speed_surface",
                &m.speed_surface,
                SLIDING_SPEED_BINS,
                T_SURFACE_BINS,
            ),
            (
                "lateral_surface_inner",
                &m.lateral_surface_inner,
                T_SURFACE_BINS,
                T_INNER_BINS,
            ),
        ] {
            for (idx, &e) in data.iter().enumerate() {
                if e == 0.0 {
                    continue;
                }
                let (i, j) = (idx / yb.n, idx % yb.n);
                c.run.push(run.clone());
                c.wheel.push(w.name());
                c.map.push(name);
                c.i.push(i as u32);
                c.j.push(j as u32);
                c.x_lo.push(xb.lower_edge(i));
                c.y_lo.push(yb.lower_edge(j));
                c.energy_j.push(e);
            }
        }
    }
    let schema = Arc::new(Schema::new(vec![
        Field::new("run", DataType::Utf8, false),
        Field::new("wheel", DataType::Utf8, false),
        Field::new("map", DataType::Utf8, false),
        Field::new("i", DataType::UInt32, false),
        Field::new("j", DataType::UInt32, false),
        Field::new("x_lo", DataType::Float64, false),
        Field::new("y_lo", DataType::Float64, false),
        Field::new("energy_j", DataType::Float64, false),
    ]));
    RecordBatch::try_new(
        schema,
        vec![
            Arc::new(StringArray::from(c.run)),
            Arc::new(StringArray::from(c.wheel)),
            Arc::new(StringArray::from(c.map)),
            Arc::new(UInt32Array::from(c.i)),
            Arc::new(UInt32Array::from(c.j)),
            Arc::new(Float64Array::from(c.x_lo)),
            Arc::new(Float64Array::from(c.y_lo)),
            Arc::new(Float64Array::from(c.energy_j)),
        ],
    )
    .expect("columns match the schema")
}
