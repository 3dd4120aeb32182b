//! `tirewear simulate`: its arguments and what it runs.

use anyhow::{Context, Result};
use std::path::PathBuf;
use std::time::Instant;
use tirewear::ingest::telemetry::Encoding;
use tirewear::sim::{self, Effect, Preset, SimOptions};

#[derive(clap::Args)]
pub(crate) struct SimulateArgs {
    /// Season preset.
    #[arg(long, value_enum, default_value = "demo")]
    preset: PresetArg,
    /// Multiplies the number of events of the `season` preset (toward full-season archives); the other presets warn that it is not used.
    #[arg(long, default_value_t = 1.0)]
    scale: f64,
    /// Number of tracks, in place of the preset's (at most 64). The first
    /// twelve are the catalogue's (docs/simulator.md); the others are
    /// generated from their number alone, each parameter within the
    /// catalogue's range, so track 13 is the same in every season. Events
    /// visit each track once before any twice: `--preset season --scale 1
    /// --tracks 24` is one event on each of 24 tracks.
    #[arg(long)]
    tracks: Option<usize>,
    /// Random seed: the same seed gives the same season.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Planted effect, repeatable: NAME[=MAGNITUDE][,threshold=T][,width=W] with NAME one of
    /// graining, blistering, thermal, road-abrasion (or `none`). The magnitude is the effect's
    /// abrasion per joule relative to base wear where it acts (default 0.5). Thresholds are °C
    /// (graining: tread-bulk temperature below; blistering: inner liner above; thermal: surface
    /// above) or mm (road-abrasion: micro-texture rms above).
    #[arg(long = "effect", value_name = "SPEC")]
    effects: Vec<String>,
    /// Plant a randomly generated effect drawn from SEED (docs/gap.md,
    /// "Generated effects"): a condition, pair of conditions, band, power law
    /// or set-up factor the gap diagnosis was not written for, on a random
    /// scope, with 5-40 % of the wear's variance. truth/settings.toml
    /// describes it; truth/wear_truth.csv has its wear per tire.
    #[arg(long, value_name = "SEED")]
    random_effect: Option<u64>,
    /// Telemetry message form: per-sample messages (Foxglove-friendly) or packed blocks (fast).
    #[arg(long, value_enum, default_value = "block")]
    encoding: EncodingArg,
    /// Telemetry sample rate in Hz (default: 20 for demo, 200 for season; at most 1000).
    #[arg(long)]
    rate: Option<f64>,
    /// Wear variation that no KPI measures (docs/simulator.md): `none`, or
    /// `realistic` (day-to-day grip, the driver's style, tire-to-tire
    /// scatter, gauge bias) tuned so the physical model's testing R² on the
    /// demo comes near the paper's real data.
    #[arg(long, value_enum, default_value = "none")]
    wear_scatter: WearScatterArg,
    /// Ideal sensors: no measurement noise and no logger dropouts.
    #[arg(long)]
    no_noise: bool,
    /// Also write each run as a race logger would have recorded it, in
    /// OUT/logger/ (only channels real loggers have: speed, accelerations,
    /// yaw rate, body slip, steering, wheel speeds, IR tyre temperatures,
    /// TPMS), with OUT/logger/CAR.car.toml per car: the input of `tirewear
    /// import` with a known answer (docs/import.md).
    #[arg(long, value_enum, value_name = "FORMAT")]
    logger_export: Option<LoggerFormatArg>,
    /// Output folder (created). An earlier season tirewear simulated there is
    /// replaced; a season archive it did not simulate is refused, untouched.
    #[arg(long)]
    out: PathBuf,
}

/// `--preset`: the library's `sim::Preset` (the library knows nothing of clap).
#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum PresetArg {
    /// 2 tracks, 2 events, 1 car, 2 short runs each: for tests and quick checks.
    Tiny,
    /// 8 tracks, 10 events, 2 cars, 320 tire-runs at 20 Hz: under a minute.
    Demo,
    /// 12 tracks, 24 events × scale, 3 cars, 6 runs each at 200 Hz: ~20 GB at scale 1.
    Season,
}

impl From<PresetArg> for Preset {
    fn from(p: PresetArg) -> Preset {
        match p {
            PresetArg::Tiny => Preset::Tiny,
            PresetArg::Demo => Preset::Demo,
            PresetArg::Season => Preset::Season,
        }
    }
}

/// `--encoding` of `simulate`: the library's `Encoding`.
#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum EncodingArg {
    /// One message per sample per topic (`TireSample`, `VehicleSample`).
    Sample,
    /// Packed blocks of equally spaced samples (`TireBlock`, `VehicleBlock`).
    Block,
}

impl From<EncodingArg> for Encoding {
    fn from(e: EncodingArg) -> Encoding {
        match e {
            EncodingArg::Sample => Encoding::Sample,
            EncodingArg::Block => Encoding::Block,
        }
    }
}

