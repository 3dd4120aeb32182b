//! Season simulator: whole seasons with known physics and planted effects,
//! written as season archives (`docs/formats.md`), with the ground truth in
//! `truth/` (`docs/simulator.md`). Deterministic for a seed.

pub mod compound;
pub mod effects;
pub mod error;
pub mod generated;
pub mod lap;
pub mod logger;
pub mod preset;
pub mod road;
pub mod run;
pub mod thermal;
pub mod tire;
pub mod track;
pub mod vehicle;
pub mod wear;

pub use effects::{Effect, EffectKind};
pub use error::SimError;
pub use generated::GeneratedEffect;
pub use preset::{Plan, Preset};
pub use wear::WearScatter;

use crate::Wheel;
use crate::ingest::manifest::{self, Manifest, ProfileRef, TireSets};
use crate::ingest::road::{Profile, write_profile_csv, write_profiles_parquet};
use crate::ingest::telemetry::{Encoding, RunInfo, TelemetryWriter};
use crate::ingest::wear::write_wear_csv;
use crate::ingest::{IngestError, write_toml};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use wear::RoadTruth;

/// What to simulate.
#[derive(Debug, Clone)]
pub struct SimOptions {
    pub preset: Preset,
    pub scale: f64,
    /// Number of tracks, in place of the preset's (`None`: the preset's);
    /// past the catalogue's twelve they are generated (`preset::tracks`).
    pub tracks: Option<usize>,
    pub seed: u64,
    pub effects: Vec<Effect>,
    /// A randomly generated effect (`GeneratedEffect::draw`), resolved on
    /// this season: thresholds from its energy quantiles, magnitude from
    /// its variance share.
    pub generated: Option<GeneratedEffect>,
    /// Wear variation no KPI measures (`WearScatter::NONE`: none).
    pub scatter: WearScatter,
    pub encoding: Encoding,
    pub rate_hz: Option<f64>,
    pub out: PathBuf,
    /// Sensor noise and logger dropouts (default on; off gives ideal sensors).
    pub sensor_noise: bool,
    /// Also write each run as a race logger would have recorded it
    /// (`OUT/logger/`, `logger::LoggerFormat`), with a `car.toml` per car.
    pub logger_export: Option<logger::LoggerFormat>,
    /// Show a progress bar.
    pub progress: bool,
}

/// What was written.
#[derive(Debug, Clone)]
pub struct SimSummary {
    pub out: PathBuf,
    pub tracks: usize,
    pub events: usize,
    pub runs: usize,
    pub observations: usize,
    /// Time steps simulated over all runs (each logs four wheels).
    pub samples: u64,
    pub bytes: u64,
    pub saturated_fraction: f64,
    /// Outputs derived from an earlier, different season in the folder
    /// (its KPI table, models, diagnosis, report): no longer this
    /// season's, left for the user to make again.
    pub stale_outputs: Vec<PathBuf>,
    /// Files of that earlier season the new one does not write (its other
    /// runs' telemetry, its tracks' profiles), removed.
    pub removed_files: usize,
}

const ROAD_MICRO_LAMBDA_MM: f64 = 0.5;

impl SimOptions {
    /// Refuses options no season can be simulated with (scale, rate,
    /// tracks, events, each planted effect), before any file is written:
    /// `simulate` calls it, and `gap validate` for every season first.
    pub fn check(&self) -> Result<(), SimError> {
        if !(self.scale > 0.0 && self.scale.is_finite()) {
            return Err(SimError::Config(format!(
                "the scale must be > 0, got {}",
                self.scale
            )));
        }
        if let Some(r) = self.rate_hz
            && !(1.0..=1000.0).contains(&r)
        {
            return Err(SimError::Config(format!(
                "the sample rate must be within 1..1000 Hz, got {r}"
            )));
        }
        if let Some(n) = self.tracks
            && !(1..=preset::MAX_TRACKS).contains(&n)
        {
            return Err(SimError::Config(format!(
                "the number of tracks must be within 1..{}, got {n}",
                preset::MAX_TRACKS
            )));
        }
        if self.preset == Preset::Season {
            let events = (24.0 * self.scale).round();
            if events > preset::MAX_EVENTS as f64 {
                return Err(SimError::Config(format!(
                    "scale {} gives {events} events; a season has at most {} (scale {}; scale 1 is 24 events, about 20 GB at 200 Hz)",
                    self.scale,
                    preset::MAX_EVENTS,
                    // The largest scale with one decimal that stays within.
                    (preset::MAX_EVENTS as f64 / 24.0 * 10.0).floor() / 10.0
                )));
            }
        }
        for e in &self.effects {
            e.check()
                .map_err(|m| SimError::Config(format!("effect {}: {m}", e.kind.name())))?;
        }
        let mut kinds: Vec<_> = self.effects.iter().map(|e| e.kind).collect();
        kinds.sort();
        kinds.dedup();
        if kinds.len() != self.effects.len() {
            return Err(SimError::Config("each effect may be given once".into()));
        }
        Ok(())
    }
}

