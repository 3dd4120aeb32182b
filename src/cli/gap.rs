//! `tirewear gap` and `tirewear gap validate`: their arguments and what they run.

use super::simulate::PresetArg;
use anyhow::{Context, Result};
use clap::Subcommand;
use std::path::PathBuf;
use tirewear::gap::scoring::{Exchangeable, MultipleTesting};
use tirewear::model::saved::SavedModel;

#[derive(clap::Args)]
pub(crate) struct GapArgs {
    #[command(subcommand)]
    action: Option<GapAction>,
    /// KPI database (Parquet, as written by `tirewear extract`); its
    /// energy maps are read from NAME.energy_maps.parquet beside it.
    #[arg(required = true)]
    kpis: Option<PathBuf>,
    /// `physics`, a model file written by `tirewear fit`, or a CSV of
    /// predicted wear from any simulation (columns `run`, `wheel`,
    /// `predicted_wear_pct`: the mean wear in % of the new tread depth, as
    /// the KPI table's `wear_mean_pct`; `tirewear predict` writes one): the
    /// "sim" side of the gap can be the team's own tool. Predictions outside
    /// −100..1000 %, or whose median is more than 10 times off the measured
    /// wear's (a fraction, mm), are refused.
    #[arg(long, default_value = "physics")]
    baseline: String,
    /// Testing events (comma-separated); default every third event.
    #[arg(long, value_delimiter = ',')]
    test_events: Option<Vec<String>>,
    /// Folder of compound files (TOML) whose WLF constants give the
    /// physics baseline its temperature factor; default `compounds/`
    /// beside the KPI file when it exists, else the exponential approximation.
    #[arg(long)]
    compounds: Option<PathBuf>,
    /// Your own hypotheses (TOML): named expressions over the energy-map
    /// bins and the KPIs, scored beside the built-in candidates (format:
    /// docs/gap.md).
    #[arg(long)]
    effects: Option<PathBuf>,
    #[command(flatten)]
    stats: GapStatsArgs,
    #[arg(long, default_value = "gap")]
    out: PathBuf,
}

