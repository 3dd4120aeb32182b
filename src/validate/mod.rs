//! `tirewear gap validate`: the proof of the gap diagnosis on withheld
//! effects, apart from the diagnosis itself (which never reads `truth/`).
//! Seasons are
//! simulated with one planted effect each (at several magnitudes, seeds and
//! thresholds off the defaults) and clean ones with none; each is extracted
//! and diagnosed with the default physics baseline, which does not contain
//! the effect. Only the scoring (`score`)
//! afterwards compares it with the truth:
//!
//! - hit: the first term forward selection adds is the planted mechanism,
//!   and its front-axle share is within 0.25 of the truth's;
//! - shrinkage: the testing-event RMSE reduction the diagnosis achieves,
//!   over the ideal one (baseline recalibrated on wear minus the exact planted
//!   contribution, which is then added back);
//! - false discovery: a clean season with any significant term.
//!
//! `--random N` adds seasons with a generated effect each
//! (`sim::generated`: conditions, pairs, bands, power laws and set-up
//! factors on random scopes, outside the candidate space); a hit there is
//! a diagnosis whose terms' wear correlates ≥ 0.8 with the planted wear
//! over the tires diagnosed, and beside its shrinkage stands that of the
//! planted wear itself as the term, sized with the law on the training
//! events (`score::exact_shape_sized`: what the term's shape costs, apart
//! from what estimating its size costs). Each season's testing events are
//! measured a second time against every testing tire's true wear
//! (`AgainstTruth`): the diagnosis's own measure leaves the worn-through
//! tires out, which favours a law biased low, and carries the gauge's
//! error. `render` writes the tables of docs/gap.md.

mod error;
mod render;
mod score;

pub use error::ValidateError;
pub use render::render;
use score::score_case;

use crate::gap::report::{Baseline, Diagnosis, GapSettings, diagnose};
use crate::sim::{Effect, EffectKind, GeneratedEffect};
use score::{read_generated, read_planted};
use std::path::PathBuf;

/// What to run.
#[derive(Debug, Clone)]
pub struct ValidateSettings {
    pub effects: Vec<EffectKind>,
    pub magnitudes: Vec<f64>,
    pub seeds: Vec<u64>,
    /// Seeds of the clean seasons.
    pub clean_seeds: Vec<u64>,
    /// Seeds of generated effects (`GeneratedEffect::draw`), one season
    /// each (its season seed is the same number).
    pub random: Vec<u64>,
    /// Season preset and scale of the simulated seasons.
    pub preset: crate::sim::Preset,
    pub scale: f64,
    /// Number of tracks, in place of the preset's (`SimOptions::tracks`).
    pub tracks: Option<usize>,
    /// Telemetry rate of the simulated seasons (Hz).
    pub rate_hz: f64,
    /// Wear variation no KPI measures in the simulated seasons.
    pub scatter: crate::sim::WearScatter,
    /// Scratch folder for the seasons.
    pub work: PathBuf,
    /// Keep each season's files instead of deleting them after scoring.
    pub keep: bool,
    /// Diagnose a season kept by an earlier run (`keep`) again instead of
    /// simulating it again, where its stamp (`REUSE_STAMP`) shows it was
    /// simulated with the same settings and this version of tirewear.
    pub reuse: bool,
    pub gap: GapSettings,
    /// Measure each season a second time against every testing tire's
    /// true wear (`Case::against_truth`): a second diagnosis per season.
    pub against_truth: bool,
    pub progress: bool,
}