/// Simulates a season into `opts.out`. The manifest is written last, so a
/// folder with `season.toml` is a complete archive.
pub fn simulate(opts: &SimOptions) -> Result<SimSummary, SimError> {
    opts.check()?;
    let plan = Plan::new(
        opts.preset,
        opts.scale,
        opts.tracks,
        opts.seed,
        opts.rate_hz,
    );
    let out = &opts.out;
    let io = |p: &Path, e| SimError::Ingest(IngestError::io(p, e));
    let earlier = earlier_season(out)?;
    std::fs::create_dir_all(out).map_err(|e| io(out, e))?;
    if opts.logger_export.is_some() {
        write_logger_cars(out, &plan)?;
    }
    if out.join("season.toml").exists() {
        std::fs::remove_file(out.join("season.toml")).map_err(|e| io(out, e))?;
    }
    tracing::info!(
        runs = plan.runs.len(),
        rate_hz = plan.rate_hz,
        "simulating season '{}'",
        plan.name
    );
    let compounds = write_compounds(out, &plan)?;
    let (tracks, roads) = write_roads(out, &plan, opts.seed)?;
    let truths = simulate_runs(opts, &plan)?;
    let saturated_fraction = write_wear(opts, &plan, &roads, &truths)?;
    let manifest = season_manifest(opts, &plan, compounds, tracks);
    manifest.validate(&out.join("season.toml"))?;
    manifest.write(&out.join("season.toml"))?;
    let (removed_files, stale_outputs) = match earlier {
        Some(old) if old != manifest => (
            remove_earlier_files(out, old, &manifest),
            derived_outputs(out),
        ),
        _ => (0, Vec::new()),
    };
    Ok(SimSummary {
        out: out.clone(),
        tracks: plan.tracks.len(),
        events: plan.events.len(),
        runs: plan.runs.len(),
        observations: plan.runs.len() * 4,
        samples: truths.iter().map(|t| t.samples).sum(),
        bytes: dir_size(out),
        saturated_fraction,
        stale_outputs,
        removed_files,
    })
}

/// Each car's description for `tirewear import`, beside the logger export.
fn write_logger_cars(out: &Path, plan: &Plan) -> Result<(), SimError> {
    let dir = out.join("logger");
    std::fs::create_dir_all(&dir).map_err(|e| SimError::Ingest(IngestError::io(&dir, e)))?;
    for car in &plan.cars {
        write_toml(
            &dir.join(format!("{}.car.toml", car.id)),
            &logger::car_description(car),
        )?;
    }
    Ok(())
}

/// The compounds' master-curve files, and the manifest's references.
fn write_compounds(out: &Path, plan: &Plan) -> Result<Vec<manifest::CompoundRef>, SimError> {
    let mut compound_refs = Vec::new();
    for c in &plan.compounds {
        let rel = format!("compounds/{}.toml", c.id);
        c.to_file().write(&out.join(&rel))?;
        compound_refs.push(manifest::CompoundRef {
            id: c.id.clone(),
            file: rel,
        });
    }
    Ok(compound_refs)
}

/// The road profiles: all but the last location of each track in the bulk
/// Parquet file, the last one as CSV. Returns the manifest's tracks and
/// each track's road truth.
fn write_roads(
    out: &Path,
    plan: &Plan,
    seed: u64,
) -> Result<(Vec<manifest::Track>, Vec<RoadTruth>), SimError> {
    let (profiles, roads) = synthesise_roads(plan, seed);
    let (bulk, single): (Vec<&Profile>, Vec<&Profile>) = profiles
        .iter()
        .partition(|p| p.location != format!("L{}", plan.locations_per_track));
    write_profiles_parquet(
        &out.join("road/profiles.parquet"),
        &bulk.into_iter().cloned().collect::<Vec<_>>(),
    )?;
    let mut tracks = Vec::new();
    for def in &plan.tracks {
        let mut refs = Vec::new();
        for p in single.iter().filter(|p| p.track == def.id) {
            let rel = format!("road/{}-{}.csv", p.track, p.location);
            write_profile_csv(&out.join(&rel), p)?;
            refs.push(ProfileRef {
                location: p.location.clone(),
                file: rel,
            });
        }
        tracks.push(manifest::Track {
            id: def.id.clone(),
            name: def.name.clone(),
            length_m: (def.shape(1.0).length_m()).round(),
            profiles: refs,
        });
    }
    Ok((tracks, roads))
}