/// Statistics settings shared by `gap` and `gap validate`.
#[derive(clap::Args)]
pub(crate) struct GapStatsArgs {
    /// Error rate of the tests: the false-discovery rate of the slices and
    /// the candidates (Benjamini-Hochberg), or the candidates' family-wise
    /// rate with `--multiple-testing max-t`.
    #[arg(long, default_value_t = 0.05)]
    fdr: f64,
    /// How the candidates' p-values are adjusted for their number: `bh`
    /// (Benjamini-Hochberg, the false-discovery rate) or `max-t` (the
    /// permutation max-statistic over all within-track candidates, the
    /// family-wise rate; road terms keep BH among themselves). Measured
    /// side by side in docs/gap.md.
    #[arg(long, value_enum, default_value = "bh")]
    multiple_testing: MultipleTestingArg,
    /// Permutations of each candidate's significance test: at least
    /// 1/fdr - 1, at most 10000.
    #[arg(long, default_value_t = 1999)]
    permutations: usize,
    /// Seed of the permutations (the same seed gives the same p-values).
    #[arg(long, default_value_t = 2026)]
    perm_seed: u64,
    /// What the within-track permutation test exchanges: `runs` (whole
    /// runs within their track, each tire to the same wheel of the other
    /// run) or `runs-and-sides` (the same, and each axle's left and right
    /// tires swapped half the time: an effect on one side of every car,
    /// which `runs` cannot tell from the null, becomes testable; a term
    /// on one car's tires is still tested on whole runs; the default).
    /// Measured in docs/gap.md ("The left and right tires exchanged").
    #[arg(long, value_enum, default_value = "runs-and-sides")]
    exchange: ExchangeArg,
    /// Most terms forward selection adds.
    #[arg(long, default_value_t = 4)]
    max_terms: usize,
    /// Tires whose tread wore through (their wear only a lower bound):
    /// `leave-out`, or `impute` the training events' ones by Buckley-James
    /// regression on the law (its prediction times the Kaplan-Meier mean of
    /// the relative residuals beyond their own), or `tobit`: the same with
    /// the residuals' tail log-normal, its mean and sd fitted by censored
    /// likelihood (reaches beyond the largest measured residual, where the
    /// heavily worn tires lie when most of them wore through).
    /// Measured side by side in docs/gap.md ("Worn-through tires imputed").
    #[arg(long, value_enum, default_value = "leave-out")]
    worn_through: WornThroughArg,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum ExchangeArg {
    Runs,
    RunsAndSides,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum WornThroughArg {
    LeaveOut,
    Impute,
    Tobit,
}

impl GapStatsArgs {
    /// The diagnosis settings, with the user's hypotheses read from
    /// `effects` (`--effects` of `gap`, `--hypotheses` of `gap validate`).
    fn settings(
        &self,
        test_events: Option<Vec<String>>,
        effects: Option<&std::path::Path>,
    ) -> Result<tirewear::gap::report::GapSettings> {
        let settings = tirewear::gap::report::GapSettings {
            test_events,
            fdr: self.fdr,
            scoring: tirewear::gap::scoring::ScoringSettings {
                permutations: self.permutations,
                seed: self.perm_seed,
                multiple_testing: match self.multiple_testing {
                    MultipleTestingArg::Bh => MultipleTesting::BenjaminiHochberg,
                    MultipleTestingArg::MaxT => MultipleTesting::MaxStatistic,
                },
                exchange: match self.exchange {
                    ExchangeArg::Runs => Exchangeable::Runs,
                    ExchangeArg::RunsAndSides => Exchangeable::RunsAndSides,
                },
            },
            max_terms: self.max_terms,
            wlf: Default::default(),
            user_effects: match effects {
                Some(f) => tirewear::gap::user_effects::load(f)?,
                None => Vec::new(),
            },
            worn_through: match self.worn_through {
                WornThroughArg::LeaveOut => tirewear::gap::report::WornThrough::LeaveOut,
                WornThroughArg::Impute => tirewear::gap::report::WornThrough::Impute,
                WornThroughArg::Tobit => tirewear::gap::report::WornThrough::Tobit,
            },
            // `gap` sets it; `gap validate`'s bar is over its seasons.
            progress: false,
        };
        // Before a season is read or simulated.
        settings.check()?;
        Ok(settings)
    }
}

#[derive(Subcommand)]
pub(crate) enum GapAction {
    /// Prove the diagnosis on seasons with withheld effects: simulate
    /// seasons with each planted effect (magnitudes × seeds, thresholds off
    /// the defaults) and clean ones, extract and diagnose each with the
    /// physics baseline (the diagnosis never reads truth/), then score hit
    /// rate, shrinkage against the ideal and false discoveries. Writes
    /// OUT/validate.json and OUT/validate.md. The defaults run the matrix
    /// of docs/gap.md (68 seasons, about 30 minutes on 2 cores).
    Validate {
        /// Effects to plant (comma-separated; `none` for none).
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "graining,blistering,thermal,road-abrasion"
        )]
        effects: Vec<String>,
        /// Magnitudes of each planted effect (abrasion per joule relative to base wear where it acts).
        #[arg(long, value_delimiter = ',', default_value = "0.5,1,2,4")]
        magnitudes: Vec<f64>,
        /// Seeds of the planted seasons.
        #[arg(long, value_delimiter = ',', default_value = "1,2,3")]
        seeds: Vec<u64>,
        /// Seeds of the clean seasons (`--clean-seeds` alone: none).
        #[arg(
            long,
            num_args = 0..,
            value_delimiter = ',',
            default_value = "1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16,17,18,19,20"
        )]
        clean_seeds: Vec<u64>,
        /// Seasons with a randomly generated effect each (docs/gap.md,
        /// "Generated effects"): a condition, pair, band, power law or set-up
        /// factor on a random scope with 5-40 % of the wear variance, drawn
        /// from seeds RANDOM_FROM, RANDOM_FROM+1, ... A hit is a diagnosis
        /// whose terms' wear correlates >= 0.8 with the planted wear. Beside
        /// each season's shrinkage, the planted wear itself as the term,
        /// sized with the law on the training events: the best a term of
        /// the right shape could reach. At most 100000.
        #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u64).range(0..=100_000))]
        random: u64,
        /// First seed of the generated effects (docs/gap.md keeps the seeds
        /// the development looked at apart from the held-out ones).
        #[arg(long, default_value_t = 1)]
        random_from: u64,
        /// Season preset of the simulated seasons. `season` at scale 0.5 has
        /// 12 events on 12 tracks: a track-level effect such as road abrasion
        /// needs the tracks (the demo's 6 training tracks leave its test 3
        /// degrees of freedom).
        #[arg(long, value_enum, default_value = "season")]
        preset: PresetArg,
        /// Multiplies the number of events of the `season` preset (0.5: one
        /// event per track).
        #[arg(long, default_value_t = 0.5)]
        scale: f64,
        /// Number of tracks of the simulated seasons, in place of the
        /// preset's (as `tirewear simulate --tracks`): `--tracks 24 --scale 1`
        /// gives 24 events on 24 tracks, 16 of them training tracks.
        #[arg(long)]
        tracks: Option<usize>,
        /// Telemetry rate of the simulated seasons (Hz).
        #[arg(long, default_value_t = 5.0)]
        rate: f64,
        /// Wear variation no KPI measures in the simulated seasons (as
        /// `tirewear simulate --wear-scatter`).
        #[arg(long, value_enum, default_value = "none")]
        wear_scatter: super::simulate::WearScatterArg,
        /// Scratch folder for the seasons (default: OUT/seasons).
        #[arg(long)]
        work: Option<PathBuf>,
        /// Keep each season's files.
        #[arg(long)]
        keep: bool,
        /// Diagnose the seasons a run with --keep left in the scratch
        /// folder again instead of simulating them again (each where it was
        /// simulated with the same settings by this version; the others are
        /// simulated afresh): for comparing diagnosis settings on the same
        /// seasons.
        #[arg(long, requires = "keep")]
        reuse: bool,
        /// Your own hypotheses (TOML, as `tirewear gap --effects`), scored
        /// in every season's diagnosis beside the built-in candidates: how
        /// a hypothesis fares on seasons whose truth is known.
        #[arg(long)]
        hypotheses: Option<PathBuf>,
        #[command(flatten)]
        stats: GapStatsArgs,
        #[arg(long, default_value = "gap-validate")]
        out: PathBuf,
    },
}