/// One season of the matrix and how its diagnosis scored.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Case {
    /// Planted effect (`None` for a clean season or a generated effect).
    pub effect: Option<Effect>,
    /// The generated effect as the simulator resolved it (from truth/).
    pub generated: Option<GeneratedEffect>,
    pub seed: u64,
    /// Variance of the planted contribution over the variance of measured
    /// wear (truth), over the tires that are not worn through.
    pub variance_share: f64,
    /// Truth: share of the planted wear on the front axle.
    pub truth_front_share: f64,
    /// The first term forward selection added (None: nothing significant).
    pub first_term: Option<String>,
    /// Whether the first term reads as a set-up effect (the diagnosis's
    /// `Step::set_up`: a set-up group, or a condition on a car, a car's axle
    /// or a wheel position that leaves out at most 5 % of its energy).
    pub first_set_up: bool,
    /// The tires the first term acts on, in words (`Step::scope`).
    pub first_scope: Option<String>,
    pub first_mechanism: Option<String>,
    pub first_front_share: f64,
    /// Without a term: the tires most of the report's leads act on, where
    /// it names them (docs/gap.md, "Leads, when nothing is significant").
    pub leads_scope: Option<String>,
    pub significant_terms: usize,
    pub hit: bool,
    pub hit_axle: bool,
    /// Testing-event RMSE (%): baseline, after the diagnosis's terms, ideal.
    pub rmse_baseline_pct: f64,
    pub rmse_diagnosed_pct: f64,
    pub rmse_ideal_pct: f64,
    /// (baseline − diagnosed) / (baseline − ideal).
    pub shrinkage_ratio: f64,
    /// The planted shape itself, its size fitted with the law on the
    /// training events (`score::exact_shape_sized`): that size (1 = the
    /// planted one), the testing RMSE (%) and its shrinkage against the
    /// ideal. What the best term could do once its size is estimated.
    pub oracle_size: f64,
    pub rmse_oracle_pct: f64,
    pub oracle_shrinkage: f64,
    /// The same for the planted shape the telemetry predicts: each tire's
    /// planted wear over its wear scatter factor (`--wear-scatter`; NaN for
    /// a season whose truth has no factors). The ideal and the planted
    /// shape above carry the tire's own scatter of the planted part, which
    /// no term can know; this is what a term of exactly the right form and
    /// size can reach (equal to the above without scatter).
    pub expected_size: f64,
    pub rmse_expected_pct: f64,
    pub expected_shrinkage: f64,
    /// Pearson correlation, over the tires diagnosed, of the wear the
    /// diagnosis's terms add with the planted wear (0 without terms).
    pub terms_correlation: f64,
    /// The testing events measured against every testing tire's true wear
    /// (None for a truth without it, or a season that failed).
    pub against_truth: Option<AgainstTruth>,
    /// How each of the user's hypotheses (`--hypotheses`) fared in this
    /// season's diagnosis, in the file's order (empty without them).
    pub hypotheses: Vec<HypothesisOutcome>,
    pub error: Option<String>,
}

/// One user hypothesis (`gap validate --hypotheses`) in one season: its
/// first-round score among every candidate and whether forward selection
/// added it.
#[derive(Debug, Clone, serde::Serialize)]
pub struct HypothesisOutcome {
    /// As the diagnosis names it (`user: NAME`).
    pub name: String,
    /// Held-out gain and adjusted p-value in the first round.
    pub cv_gain: f64,
    pub p_adjusted: f64,
    /// Significant in the first round (adjusted p ≤ the false-discovery
    /// rate, held-out gain > 0): a candidate forward selection may add.
    pub significant: bool,
    /// The term it became (1: the first term added); None: not added.
    pub added_as: Option<usize>,
}

/// The testing events measured against the simulator's true wear of every
/// testing tire (`wear_total_pct`: without the gauge's error, not capped
/// where the tread wore through), where the diagnosis's own measure uses
/// the measured wear and leaves worn-through tires out. The baseline and
/// the diagnosed model are the diagnosis's own (its training rows and
/// choices are the same); the ideal and the expected shape as in [`Case`].
#[derive(Debug, Clone, serde::Serialize)]
pub struct AgainstTruth {
    /// Testing tires, and those of them whose tread wore through.
    pub testing_tires: usize,
    pub testing_worn_through: usize,
    /// Testing RMSE (%) against the true wear: baseline, after the
    /// diagnosis's terms, ideal, the expected shape at its size.
    pub rmse_baseline_pct: f64,
    pub rmse_diagnosed_pct: f64,
    pub rmse_ideal_pct: f64,
    pub rmse_expected_pct: f64,
    /// (baseline − diagnosed) / (baseline − ideal), and the same for the
    /// expected shape.
    pub shrinkage_ratio: f64,
    pub expected_shrinkage: f64,
    /// Whether the diagnosis on the true testing wear added the same terms
    /// (it should: the testing rows enter no fit and no choice).
    pub same_terms: bool,
    /// The training events' worn-through tires whose wear the baseline's
    /// calibration imputed (`--worn-through impute` or `tobit`; 0 when they
    /// are left out), and the imputed wear's mean error and RMSE (%)
    /// against their true wear (NaN without any).
    pub imputed_tires: usize,
    pub imputed_bias_pct: f64,
    pub imputed_rmse_pct: f64,
}

/// What a season of the matrix has planted.
#[derive(Debug, Clone)]
pub enum Planted {
    Named(Effect),
    /// As drawn; the simulator resolves it on the season.
    Generated(GeneratedEffect),
    Clean,
}