/// Simulates every run, in parallel, writing its telemetry (and its
/// logger export); the runs' truths in plan order.
fn simulate_runs(opts: &SimOptions, plan: &Plan) -> Result<Vec<run::RunTruth>, SimError> {
    let shapes: Vec<_> = plan.tracks.iter().map(|t| t.shape(1.0)).collect();
    let progress = crate::progress::bar(opts.progress, plan.runs.len() as u64, "simulating runs");
    let results: Vec<Result<run::RunTruth, SimError>> = plan
        .runs
        .par_iter()
        .map(|rp| {
            let truth = simulate_one(opts, plan, &shapes[plan.events[rp.event].track], rp);
            progress.inc(1);
            truth
        })
        .collect();
    progress.finish_and_clear();
    results.into_iter().collect()
}

/// Simulates run `rp` on its track's `shape`: its telemetry file, and its
/// logger export when asked for.
fn simulate_one(
    opts: &SimOptions,
    plan: &Plan,
    shape: &track::TrackShape,
    rp: &preset::RunPlan,
) -> Result<run::RunTruth, SimError> {
    let ev = &plan.events[rp.event];
    let car = &plan.cars[rp.car];
    let compound = &plan.compounds[rp.compound];
    let track = &plan.tracks[ev.track];
    let mu = compound
        .grip
        .mu(compound.grip.t_opt_c, tire::FZ_NOMINAL, track.grip)
        * rp.pace;
    let lap = lap::solve(shape, car, mu);
    let ctx = run::RunContext {
        car,
        compound,
        lap: &lap,
        thermal: thermal::ThermalParams::default(),
        road_grip: track.grip,
        effects: &opts.effects,
        generated: opts.generated.as_ref(),
    };
    let settings = run::RunSettings {
        distance_m: rp.distance_m,
        rate_hz: plan.rate_hz,
        start_ns: rp.start_ns,
        air_c: ev.air_c,
        track_c: ev.track_c,
        cold_pressure_pa: rp.cold_pressure_pa,
        blanket_c: 70.0,
        sensor_noise: opts.sensor_noise,
    };
    let info = RunInfo {
        run: rp.id.clone(),
        event: ev.id.clone(),
        car: car.id.clone(),
        sample_rate_hz: plan.rate_hz,
    };
    let path = opts.out.join(telemetry_rel(&rp.id));
    let mut writer =
        TelemetryWriter::create(&path, &info, opts.encoding, plan.rate_hz.round() as usize)?;
    let mut rng = ChaCha8Rng::seed_from_u64(rp.seed);
    // The export's noise has its own stream: asking for an export leaves
    // the archive unchanged.
    let mut logger_rng = ChaCha8Rng::seed_from_u64(rp.seed ^ 0x6c6f_6767_6572);
    let mut recorder = opts
        .logger_export
        .map(|_| logger::Recorder::new(car, opts.sensor_noise));
    let truth = run::simulate_run(&ctx, &settings, &mut rng, |t, tires, veh, motion| {
        if let Some(r) = &mut recorder {
            r.push(t, tires, veh, motion, &mut logger_rng);
        }
        writer.push(t, tires, veh)
    })?;
    writer.finish()?;
    if let (Some(r), Some(format)) = (&recorder, opts.logger_export) {
        let ext = match format {
            logger::LoggerFormat::MotecCsv => "csv",
            logger::LoggerFormat::MotecLd => "ld",
        };
        let path = opts.out.join(format!("logger/{}.{ext}", rp.id));
        let info = logger::ExportInfo {
            run: rp.id.clone(),
            venue: track.name.clone(),
            vehicle: car.id.clone(),
            vehicle_desc: car.name.clone(),
            date: ev.date.clone(),
            rate_hz: plan.rate_hz,
        };
        r.write(&path, format, &info)
            .map_err(|e| IngestError::io(&path, e))?;
    }
    Ok(truth)
}