pub(crate) fn run_validate(
    settings: &tirewear::validate::ValidateSettings,
    out: &std::path::Path,
) -> Result<()> {
    settings.check()?;
    super::not_a_file(out, "gap validate")?;
    let started = std::time::Instant::now();
    let cases = tirewear::validate::validate(settings);
    let table = tirewear::validate::render(&cases);
    println!("{table}");
    let md = format!(
        "# Gap diagnosis on withheld effects\n\n{} seasons ({:?} preset, scale {}, {} tracks, {} Hz; wear scatter σ per event {}, run {}, tire {}, gauge bias {} mm; worn-through tires: {}) in {:.0} s.\n\n{table}",
        cases.len(),
        settings.preset,
        settings.scale,
        settings
            .tracks
            .map_or_else(|| "the preset's".to_string(), |n| n.to_string()),
        settings.rate_hz,
        settings.scatter.event_sd,
        settings.scatter.run_sd,
        settings.scatter.tire_sd,
        settings.scatter.gauge_bias_sd_mm,
        settings.gap.worn_through.name(),
        started.elapsed().as_secs_f64()
    );
    let [json, md] = tirewear::validate::write_outputs(out, &cases, &md)
        .with_context(|| format!("writing the validation to {}", out.display()))?;
    println!("wrote {} and {}", json.display(), md.display());
    if cases.iter().any(|c| c.error.is_some()) {
        anyhow::bail!("some seasons failed (listed above)");
    }
    Ok(())
}

pub(crate) fn run_gap(
    kpis: &std::path::Path,
    baseline: &str,
    settings: &tirewear::gap::report::GapSettings,
    out: &std::path::Path,
) -> Result<()> {
    use tirewear::gap::report::{Baseline, diagnose_file, render_markdown, write_diagnosis};
    super::not_a_file(out, "gap")?;
    let base = if baseline == "physics" {
        Baseline::Physics
    } else if baseline.ends_with(".csv") {
        let p = tirewear::gap::report::Predictions::read(std::path::Path::new(baseline))?;
        let rows = tirewear::kpi::table::read_parquet_rows(kpis)?;
        let missing = rows
            .iter()
            .filter(|r| !p.wear_pct.contains_key(&r.tire_run()))
            .count();
        if missing > 0 {
            tracing::warn!(
                "{baseline}: no prediction for {missing} of {} tires; they are left out",
                rows.len()
            );
        }
        p.check_scale(&rows).map_err(anyhow::Error::msg)?;
        Baseline::Predictions(p)
    } else {
        let m = SavedModel::load(std::path::Path::new(baseline))?;
        m.check_columns(&tirewear::kpi::table::read_units(kpis)?)
            .with_context(|| format!("{} against {baseline}", kpis.display()))?;
        Baseline::Model(Box::new(m))
    };
    let d = diagnose_file(kpis, &base, settings)
        .with_context(|| format!("diagnosing {}", kpis.display()))?;
    print!("{}", render_markdown(&d, 12));
    let [json, md] = write_diagnosis(&d, out)?;
    println!("\nwrote {} and {}", json.display(), md.display());
    Ok(())
}