pub(crate) fn parse_effects(specs: &[String]) -> Result<Vec<Effect>> {
    specs
        .iter()
        .filter(|s| s.as_str() != "none")
        .map(|s| {
            s.parse::<Effect>()
                .map_err(|e| anyhow::anyhow!("--effect {s}: {e}"))
        })
        .collect()
}

pub(crate) fn run_simulation(opts: &SimOptions) -> Result<sim::SimSummary> {
    let t0 = Instant::now();
    let s =
        sim::simulate(opts).with_context(|| format!("simulating into {}", opts.out.display()))?;
    println!(
        "wrote {}: {} tracks, {} events, {} runs, {} tire-run observations, {:.1} M telemetry samples, {:.1} MB in {:.1} s",
        s.out.display(),
        s.tracks,
        s.events,
        s.runs,
        s.observations,
        s.samples as f64 / 1e6,
        s.bytes as f64 / 1e6,
        t0.elapsed().as_secs_f64()
    );
    if s.saturated_fraction > 0.0 {
        tracing::debug!(
            "{:.3} % of wheel samples past the tire's force peak",
            100.0 * s.saturated_fraction
        );
    }
    Ok(s)
}

/// The warning for a `--scale` the preset does not use (only `season`
/// scales its events): `--preset demo --scale 4` wrote the demo silently.
fn unused_scale(preset: PresetArg, scale: f64) -> Option<String> {
    let name = match preset {
        PresetArg::Season => return None,
        PresetArg::Tiny => "tiny",
        PresetArg::Demo => "demo",
    };
    (scale != 1.0).then(|| {
        format!(
            "--scale {scale} is not used: it multiplies the events of the `season` preset only, \
             and the `{name}` preset has a fixed calendar (--tracks changes its tracks)"
        )
    })
}

/// Runs `tirewear simulate`.
pub(crate) fn run(a: SimulateArgs, progress: bool) -> Result<()> {
    if let Some(warning) = unused_scale(a.preset, a.scale) {
        tracing::warn!("{warning}");
    }
    let opts = SimOptions {
        preset: a.preset.into(),
        scale: a.scale,
        tracks: a.tracks,
        seed: a.seed,
        effects: parse_effects(&a.effects)?,
        generated: a.random_effect.map(tirewear::sim::GeneratedEffect::draw),
        scatter: a.wear_scatter.into(),
        encoding: a.encoding.into(),
        rate_hz: a.rate,
        out: a.out,
        sensor_noise: !a.no_noise,
        logger_export: a.logger_export.map(Into::into),
        progress,
    };
    let s = run_simulation(&opts)?;
    if s.removed_files > 0 {
        tracing::info!(
            "removed {} files of the earlier season in {} that this one does not write",
            s.removed_files,
            s.out.display()
        );
    }
    if !s.stale_outputs.is_empty() {
        let names: Vec<String> = s
            .stale_outputs
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        tracing::warn!(
            "{} are from the earlier season in {}, not this one: run `tirewear extract` (and \
             fit, gap, report) again before using them",
            names.join(", "),
            s.out.display()
        );
    }
    Ok(())
}

/// `--logger-export`: the library's `sim::logger::LoggerFormat`.
#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum LoggerFormatArg {
    /// MoTeC CSV export (`logger/RUN.csv`).
    MotecCsv,
    /// MoTeC i2 `.ld` (`logger/RUN.ld`; tyre temperatures and TPMS at lower rates).
    MotecLd,
}

impl From<LoggerFormatArg> for tirewear::sim::logger::LoggerFormat {
    fn from(f: LoggerFormatArg) -> Self {
        match f {
            LoggerFormatArg::MotecCsv => Self::MotecCsv,
            LoggerFormatArg::MotecLd => Self::MotecLd,
        }
    }
}

/// `--wear-scatter`: the library's `sim::WearScatter` presets.
#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum WearScatterArg {
    /// No variation beyond the physics and the reading noise.
    None,
    /// Day-to-day grip, driver style, tire-to-tire scatter, gauge bias.
    Realistic,
}

impl From<WearScatterArg> for tirewear::sim::WearScatter {
    fn from(w: WearScatterArg) -> Self {
        match w {
            WearScatterArg::None => Self::NONE,
            WearScatterArg::Realistic => Self::REALISTIC,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_scale_the_preset_does_not_use_is_warned_of() {
        assert_eq!(unused_scale(PresetArg::Season, 4.0), None);
        assert_eq!(unused_scale(PresetArg::Demo, 1.0), None);
        let w = unused_scale(PresetArg::Tiny, 1e9).unwrap();
        assert!(
            w.starts_with("--scale 1000000000 is not used") && w.contains("`tiny`"),
            "{w}"
        );
        assert!(
            unused_scale(PresetArg::Demo, 0.5)
                .unwrap()
                .contains("`demo`")
        );
    }
}