/// Each tire's wear (drawn, with any generated effect and the scatter of
/// real readings), written as spot readings and as the ground truth.
/// Returns the fraction of tire samples whose friction saturated.
fn write_wear(
    opts: &SimOptions,
    plan: &Plan,
    roads: &[RoadTruth],
    truths: &[run::RunTruth],
) -> Result<f64, SimError> {
    let mut drawn = draw_tire_wear(opts, plan, roads, truths);
    let generated = resolve_generated(opts, plan, roads, truths, &drawn);
    let mut readings = Vec::new();
    let mut truth_rows = Vec::new();
    let mut saturated = 0u64;
    let mut total_samples = 0u64;
    for ((rp, truth), tires) in plan.runs.iter().zip(truths).zip(&mut drawn) {
        let ev = &plan.events[rp.event];
        let car = &plan.cars[rp.car];
        let compound = &plan.compounds[rp.compound];
        saturated += truth.saturated_samples;
        total_samples += truth.samples * 4;
        for (w, tire) in Wheel::ALL.into_iter().zip(tires.iter_mut()) {
            let wt = &truth.wheels[w.index()];
            let tw = &mut tire.wear;
            if let Some((g, _)) = &generated {
                tw.generated_pct =
                    g.magnitude * generated_unit_pct(g, rp, w, wt, compound, &roads[ev.track], tw);
            }
            let (factor, gauge_bias_mm) = opts.scatter.draw(event_seed(opts, rp), rp.seed, w);
            tw.scale(factor);
            let set = tire_set_id(rp, w);
            readings.extend(wear::spot_readings(
                &rp.id,
                w,
                &set,
                car.tread_width(w),
                tw,
                gauge_bias_mm,
                &mut tire.readings_rng,
            ));
            truth_rows.push(TruthRow::new(
                rp,
                ev,
                &plan.tracks[ev.track].id,
                compound,
                w,
                &set,
                wt,
                tw,
            ));
        }
    }
    write_wear_csv(&opts.out.join("wear/readings.csv"), &readings)?;
    write_truth(
        &opts.out,
        plan,
        roads,
        &truth_rows,
        truths,
        opts,
        generated.as_ref(),
    )?;
    Ok(saturated as f64 / total_samples.max(1) as f64)
}

/// The season's manifest: what was simulated (in its description), the
/// compounds' and tracks' files, the events, cars and runs.
fn season_manifest(
    opts: &SimOptions,
    plan: &Plan,
    compounds: Vec<manifest::CompoundRef>,
    tracks: Vec<manifest::Track>,
) -> Manifest {
    Manifest {
        format_version: manifest::FORMAT_VERSION,
        name: plan.name.clone(),
        description: format!(
            "{SIMULATED_BY} {} (preset {:?}, seed {}, scale {}, effects [{}])",
            env!("CARGO_PKG_VERSION"),
            opts.preset,
            opts.seed,
            opts.scale,
            opts.effects
                .iter()
                .map(|e| e.to_string())
                .collect::<Vec<_>>()
                .join("; ")
        ),
        wear_readings: vec!["wear/readings.csv".into()],
        road_profiles: Some("road/profiles.parquet".into()),
        compounds,
        tracks,
        events: plan
            .events
            .iter()
            .map(|e| manifest::Event {
                id: e.id.clone(),
                track: plan.tracks[e.track].id.clone(),
                date: e.date.clone(),
                air_temp_c: e.air_c,
                track_temp_c: e.track_c,
            })
            .collect(),
        cars: plan
            .cars
            .iter()
            .map(|c| manifest::Car {
                id: c.id.clone(),
                name: c.name.clone(),
                mass_kg: c.mass_kg,
                wheelbase_m: c.wheelbase_m,
                front_track_m: c.front_track_m,
                rear_track_m: c.rear_track_m,
            })
            .collect(),
        runs: plan
            .runs
            .iter()
            .map(|r| manifest::Run {
                id: r.id.clone(),
                event: plan.events[r.event].id.clone(),
                car: plan.cars[r.car].id.clone(),
                compound: plan.compounds[r.compound].id.clone(),
                distance_m: r.distance_m,
                telemetry: telemetry_rel(&r.id),
                tire_sets: TireSets {
                    fl: tire_set_id(r, Wheel::FL),
                    fr: tire_set_id(r, Wheel::FR),
                    rl: tire_set_id(r, Wheel::RL),
                    rr: tire_set_id(r, Wheel::RR),
                },
            })
            .collect(),
    }
}