impl Planted {
    fn label(&self) -> String {
        match self {
            Planted::Named(e) => e.to_string(),
            Planted::Generated(g) => format!("generated #{}", g.seed),
            Planted::Clean => "clean".into(),
        }
    }
}

/// The matrix: planted cases first, then the generated effects, then the clean seasons.
pub fn matrix(s: &ValidateSettings) -> Vec<(Planted, u64)> {
    let mut out = Vec::new();
    for &kind in &s.effects {
        for &m in &s.magnitudes {
            for (i, &seed) in s.seeds.iter().enumerate() {
                let mut e = Effect::with_defaults(kind, m);
                // Thresholds off the defaults, in turn: the candidates' grids
                // must find them, not know them.
                let shift = [0.0, -1.0, 1.0][i % 3];
                e.threshold += shift
                    * match kind {
                        EffectKind::RoadAbrasion => 0.005,
                        _ => 3.0,
                    };
                out.push((Planted::Named(e), seed));
            }
        }
    }
    out.extend(
        s.random
            .iter()
            .map(|&seed| (Planted::Generated(GeneratedEffect::draw(seed)), seed)),
    );
    out.extend(s.clean_seeds.iter().map(|&seed| (Planted::Clean, seed)));
    out
}

/// Simulates a season into `opts.out` and extracts its KPI database there
/// (`kpis.parquet`, CPU engine): the seasons `gap validate` and `tirewear
/// bench --only gap` diagnose. Returns the KPI file's path.
pub(crate) fn simulate_and_extract(
    opts: &crate::sim::SimOptions,
) -> Result<PathBuf, ValidateError> {
    crate::sim::simulate(opts)?;
    let kpis = opts.out.join("kpis.parquet");
    crate::kpi::extract(&crate::kpi::ExtractOptions::new(&opts.out, &kpis))?;
    Ok(kpis)
}

/// A kept season's record of what it was simulated with (`--reuse`).
const REUSE_STAMP: &str = "validate-season.txt";

/// What a season's files depend on: the simulator's settings and the
/// version of tirewear that wrote them (the folder and the progress bar
/// aside).
fn reuse_stamp(opts: &crate::sim::SimOptions) -> String {
    let o = crate::sim::SimOptions {
        out: PathBuf::new(),
        progress: false,
        ..opts.clone()
    };
    format!("tirewear {}\n{o:?}\n", env!("CARGO_PKG_VERSION"))
}

/// The season's KPI file: the kept one where `reuse` is asked for and its
/// stamp matches, else simulated and extracted afresh (and stamped).
fn simulated_season(opts: &crate::sim::SimOptions, reuse: bool) -> Result<PathBuf, ValidateError> {
    let stamp_path = opts.out.join(REUSE_STAMP);
    let kpis = opts.out.join("kpis.parquet");
    let stamp = reuse_stamp(opts);
    if reuse
        && kpis.is_file()
        && std::fs::read_to_string(&stamp_path).is_ok_and(|kept| kept == stamp)
    {
        tracing::info!(season = %opts.out.display(), "reusing the kept season");
        return Ok(kpis);
    }
    let _ = std::fs::remove_dir_all(&opts.out);
    let kpis = simulate_and_extract(opts)?;
    crate::atomic::write_bytes(&stamp_path, stamp.as_bytes()).map_err(|e| ValidateError::Io {
        path: stamp_path.display().to_string(),
        source: e,
    })?;
    Ok(kpis)
}

/// The simulator's options for one season of the matrix (its folder under
/// `s.work` named by what is planted and the seed).
fn season_options(
    planted_kind: &Planted,
    seed: u64,
    s: &ValidateSettings,
) -> crate::sim::SimOptions {
    let name = match planted_kind {
        Planted::Named(e) => format!(
            "{}-m{}-t{}-s{seed}",
            e.kind.name(),
            e.magnitude,
            e.threshold
        ),
        Planted::Generated(g) => format!("generated-{}-s{seed}", g.seed),
        Planted::Clean => format!("clean-s{seed}"),
    };
    crate::sim::SimOptions {
        preset: s.preset,
        scale: s.scale,
        tracks: s.tracks,
        seed,
        effects: match planted_kind {
            Planted::Named(e) => vec![e.clone()],
            _ => Vec::new(),
        },
        generated: match planted_kind {
            Planted::Generated(g) => Some(g.clone()),
            _ => None,
        },
        scatter: s.scatter,
        encoding: crate::ingest::telemetry::Encoding::Block,
        rate_hz: Some(s.rate_hz),
        out: s.work.join(name),
        sensor_noise: true,
        logger_export: None,
        progress: false,
    }
}

