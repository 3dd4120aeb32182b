//! `tirewear import`: its arguments and what it runs.

use anyhow::{Result, bail};
use std::path::PathBuf;
use tirewear::Wheel;
use tirewear::import::{CarDescription, ChannelMap, ImportSettings, NewRun, import_logs};
use tirewear::ingest::manifest::TireSets;

#[derive(clap::Args)]
pub(crate) struct ImportArgs {
    /// Log files: MoTeC `.ld` (its `.ldx` beside it is not needed), MoTeC
    /// CSV exports or generic `.csv`/`.parquet` tables with a time column.
    #[arg(required = true)]
    logs: Vec<PathBuf>,
    /// Season archive to import into (its season.toml is updated; the
    /// telemetry goes to ARCHIVE/telemetry/RUN.mcap).
    #[arg(long)]
    archive: PathBuf,
    /// Vehicle description (docs/import.md, "Vehicle description"),
    /// repeatable: a run in the manifest uses its car's (by id), a new run
    /// the only one or the one whose id is the log's vehicle.
    #[arg(long = "car", required = true)]
    cars: Vec<PathBuf>,
    /// Channel map (default: the shipped one, datasets/import/channels.toml).
    #[arg(long)]
    channels: Option<PathBuf>,
    /// Run id (one log only; default: the log's file name without extension).
    /// A run already in the manifest gets its telemetry replaced.
    #[arg(long)]
    run: Option<String>,
    /// Event of a new run (created with --track when the manifest lacks it,
    /// dated by the log).
    #[arg(long)]
    event: Option<String>,
    /// Track of a new event.
    #[arg(long)]
    track: Option<String>,
    /// Compound of a new run.
    #[arg(long)]
    compound: Option<String>,
    /// Tire sets of a new run: FL=ID,FR=ID,RL=ID,RR=ID, each wheel once
    /// with its own id. For a run already in the manifest, --event,
    /// --track, --compound and --tire-sets must agree with its entry (a
    /// differing one fails the log: the entry is changed in season.toml).
    #[arg(long, value_name = "FL=..,FR=..,RL=..,RR=..", value_parser = parse_tire_sets)]
    tire_sets: Option<TireSets>,
    /// Sample rate (Hz) to put a `.ld` log's channels on (default: the
    /// fastest mapped channel's rate).
    #[arg(long)]
    rate: Option<f64>,
    /// Scale each free-rolling wheel's radius (the non-driven axle) so
    /// that its median slip while rolling freely is zero; without it the
    /// check is only reported (docs/import.md, "Rolling radius").
    #[arg(long)]
    calibrate_radius: bool,
}

/// `FL=ID,FR=ID,RL=ID,RR=ID`, each wheel once (any case) with its own
/// non-empty id: a wheel named twice, an unknown one or an id on two wheels
/// (one tire on two wheels, docs/formats.md: ids are unique) is a typo that
/// would otherwise be entered in the manifest.
fn parse_tire_sets(s: &str) -> std::result::Result<TireSets, String> {
    let mut m: std::collections::HashMap<Wheel, String> = std::collections::HashMap::new();
    for part in s.split(',') {
        let (k, v) = part
            .split_once('=')
            .ok_or_else(|| format!("'{part}' is not WHEEL=ID"))?;
        let wheel: Wheel = k
            .trim()
            .parse()
            .map_err(|_| format!("'{}' is no wheel position (FL, FR, RL, RR)", k.trim()))?;
        let id = v.trim().to_string();
        if m.contains_key(&wheel) {
            return Err(format!("{wheel} is given twice"));
        }
        if id.is_empty() {
            return Err(format!("{wheel} has an empty id"));
        }
        if let Some((other, _)) = m.iter().find(|(_, given)| **given == id) {
            return Err(format!(
                "'{id}' is given for both {other} and {wheel}: each wheel's tire set has its own id"
            ));
        }
        m.insert(wheel, id);
    }
    let mut get = |w: Wheel| m.remove(&w).ok_or_else(|| format!("{w} is missing"));
    Ok(TireSets {
        fl: get(Wheel::FL)?,
        fr: get(Wheel::FR)?,
        rl: get(Wheel::RL)?,
        rr: get(Wheel::RR)?,
    })
}

/// Runs `tirewear import`; false when some logs failed, an error when all did.
pub(crate) fn run(a: ImportArgs) -> Result<bool> {
    if a.run.is_some() && a.logs.len() > 1 {
        bail!("--run names one run: give one log with it");
    }
    let channels = match &a.channels {
        Some(p) => ChannelMap::read(p)?,
        None => ChannelMap::default_map(),
    };
    let settings = ImportSettings {
        channels,
        cars: a
            .cars
            .iter()
            .map(|p| CarDescription::read(p))
            .collect::<Result<_, _>>()?,
        rate_hz: a.rate,
        calibrate_radius: a.calibrate_radius,
        new_run: NewRun {
            event: a.event,
            track: a.track,
            compound: a.compound,
            tire_sets: a.tire_sets,
        },
    };
    let ids: Vec<String> = match a.run {
        Some(r) => vec![r],
        None => a
            .logs
            .iter()
            .map(|p| {
                p.file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default()
            })
            .collect(),
    };
    let s = import_logs(&a.archive, &a.logs, &ids, &settings)?;
    for r in &s.imported {
        println!(
            "{} -> run {} ({}): {} samples at {} Hz, {:.0} s, {:.0} m{}; lateral slip: {}",
            r.log.display(),
            r.run,
            if r.replaced {
                "telemetry replaced"
            } else {
                "new run"
            },
            r.samples,
            r.rate_hz,
            r.duration_s,
            r.distance_m,
            if r.dropped_samples > 0 {
                format!(", {} incomplete samples dropped", r.dropped_samples)
            } else {
                String::new()
            },
            match r.lateral {
                Some(tirewear::import::estimate::LateralMethod::Kinematic) => "kinematic",
                Some(tirewear::import::estimate::LateralMethod::TyreModel) => "tyre model",
                None => "-",
            }
        );
        if !r.unmapped.is_empty() {
            println!("  not mapped: {}", r.unmapped.join(", "));
        }
        println!("  estimated: {}", r.estimated.join("; "));
        for c in &r.radius_checks {
            let flag = if c.applied_factor == 1.0 && c.median_slip.abs() > 0.002 {
                " — the radius looks wrong: check car.toml's rolling and wheel-speed radius, or give --calibrate-radius"
            } else {
                ""
            };
            println!(
                "  radius check {}: median free-rolling slip {:+.3} % over {} samples{}{flag}",
                c.wheel.name(),
                100.0 * c.median_slip,
                c.samples,
                if c.applied_factor != 1.0 {
                    format!(", radius ×{:.5}", c.applied_factor)
                } else {
                    String::new()
                },
            );
        }
    }
    for (_, e) in &s.failed {
        eprintln!("failed: {e}");
    }
    // Nothing imported is not a partial import (exit 3) but a failed one:
    // a nightly script must not go on as if the logs were in.
    if s.imported.is_empty() {
        bail!(
            "{}: {}, so the archive is as it was",
            a.archive.display(),
            match a.logs.len() {
                1 => "the log could not be imported (its error above)".to_string(),
                n => format!("none of the {n} logs could be imported (each one's error above)"),
            }
        );
    }
    println!(
        "imported {} of {} logs into {}",
        s.imported.len(),
        a.logs.len(),
        a.archive.display()
    );
    Ok(s.failed.is_empty())
}