/// The manifest of a season tirewear simulated into `out` before, which
/// the new one replaces. Refused, before anything is written: a file in
/// the folder's place, and an archive tirewear did not simulate (a team's
/// own or a hand-made one, whose manifest, compounds and wear readings the
/// simulator would overwrite) or whose manifest cannot be read.
fn earlier_season(out: &Path) -> Result<Option<Manifest>, SimError> {
    if out.exists() && !out.is_dir() {
        return Err(SimError::Config(format!(
            "{}: is a file, not a folder: simulate writes a season archive into a folder",
            out.display()
        )));
    }
    let path = out.join("season.toml");
    if !path.exists() {
        return Ok(None);
    }
    let refuse = |why: String| {
        Err(SimError::Config(format!(
            "{}: {why}: simulating there would overwrite its manifest, compounds and wear \
             readings; give a new folder (or remove this one)",
            out.display()
        )))
    };
    match crate::ingest::read_toml::<Manifest>(&path) {
        Ok(m)
            if m.description.starts_with(SIMULATED_BY)
                || out.join("truth/settings.toml").is_file() =>
        {
            Ok(Some(m))
        }
        Ok(m) => refuse(format!(
            "holds a season archive tirewear did not simulate ('{}': no \"{SIMULATED_BY}\" \
             in its description, no truth/settings.toml)",
            m.name
        )),
        Err(e) => refuse(format!("holds a season.toml that cannot be read ({e})")),
    }
}

/// How every simulated season's description begins.
const SIMULATED_BY: &str = "Simulated by tirewear";

/// Removes the files the earlier simulated season listed that the new one
/// does not (paths inside the folder only); returns how many.
fn remove_earlier_files(out: &Path, old: Manifest, new: &Manifest) -> usize {
    let files = |m: Manifest| -> std::collections::BTreeSet<PathBuf> {
        let season = crate::ingest::manifest::Season {
            root: out.to_path_buf(),
            manifest_path: out.join("season.toml"),
            manifest: m,
        };
        season.input_files().into_iter().map(|(_, p)| p).collect()
    };
    let keep = files(new.clone());
    let inside = |p: &Path| {
        p.strip_prefix(out).is_ok_and(|rel| {
            rel.components()
                .all(|c| matches!(c, std::path::Component::Normal(_)))
        })
    };
    let mut removed = 0;
    for p in files(old).difference(&keep).filter(|p| inside(p)) {
        match std::fs::remove_file(p) {
            Ok(()) => removed += 1,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => tracing::warn!("{}: left from the earlier season: {e}", p.display()),
        }
    }
    removed
}

/// What `extract`, `fit`, `gap`, `report` and `process` write into an
/// archive's folder by default, where present.
fn derived_outputs(out: &Path) -> Vec<PathBuf> {
    ["kpis.parquet", "kpis.csv", "models", "gap", "report.html"]
        .iter()
        .map(|name| out.join(name))
        .filter(|p| p.exists())
        .collect()
}

fn telemetry_rel(run: &str) -> String {
    format!("telemetry/{run}.mcap")
}

fn tire_set_id(r: &preset::RunPlan, w: Wheel) -> String {
    format!("{}-{}", r.id, w.name())
}

fn dir_size(p: &Path) -> u64 {
    std::fs::read_dir(p)
        .map(|rd| {
            rd.filter_map(Result::ok)
                .map(|e| match e.metadata() {
                    Ok(m) if m.is_dir() => dir_size(&e.path()),
                    Ok(m) => m.len(),
                    Err(_) => 0,
                })
                .sum()
        })
        .unwrap_or(0)
}