impl ValidateSettings {
    /// Refuses settings no season of the matrix can run with (the
    /// diagnosis's, and each season's simulator options), before anything
    /// is simulated: `--rate 0` or a magnitude of 1e308 once failed every
    /// season in turn.
    pub fn check(&self) -> Result<(), ValidateError> {
        self.gap.check()?;
        for (planted, seed) in matrix(self) {
            season_options(&planted, seed, self).check()?;
        }
        Ok(())
    }
}

/// Simulates, extracts, diagnoses and scores one season.
pub fn run_case(
    planted_kind: &Planted,
    seed: u64,
    s: &ValidateSettings,
) -> Result<(Case, Diagnosis), ValidateError> {
    let opts = season_options(planted_kind, seed, s);
    let dir = &opts.out;
    let kpis = simulated_season(&opts, s.reuse)?;
    let rows = crate::kpi::table::read_parquet(&kpis)?;
    let maps = crate::kpi::energy_maps::read_tire_maps(&kpis)?;
    // The diagnosis sees the KPI tables and the compound files only.
    let gap = GapSettings {
        wlf: crate::ingest::compound::read_wlf(&dir.join("compounds"))?,
        ..s.gap.clone()
    };
    let d = diagnose(&rows, &maps, &Baseline::Physics, &gap)?;
    let truth = dir.join("truth");
    let (resolved, column) = match planted_kind {
        Planted::Named(e) => (planted_kind.clone(), Some(e.kind.name())),
        Planted::Generated(_) => (
            Planted::Generated(read_generated(&truth.join("settings.toml"))?),
            Some("generated"),
        ),
        Planted::Clean => (Planted::Clean, None),
    };
    let mut planted = read_planted(&truth.join("wear_truth.csv"), column)?;
    if !s.against_truth {
        // Without the true wear, score_case leaves the second measure out.
        planted.true_wear = None;
    }
    let case = score_case(&resolved, seed, &rows, &maps, &planted, &d, &gap)?;
    if !s.keep {
        std::fs::remove_dir_all(dir).map_err(|e| ValidateError::Io {
            path: dir.display().to_string(),
            source: e,
        })?;
    }
    Ok((case, d))
}

/// Writes `validate.json` (the cases) and `validate.md` (`md`, the table
/// with its heading) to `out`; they become visible together
/// (`atomic::OutputSet`). Returns their paths.
pub fn write_outputs(
    out: &std::path::Path,
    cases: &[Case],
    md: &str,
) -> std::io::Result<[PathBuf; 2]> {
    std::fs::create_dir_all(out)?;
    let paths = [out.join("validate.json"), out.join("validate.md")];
    let json = serde_json::to_string_pretty(cases).map_err(std::io::Error::other)?;
    crate::atomic::write_set(
        &out.join(".validate.journal"),
        &[(&paths[0], json.as_bytes()), (&paths[1], md.as_bytes())],
    )?;
    Ok(paths)
}