/// Runs `tirewear gap` or `tirewear gap validate`.
pub(crate) fn run(a: GapArgs, progress: bool) -> Result<()> {
    let GapArgs {
        action,
        kpis,
        baseline,
        test_events,
        compounds,
        effects,
        stats,
        out,
    } = a;
    if let Some(GapAction::Validate {
        effects,
        magnitudes,
        seeds,
        clean_seeds,
        random,
        random_from,
        preset,
        scale,
        tracks,
        rate,
        wear_scatter,
        work,
        keep,
        reuse,
        hypotheses,
        stats,
        out,
    }) = action
    {
        let effects = effects
            .iter()
            .filter(|e| e.as_str() != "none")
            .map(|e| {
                tirewear::sim::EffectKind::ALL
                    .into_iter()
                    .find(|k| k.name() == e)
                    .ok_or_else(|| {
                        anyhow::anyhow!(
                            "unknown effect '{e}' (graining, blistering, thermal, road-abrasion)"
                        )
                    })
            })
            .collect::<Result<Vec<_>>>()?;
        let gap = stats.settings(None, hypotheses.as_deref())?;
        let settings = tirewear::validate::ValidateSettings {
            effects,
            magnitudes,
            seeds,
            clean_seeds,
            random: (random_from..random_seeds_end(random_from, random)?).collect(),
            preset: preset.into(),
            scale,
            tracks,
            rate_hz: rate,
            scatter: wear_scatter.into(),
            work: work.unwrap_or_else(|| out.join("seasons")),
            keep,
            reuse,
            gap,
            against_truth: true,
            progress,
        };
        run_validate(&settings, &out)?;
        return Ok(());
    }
    let kpis =
        kpis.ok_or_else(|| anyhow::anyhow!("a KPI database is needed: tirewear gap KPIS"))?;
    let mut settings = stats.settings(test_events, effects.as_deref())?;
    let dir = compounds.clone().unwrap_or_else(|| {
        kpis.parent()
            .unwrap_or(std::path::Path::new("."))
            .join("compounds")
    });
    if compounds.is_some() || dir.is_dir() {
        settings.wlf = tirewear::ingest::compound::read_wlf(&dir)
            .with_context(|| format!("reading compound files in {}", dir.display()))?;
    } else {
        tracing::warn!(
            "no compounds/ beside {}: the baseline's temperature factor is exponential",
            kpis.display()
        );
    }
    settings.progress = progress;
    run_gap(&kpis, &baseline, &settings, &out)
}

/// `--multiple-testing`: the library's `gap::scoring::MultipleTesting`.
#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum MultipleTestingArg {
    Bh,
    MaxT,
}

/// The end of `--random`'s seeds, RANDOM_FROM + RANDOM: an error where it
/// passes the largest seed (the sum wrapped to an empty range, or panicked
/// with overflow checks).
fn random_seeds_end(from: u64, count: u64) -> Result<u64> {
    from.checked_add(count).ok_or_else(|| {
        anyhow::anyhow!(
            "--random-from {from} with --random {count} passes the largest seed ({})",
            u64::MAX
        )
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn random_seeds_end_by_hand() {
        assert_eq!(super::random_seeds_end(1, 20).unwrap(), 21);
        assert_eq!(super::random_seeds_end(u64::MAX - 2, 2).unwrap(), u64::MAX);
        let e = super::random_seeds_end(u64::MAX, 2)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--random-from 18446744073709551615 with --random 2"),
            "{e}"
        );
    }
}