/// Synthesises every measurement location of every track, and the per-track
/// road truth (means over locations) the wear law uses.
fn synthesise_roads(plan: &Plan, seed: u64) -> (Vec<Profile>, Vec<RoadTruth>) {
    let jobs: Vec<(usize, usize)> = (0..plan.tracks.len())
        .flat_map(|t| (0..plan.locations_per_track).map(move |l| (t, l)))
        .collect();
    let profiles: Vec<Profile> = jobs
        .par_iter()
        .map(|&(t, l)| {
            let def = &plan.tracks[t];
            let mut rng = ChaCha8Rng::seed_from_u64(seed ^ (def.seed << 8) ^ l as u64);
            let mut z = road::gaussian_profile(
                &def.road,
                plan.profile_samples,
                plan.profile_dx_mm,
                road::Amplitudes::Random,
                &mut rng,
            );
            road::shape_heights(&mut z, &def.road);
            Profile {
                track: def.id.clone(),
                location: format!("L{}", l + 1),
                x0_mm: 0.0,
                dx_mm: plan.profile_dx_mm,
                z_mm: z.iter().map(|v| (v * 1e5).round() / 1e5).collect(),
            }
        })
        .collect();
    let roads = plan
        .tracks
        .iter()
        .map(|def| {
            let mine: Vec<_> = profiles
                .iter()
                .filter(|p| p.track == def.id)
                .map(|p| road::moments(&p.z_mm))
                .collect();
            let n = mine.len() as f64;
            let mean = |f: fn(&(f64, f64, f64)) -> f64| mine.iter().map(f).sum::<f64>() / n;
            let micro_share = road::variance_fraction_below(
                &def.road,
                plan.profile_samples,
                plan.profile_dx_mm,
                ROAD_MICRO_LAMBDA_MM,
            );
            RoadTruth {
                rq_mm: mean(|m| m.0),
                skewness: mean(|m| m.1),
                kurtosis: mean(|m| m.2),
                micro_rms_mm: def.road.rms_mm * micro_share.sqrt(),
                hurst: def.road.hurst,
                hidden_abrasiveness: def.hidden_abrasiveness,
            }
        })
        .collect();
    (profiles, roads)
}

/// One row of `truth/wear_truth.csv`.
#[derive(Debug, serde::Serialize)]
struct TruthRow {
    run: String,
    event: String,
    track: String,
    car: String,
    compound: String,
    wheel: Wheel,
    tire_set: String,
    friction_energy_j: f64,
    friction_energy_x_j: f64,
    friction_energy_y_j: f64,
    weighted_energy_j: f64,
    mean_surface_c: f64,
    mean_inner_c: f64,
    wear_base_pct: f64,
    wear_irregular_pct: f64,
    wear_graining_pct: f64,
    wear_blistering_pct: f64,
    wear_thermal_pct: f64,
    wear_road_abrasion_pct: f64,
    wear_generated_pct: f64,
    wear_total_pct: f64,
    /// The tire's wear scatter factor (`WearScatter::draw`), already in
    /// every wear column above: 1 without `--wear-scatter`.
    wear_scatter_factor: f64,
}

impl TruthRow {
    #[allow(clippy::too_many_arguments)]
    fn new(
        rp: &preset::RunPlan,
        ev: &preset::EventPlan,
        track: &str,
        compound: &compound::CompoundModel,
        w: Wheel,
        set: &str,
        wt: &run::WheelTruth,
        tw: &wear::TireWear,
    ) -> Self {
        TruthRow {
            run: rp.id.clone(),
            event: ev.id.clone(),
            track: track.into(),
            car: format!("car{}", rp.car + 1),
            compound: compound.id.clone(),
            wheel: w,
            tire_set: set.into(),
            friction_energy_j: wt.friction_energy_x_j + wt.friction_energy_y_j,
            friction_energy_x_j: wt.friction_energy_x_j,
            friction_energy_y_j: wt.friction_energy_y_j,
            weighted_energy_j: wt.weighted_energy_j,
            mean_surface_c: wt.mean_surface_c,
            mean_inner_c: wt.mean_inner_c,
            wear_base_pct: tw.base_pct,
            wear_irregular_pct: tw.irregular_pct,
            wear_graining_pct: tw.effect_pct[0],
            wear_blistering_pct: tw.effect_pct[1],
            wear_thermal_pct: tw.effect_pct[2],
            wear_road_abrasion_pct: tw.effect_pct[3],
            wear_generated_pct: tw.generated_pct,
            wear_total_pct: tw.total_pct(),
            wear_scatter_factor: tw.scatter_factor,
        }
    }
}

#[derive(serde::Serialize)]
struct TruthSettings<'a> {
    preset: String,
    seed: u64,
    scale: f64,
    sample_rate_hz: f64,
    encoding: Encoding,
    effects: &'a [Effect],
    /// Wear variation no KPI measures.
    scatter: WearScatter,
    /// The generated effect as resolved, and in words.
    generated: Option<&'a GeneratedEffect>,
    generated_description: Option<&'a str>,
    tracks: Vec<TrackTruth<'a>>,
    compounds: &'a [compound::CompoundModel],
    thermal: thermal::ThermalParams,
}