/// Runs the whole matrix; a season that fails is recorded with its error and the rest go on.
pub fn validate(s: &ValidateSettings) -> Vec<Case> {
    let cases = matrix(s);
    let pb = crate::progress::bar(s.progress, cases.len() as u64, "validating seasons");
    let mut out = Vec::new();
    for (planted, seed) in &cases {
        pb.set_message(planted.label());
        // A panic fails this season alone: the matrix goes on.
        let outcome = crate::guard::catch_panic(|| run_case(planted, *seed, s))
            .unwrap_or_else(|msg| Err(ValidateError::Internal(msg)));
        let case = match outcome {
            Ok((c, _)) => c,
            Err(e) => {
                tracing::error!("season {} seed {seed}: {e}", planted.label());
                Case {
                    effect: match planted {
                        Planted::Named(e) => Some(e.clone()),
                        _ => None,
                    },
                    generated: match planted {
                        Planted::Generated(g) => Some(g.clone()),
                        _ => None,
                    },
                    terms_correlation: f64::NAN,
                    seed: *seed,
                    variance_share: f64::NAN,
                    truth_front_share: f64::NAN,
                    first_term: None,
                    first_set_up: false,
                    first_scope: None,
                    leads_scope: None,
                    first_mechanism: None,
                    first_front_share: f64::NAN,
                    significant_terms: 0,
                    hit: false,
                    hit_axle: false,
                    rmse_baseline_pct: f64::NAN,
                    rmse_diagnosed_pct: f64::NAN,
                    rmse_ideal_pct: f64::NAN,
                    shrinkage_ratio: f64::NAN,
                    oracle_size: f64::NAN,
                    rmse_oracle_pct: f64::NAN,
                    oracle_shrinkage: f64::NAN,
                    expected_size: f64::NAN,
                    rmse_expected_pct: f64::NAN,
                    expected_shrinkage: f64::NAN,
                    against_truth: None,
                    hypotheses: Vec::new(),
                    error: Some(e.to_string()),
                }
            }
        };
        tracing::info!(
            "{} seed {seed}: first term {:?}, share {:.3}, shrinkage {:.2}",
            case.generated
                .as_ref()
                .map_or_else(|| planted.label(), |g| g.to_string()),
            case.first_term,
            case.variance_share,
            case.shrinkage_ratio
        );
        out.push(case);
        pb.inc(1);
    }
    pb.finish_and_clear();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Settings no season can run with are refused before anything is
    /// simulated, naming what is wrong: a rate of 0, a magnitude of 1e308,
    /// an error rate of 2; the same settings with sane values pass.
    #[test]
    fn settings_no_season_can_run_with_are_refused_first() {
        let dir = tempfile::tempdir().unwrap();
        let ok = ValidateSettings {
            effects: vec![EffectKind::Graining],
            magnitudes: vec![1.0],
            seeds: vec![1],
            clean_seeds: vec![2],
            random: vec![3],
            preset: crate::sim::Preset::Demo,
            scale: 1.0,
            tracks: None,
            rate_hz: 5.0,
            scatter: crate::sim::WearScatter::NONE,
            work: dir.path().to_path_buf(),
            keep: false,
            reuse: false,
            gap: GapSettings::default(),
            against_truth: false,
            progress: false,
        };
        ok.check().unwrap();
        let refused = |s: ValidateSettings, what: &str| {
            let e = s.check().unwrap_err().to_string();
            assert!(e.contains(what), "{e}");
        };
        refused(
            ValidateSettings {
                rate_hz: 0.0,
                ..ok.clone()
            },
            "sample rate must be within 1..1000 Hz, got 0",
        );
        refused(
            ValidateSettings {
                magnitudes: vec![1.0, 1e308],
                ..ok.clone()
            },
            "effect graining: magnitude must be within 0..100 (abrasion per joule relative to base wear where it acts), got 1e308",
        );
        let gap = GapSettings {
            fdr: 2.0,
            ..Default::default()
        };
        refused(ValidateSettings { gap, ..ok.clone() }, "setting fdr = 2");
        // Nothing was simulated.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    fn options(out: &std::path::Path, seed: u64) -> crate::sim::SimOptions {
        crate::sim::SimOptions {
            preset: crate::sim::Preset::Tiny,
            scale: 1.0,
            tracks: None,
            seed,
            effects: Vec::new(),
            generated: None,
            scatter: crate::sim::WearScatter::NONE,
            encoding: crate::ingest::telemetry::Encoding::Block,
            rate_hz: Some(5.0),
            out: out.to_path_buf(),
            sensor_noise: true,
            logger_export: None,
            progress: false,
        }
    }

    #[test]
    fn a_kept_season_is_reused_only_with_its_own_stamp() {
        let dir = tempfile::tempdir().unwrap();
        let opts = options(dir.path(), 7);
        // The stamp names the settings, not the folder or the progress bar.
        let elsewhere = crate::sim::SimOptions {
            out: PathBuf::from("/elsewhere"),
            progress: true,
            ..opts.clone()
        };
        assert_eq!(reuse_stamp(&opts), reuse_stamp(&elsewhere));
        assert_ne!(reuse_stamp(&opts), reuse_stamp(&options(dir.path(), 8)));
        // A kept KPI file with its stamp is taken as it is (a simulation
        // would have replaced the folder and this file with it).
        std::fs::write(dir.path().join("kpis.parquet"), b"kept").unwrap();
        std::fs::write(dir.path().join(REUSE_STAMP), reuse_stamp(&opts)).unwrap();
        let kpis = simulated_season(&opts, true).unwrap();
        assert_eq!(std::fs::read(kpis).unwrap(), b"kept");
        // Another seed's stamp, or no --reuse: simulated afresh.
        let fresh = simulated_season(&options(dir.path(), 8), true).unwrap();
        assert_ne!(std::fs::read(&fresh).unwrap(), b"kept");
        assert_eq!(
            std::fs::read_to_string(dir.path().join(REUSE_STAMP)).unwrap(),
            reuse_stamp(&options(dir.path(), 8))
        );
    }
}