#[derive(serde::Serialize)]
struct TrackTruth<'a> {
    id: &'a str,
    grip: f64,
    road_params: &'a track::RoadParams,
    road: RoadTruth,
}

#[derive(serde::Serialize)]
struct RunTruthRow<'a> {
    run: &'a str,
    pace: f64,
    laps: u64,
    duration_s: f64,
    samples: u64,
    dropped_samples: u64,
    saturated_samples: u64,
}

fn write_truth(
    out: &Path,
    plan: &Plan,
    roads: &[RoadTruth],
    rows: &[TruthRow],
    truths: &[run::RunTruth],
    opts: &SimOptions,
    generated: Option<&(GeneratedEffect, String)>,
) -> Result<(), SimError> {
    let settings = TruthSettings {
        scatter: opts.scatter,
        generated: generated.map(|g| &g.0),
        generated_description: generated.map(|g| g.1.as_str()),
        preset: format!("{:?}", opts.preset).to_lowercase(),
        seed: opts.seed,
        scale: opts.scale,
        sample_rate_hz: plan.rate_hz,
        encoding: opts.encoding,
        effects: &opts.effects,
        tracks: plan
            .tracks
            .iter()
            .zip(roads)
            .map(|(t, r)| TrackTruth {
                id: &t.id,
                grip: t.grip,
                road_params: &t.road,
                road: *r,
            })
            .collect(),
        compounds: &plan.compounds,
        thermal: thermal::ThermalParams::default(),
    };
    write_toml(&out.join("truth/settings.toml"), &settings)?;
    write_csv(&out.join("truth/wear_truth.csv"), rows)?;
    let run_rows: Vec<RunTruthRow> = plan
        .runs
        .iter()
        .zip(truths)
        .map(|(r, t)| RunTruthRow {
            run: &r.id,
            pace: r.pace,
            laps: t.laps,
            duration_s: t.duration_s,
            samples: t.samples,
            dropped_samples: t.dropped_samples,
            saturated_samples: t.saturated_samples,
        })
        .collect();
    write_csv(&out.join("truth/runs.csv"), &run_rows)
}

/// One tire's true wear before a generated effect and the scatter, with its
/// run's wear stream as it stands just before the tire's readings.
struct DrawnTire {
    wear: wear::TireWear,
    readings_rng: ChaCha8Rng,
}

/// Every tire's wear, drawn once. Each run has one wear stream, drawn in
/// wheel order: a tire's wear, then its readings. The readings' draws do not
/// depend on the wear (the gauge noise is drawn alike at any depth), so the
/// stream is advanced past them here and the readings drawn later, once a
/// generated effect's magnitude is known, from the saved state.
fn draw_tire_wear(
    opts: &SimOptions,
    plan: &Plan,
    roads: &[RoadTruth],
    truths: &[run::RunTruth],
) -> Vec<[DrawnTire; 4]> {
    plan.runs
        .iter()
        .zip(truths)
        .map(|(rp, truth)| {
            let ev = &plan.events[rp.event];
            let car = &plan.cars[rp.car];
            let compound = &plan.compounds[rp.compound];
            let mut rng = ChaCha8Rng::seed_from_u64(rp.seed ^ 0x5745_4152);
            Wheel::ALL.map(|w| {
                let wt = &truth.wheels[w.index()];
                let wear =
                    wear::tire_wear(compound, &roads[ev.track], w, wt, &opts.effects, &mut rng);
                let readings_rng = rng.clone();
                wear::spot_readings(&rp.id, w, "", car.tread_width(w), &wear, 0.0, &mut rng);
                DrawnTire { wear, readings_rng }
            })
        })
        .collect()
}

/// The generated effect resolved on the season: thresholds from the energy
/// quantiles of every tire's histogram, then the magnitude from its variance
/// share (against the rest of the true wear, tire by tire); with its
/// description.
fn resolve_generated(
    opts: &SimOptions,
    plan: &Plan,
    roads: &[RoadTruth],
    truths: &[run::RunTruth],
    drawn: &[[DrawnTire; 4]],
) -> Option<(GeneratedEffect, String)> {
    let mut g = opts.generated.clone()?;
    let len = g.histogram_len();
    let mut season = vec![0.0; len];
    for t in truths {
        for wt in &t.wheels {
            for (s, e) in season.iter_mut().zip(&wt.generated_histogram) {
                *s += e;
            }
        }
    }
    g.resolve(plan.cars.len(), &season);
    g.magnitude = 1.0;
    let (mut other, mut unit) = (Vec::new(), Vec::new());
    for ((rp, truth), tires) in plan.runs.iter().zip(truths).zip(drawn) {
        let ev = &plan.events[rp.event];
        let compound = &plan.compounds[rp.compound];
        for (w, tire) in Wheel::ALL.into_iter().zip(tires) {
            let wt = &truth.wheels[w.index()];
            let tw = &tire.wear;
            // The share is of the wear as it will be, scatter included.
            let (factor, _) = opts.scatter.draw(event_seed(opts, rp), rp.seed, w);
            other.push(factor * tw.total_pct());
            unit.push(factor * generated_unit_pct(&g, rp, w, wt, compound, &roads[ev.track], tw));
        }
    }
    g.magnitude = g.magnitude_for(&other, &unit);
    let text = g.to_string();
    tracing::info!("generated effect: {text}");
    Some((g, text))
}

/// The seed of a run's event's shared draws (`WearScatter`).
fn event_seed(opts: &SimOptions, rp: &preset::RunPlan) -> u64 {
    opts.seed
        .wrapping_mul(0x9e37_79b9_7f4a_7c15)
        .wrapping_add(rp.event as u64)
}

/// A generated effect's wear (%) on one tire at magnitude 1 (0 outside its scope).
fn generated_unit_pct(
    g: &GeneratedEffect,
    rp: &preset::RunPlan,
    w: Wheel,
    wt: &run::WheelTruth,
    compound: &compound::CompoundModel,
    road: &RoadTruth,
    tw: &wear::TireWear,
) -> f64 {
    if !g.scope.contains(rp.car, w) {
        return 0.0;
    }
    let energy = g.weighted_energy_j(&wt.generated_histogram);
    100.0 * wear::abrasion_mm_per_j(compound, road) * energy / tw.new_depth_mm
}

fn write_csv<T: serde::Serialize>(path: &Path, rows: &[T]) -> Result<(), SimError> {
    crate::atomic::write_csv(path, rows).map_err(|e| SimError::Ingest(IngestError::io(path, e)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A season scale beyond 1000 events (`--scale 1e9` once asked for 1.7 TB
    /// and aborted) and an effect that cannot be planted are refused before
    /// any file is written.
    #[test]
    fn huge_scales_and_bad_effects_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("s");
        let opts = |preset: Preset, scale: f64, effects: Vec<Effect>| SimOptions {
            preset,
            scale,
            tracks: None,
            seed: 1,
            effects,
            generated: None,
            scatter: WearScatter::NONE,
            encoding: Encoding::Block,
            rate_hz: Some(5.0),
            out: out.clone(),
            sensor_noise: true,
            logger_export: None,
            progress: false,
        };
        for scale in [1e9, 41.7] {
            let e = simulate(&opts(Preset::Season, scale, vec![]))
                .unwrap_err()
                .to_string();
            assert!(e.contains("at most 1000 (scale 41.6;"), "{e}");
        }
        let nan = Effect {
            threshold: f64::NAN,
            ..Effect::with_defaults(EffectKind::Graining, 1.0)
        };
        let e = simulate(&opts(Preset::Tiny, 1.0, vec![nan]))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("effect graining: threshold must be a number"),
            "{e}"
        );
        assert!(!out.exists());
    }

    /// A number of tracks outside 1..=64 is refused by name before any file
    /// is written.
    #[test]
    fn tracks_out_of_range_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        // 64 is the documented limit (docs/simulator.md).
        for n in [0, 65] {
            let out = dir.path().join(format!("s{n}"));
            let opts = SimOptions {
                preset: Preset::Tiny,
                scale: 1.0,
                tracks: Some(n),
                seed: 1,
                effects: Vec::new(),
                generated: None,
                scatter: WearScatter::NONE,
                encoding: Encoding::Block,
                rate_hz: None,
                out: out.clone(),
                sensor_noise: true,
                logger_export: None,
                progress: false,
            };
            let e = simulate(&opts).unwrap_err().to_string();
            assert!(
                e.contains("number of tracks") && e.contains(&n.to_string()),
                "{e}"
            );
            assert!(!out.exists());
        }
    }
}
