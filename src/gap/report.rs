//! `tirewear gap`: the baseline, the gap's size on training and testing
//! events, where it lies (step 1), which candidate effect explains it (step
//! 2) and how far it shrinks as terms are added (step 3); written as JSON
//! and Markdown.

use super::baseline::{CensoredTail, PhysicsBaseline, impute_censored};
use super::candidates::{Candidate, Feature, LawRow, SET_UP_SHARE, library};
use super::error::GapError;
use super::linear::weighted_fit;
use super::recalibrate::{Censoring, Rows, Term};
pub use super::render::render_markdown;
use super::scoring::{Score, ScoringSettings, rank};
use super::selection::{Selection, next_term};
use super::slices::{Slice, slice_residuals};
use crate::ingest::compound::Wlf;
use crate::kpi::energy_maps::EnergyMaps;
use crate::kpi::{KpiRow, TireRun};
use crate::model::ModelError;
use crate::model::fit::{Split, split};
use crate::model::saved::SavedModel;
use crate::{Axle, Wheel};
use std::collections::BTreeMap;

/// The simulation side of the gap.
pub enum Baseline {
    /// The frictional-energy wear law, calibrated on the training events.
    Physics,
    /// A model saved by `tirewear fit`.
    Model(Box<SavedModel>),
    /// Predicted wear per run and wheel from any simulation or model (the
    /// team's own tool): `--baseline predictions.csv`.
    Predictions(Predictions),
}

/// Predicted mean wear (%) by (run, wheel), read from a CSV file with
/// columns `run`, `wheel`, `predicted_wear_pct` (others are ignored, so
/// `tirewear predict`'s output is one).
#[derive(Debug, Clone, Default)]
pub struct Predictions {
    pub source: String,
    pub wear_pct: BTreeMap<TireRun, f64>,
}

impl Predictions {
    /// Reads and checks a predictions CSV: each row's wheel is FL/FR/RL/RR,
    /// the prediction finite (an empty cell or NaN is a row without a
    /// prediction, left out), one row per run and wheel. Errors name the
    /// file and line.
    pub fn read(path: &std::path::Path) -> Result<Predictions, crate::ingest::IngestError> {
        use crate::ingest::IngestError;
        #[derive(serde::Deserialize)]
        struct Row {
            run: String,
            wheel: String,
            predicted_wear_pct: Option<f64>,
        }
        let file = crate::ingest::open_bounded(path, 1 << 30)?;
        let mut out = Predictions {
            source: path.display().to_string(),
            ..Default::default()
        };
        for (i, row) in csv::Reader::from_reader(file)
            .deserialize::<Row>()
            .enumerate()
        {
            let line = i + 2;
            let r = row.map_err(|source| IngestError::Csv {
                path: path.to_path_buf(),
                source,
            })?;
            let bad = |what: String| IngestError::invalid(path, format!("line {line}"), what);
            let Ok(wheel) = r.wheel.parse::<crate::Wheel>() else {
                return Err(bad(format!("wheel '{}' is not FL, FR, RL or RR", r.wheel)));
            };
            let Some(p) = r.predicted_wear_pct.filter(|p| p.is_finite()) else {
                continue;
            };
            if !PLAUSIBLE_PREDICTION_PCT.contains(&p) {
                let shown = if p.abs() < 1e6 {
                    p.to_string()
                } else {
                    format!("{p:e}")
                };
                return Err(bad(format!(
                    "predicted_wear_pct = {shown} is not a wear in % of the tread depth \
                     (accepted: {}..{} %)",
                    PLAUSIBLE_PREDICTION_PCT.start(),
                    PLAUSIBLE_PREDICTION_PCT.end()
                )));
            }
            if out.wear_pct.insert((r.run.clone(), wheel), p).is_some() {
                return Err(bad(format!(
                    "a second prediction for run {} wheel {}",
                    r.run, r.wheel
                )));
            }
        }
        if out.wear_pct.is_empty() {
            return Err(IngestError::invalid(path, "rows", "no finite prediction"));
        }
        Ok(out)
    }

    /// Refuses predictions on another scale than the measured wear: over
    /// the tires of `rows` with both, a median prediction more than
    /// [`PREDICTION_SCALE_LIMIT`] times above or below the median measured
    /// wear (a fraction of the tread instead of %, or mm of tread lost);
    /// and predictions for none of them.
    pub fn check_scale(&self, rows: &[KpiRow]) -> Result<(), String> {
        let (mut predicted, mut measured): (Vec<f64>, Vec<f64>) = rows
            .iter()
            .filter_map(|r| Some((*self.wear_pct.get(&r.tire_run())?, r.wear_mean_pct)))
            .filter(|(p, m)| p.is_finite() && m.is_finite())
            .unzip();
        if predicted.is_empty() {
            return Err(format!(
                "{}: no prediction for a tire of the KPI table with a measured wear \
                 (are the run ids and wheels the table's?)",
                self.source
            ));
        }
        let median = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let (p, m) = (median(&mut predicted), median(&mut measured));
        let ratio = p / m;
        if m > 0.0 && !(1.0 / PREDICTION_SCALE_LIMIT..=PREDICTION_SCALE_LIMIT).contains(&ratio) {
            return Err(format!(
                "{}: the median predicted wear ({p:.4} %) is {ratio:.3} times the median \
                 measured wear ({m:.4} %) of the same {} tires: predictions must be the mean \
                 wear in % of the new tread depth, as the KPI table's wear_mean_pct \
                 (a fraction, or mm of tread lost, is on another scale)",
                self.source,
                predicted.len()
            ));
        }
        Ok(())
    }
}

/// Predictions a baseline CSV may hold (% of the new tread depth): a model
/// may predict beyond worn-through or slightly below zero, never by orders
/// of magnitude.
pub const PLAUSIBLE_PREDICTION_PCT: std::ops::RangeInclusive<f64> = -100.0..=1000.0;

/// How far the median prediction may lie from the median measured wear
/// (a factor either way) before the predictions are taken for another unit.
pub const PREDICTION_SCALE_LIMIT: f64 = 10.0;

/// Candidates (the leading ones by CV gain) whose slices are listed.
const ACTS_FOR: usize = 10;

/// Size of the gap on a set of rows.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct GapSize {
    pub n: usize,
    /// Mean of measured − baseline (% of tread).
    pub bias_pct: f64,
    pub rmse_pct: f64,
}

/// One step of the forward selection (step 3).
#[derive(Debug, Clone, serde::Serialize)]
pub struct Step {
    /// The term added ("baseline" for the starting point).
    pub added: String,
    /// The kind of term added (None for the baseline).
    pub feature: Option<Feature>,
    pub threshold: f64,
    pub coefficient: f64,
    /// The term's held-out gain and adjusted p-value when it was added.
    pub cv_gain: f64,
    pub p_adjusted: f64,
    /// A condition or pair term's share of its energy component on the
    /// tires it acts on (training events) at its threshold
    /// ([`Candidate::energy_share`]); None for other terms.
    pub energy_share: Option<f64>,
    /// The tires the term acts on, in words
    /// ([`Candidate::scope_description`]); None for the baseline.
    pub scope: Option<String>,
    /// Whether the term reads as a set-up effect: a set-up group's term, or
    /// a condition or pair term on a car, a car's axle or a wheel position
    /// whose threshold leaves out at most 5 % of that energy
    /// ([`SET_UP_SHARE`]).
    pub set_up: bool,
    pub training: GapSize,
    pub testing: Option<GapSize>,
    /// The gap inside each slice of `Diagnosis::slices` (same order).
    pub slices: Vec<GapSize>,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct Diagnosis {
    pub baseline: String,
    pub physics: Option<PhysicsBaseline>,
    /// The physics law calibrated again around the terms step 3 added
    /// (`recalibrate`); None without terms or under a model baseline.
    pub physics_with_terms: Option<PhysicsBaseline>,
    pub training_events: Vec<String>,
    pub testing_events: Vec<String>,
    /// Tires whose tread was worn through (run/wheel): their measured wear
    /// is a lower bound.
    pub censored: Vec<String>,
    /// Those of the training events, which entered the calibration and the
    /// tests with their wear imputed (Buckley–James,
    /// `PhysicsBaseline::fit_censored`); the rest (the testing events') are
    /// left out of the gap's measure.
    pub imputed: Vec<String>,
    /// Their wear (%) as the baseline's calibration imputed it (same
    /// order); the terms' recalibration imputes it again.
    pub imputed_wear_pct: Vec<f64>,
    /// Tires with a measured wear but no baseline prediction (run/wheel),
    /// left out of the whole diagnosis: under the physics law, those of a
    /// track without road profiles (no skewness).
    pub unpredicted: Vec<String>,
    /// The columns none of `unpredicted` has (why the baseline has none).
    pub unpredicted_lacking: Vec<String>,
    /// What was done with the worn-through tires (`--worn-through`).
    pub worn_through: WornThrough,
    /// What the within-track permutation test exchanged (`--exchange`).
    pub exchange: crate::gap::scoring::Exchangeable,
    pub training: GapSize,
    pub testing: Option<GapSize>,
    /// False-discovery rate of the slice tests.
    pub fdr: f64,
    pub slices_tested: usize,
    /// Slices whose adjusted p-value is at most `fdr`, by share of the squared gap.
    pub slices: Vec<Slice>,
    /// Step 2: candidate effects ranked on the training events (empty without energy maps).
    pub candidates: Vec<Score>,
    /// Step 3: the gap before and after each significant term, added in turn.
    pub steps: Vec<Step>,
    /// The wear (%) step 3's terms together add to each tire diagnosed
    /// (training and testing), in the final model (empty without terms).
    pub terms_wear: Vec<TermsWear>,
    /// Step 3's terms in the final model, in the order they were added.
    pub final_terms: Vec<FinalTerm>,
    /// What the diagnosis found, in words: gap.md's Findings, one line per
    /// paragraph or numbered term (what `tirewear report` shows).
    pub findings: Vec<String>,
}

/// A term of the final model: its coefficient and a 95 % interval.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FinalTerm {
    pub name: String,
    pub coefficient: f64,
    /// 2.5 and 97.5 percentiles of the coefficient over [`BOOTSTRAP_DRAWS`]
    /// refits on the training events resampled with replacement (whole
    /// events: the tires of one event share its track and weather), with
    /// the law's temperature factor, skewness coefficient and the terms'
    /// thresholds held at their fitted values.
    pub ci95: (f64, f64),
}

/// Event-bootstrap draws of the final terms' intervals.
pub const BOOTSTRAP_DRAWS: usize = 999;

/// The final model's coefficients of the last `n_terms` columns of `cols`
/// refitted on training events drawn with replacement: the 2.5 and 97.5
/// percentiles of each.
fn bootstrap_terms(
    cols: &[Vec<f64>],
    w: &[f64],
    y: &[f64],
    events: &[&str],
    n_terms: usize,
    seed: u64,
) -> Vec<(f64, f64)> {
    use rand::{Rng, SeedableRng};
    let (names, of) = super::stats::levels(events.iter().copied());
    let members: Vec<Vec<usize>> = (0..names.len())
        .map(|e| (0..events.len()).filter(|&i| of[i] == e).collect())
        .collect();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x626f_6f74);
    let first = cols.len() - n_terms;
    let mut draws: Vec<Vec<f64>> = vec![Vec::with_capacity(BOOTSTRAP_DRAWS); n_terms];
    for _ in 0..BOOTSTRAP_DRAWS {
        let idx: Vec<usize> = (0..members.len())
            .flat_map(|_| members[rng.random_range(0..members.len())].iter().copied())
            .collect();
        let (k, _) = weighted_fit(cols, w, y, &idx);
        for (t, d) in draws.iter_mut().enumerate() {
            d.push(k[first + t]);
        }
    }
    draws
        .into_iter()
        .map(|mut d| {
            d.sort_by(f64::total_cmp);
            let at = |q: f64| d[((q * (d.len() - 1) as f64).round() as usize).min(d.len() - 1)];
            (at(0.025), at(0.975))
        })
        .collect()
}

/// What step 3's terms add to one tire's predicted wear.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TermsWear {
    pub run: String,
    pub wheel: Wheel,
    pub axle: Axle,
    /// All terms together (%).
    pub wear_pct: f64,
    /// Each term's part (%), in the order of `Diagnosis::steps[1..]`.
    pub by_term_pct: Vec<f64>,
    /// The final model's predicted wear (%).
    pub predicted_pct: f64,
}

fn size(r: &[f64]) -> GapSize {
    let n = r.len();
    GapSize {
        n,
        bias_pct: r.iter().sum::<f64>() / n as f64,
        rmse_pct: (r.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt(),
    }
}

/// Settings of a diagnosis.
#[derive(Debug, Clone, serde::Serialize)]
pub struct GapSettings {
    /// Testing events (default: every third event, as `fit`).
    pub test_events: Option<Vec<String>>,
    /// False-discovery rate of the slice and candidate tests.
    pub fdr: f64,
    pub scoring: ScoringSettings,
    /// Most terms forward selection adds.
    pub max_terms: usize,
    /// WLF constants per compound id for the physics baseline's temperature
    /// factor (empty: the exponential approximation).
    pub wlf: BTreeMap<String, Wlf>,
    /// User hypotheses (`effects.toml`), scored beside the library.
    #[serde(skip)]
    pub user_effects: Vec<Candidate>,
    /// What becomes of the tires whose tread wore through.
    pub worn_through: WornThrough,
    /// A progress bar over each round's candidates (the command line's,
    /// on a terminal): a diagnosis of a season of thousands of tire-runs
    /// takes minutes (docs/gap.md, "Time, by season size").
    #[serde(skip)]
    pub progress: bool,
}

/// What the diagnosis does with the tires whose tread wore through: their
/// measured wear is only a lower bound (docs/gap.md, "Worn-through tires
/// imputed"). Either way the testing events' ones are left out of the
/// gap's measure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum WornThrough {
    /// Left out of the whole diagnosis.
    #[default]
    LeaveOut,
    /// The training events' ones enter the calibration, the slices and the
    /// tests with their wear imputed by Buckley–James regression on the
    /// law (`PhysicsBaseline::fit_censored`), the residuals' tail from
    /// their Kaplan–Meier estimate.
    Impute,
    /// As `Impute`, the tail from a log-normal scatter of wear about the
    /// law fitted by censored likelihood (Tobit).
    Tobit,
}

impl WornThrough {
    /// The setting as `--worn-through` names it.
    pub fn name(self) -> &'static str {
        match self {
            WornThrough::LeaveOut => "leave-out",
            WornThrough::Impute => "impute",
            WornThrough::Tobit => "tobit",
        }
    }

    /// How the imputed ones' tail is estimated; None when they are left out.
    fn tail(self) -> Option<CensoredTail> {
        match self {
            WornThrough::LeaveOut => None,
            WornThrough::Impute => Some(CensoredTail::KaplanMeier),
            WornThrough::Tobit => Some(CensoredTail::LogNormal),
        }
    }
}

impl Default for GapSettings {
    fn default() -> Self {
        GapSettings {
            test_events: None,
            fdr: 0.05,
            scoring: ScoringSettings::default(),
            max_terms: 4,
            wlf: BTreeMap::new(),
            user_effects: Vec::new(),
            worn_through: WornThrough::default(),
            progress: false,
        }
    }
}

/// The most permutations a diagnosis draws (`--permutations`), five times
/// the default: p-values to 1e-4. Each permutation holds an index and a
/// permuted residual per tire, for the runs exchanged and again for the
/// sides (55 MB per thousand at the season preset's 1 728 tires), four
/// times as many again where p-values at the floor are refined (some
/// 2.8 GB there at this bound), and the time grows with them.
pub const MAX_PERMUTATIONS: usize = 10_000;

impl GapSettings {
    /// Refuses settings no diagnosis can honour: an error rate outside
    /// (0, 1] (`--fdr 2` once reported every candidate significant, NaN
    /// none), or so few permutations that no p-value can reach it (the
    /// smallest is 1/(permutations + 1)), or more than [`MAX_PERMUTATIONS`]
    /// (`--permutations 18446744073709551615` was a capacity-overflow panic).
    pub fn check(&self) -> Result<(), ModelError> {
        if !(self.fdr > 0.0 && self.fdr <= 1.0) {
            return Err(ModelError::Setting {
                name: "fdr",
                value: self.fdr.to_string(),
                expected: "an error rate in (0, 1]",
            });
        }
        let n = self.scoring.permutations;
        if 1.0 / (n as f64 + 1.0) > self.fdr {
            return Err(ModelError::Setting {
                name: "permutations",
                value: n.to_string(),
                expected: "at least 1/fdr - 1 (19 at 0.05), or no p-value can reach the rate",
            });
        }
        if n > MAX_PERMUTATIONS {
            return Err(ModelError::Setting {
                name: "permutations",
                value: n.to_string(),
                expected: "at most 10000 (p-values to 1e-4; memory and time grow with \
                           them: docs/gap.md)",
            });
        }
        Ok(())
    }
}

/// Reads a KPI table and its energy and condition maps (missing maps leave
/// the candidates and shrinkage out) and diagnoses it: what `tirewear gap`,
/// `tirewear demo` and `process --then gap` run.
pub fn diagnose_file(
    kpis: &std::path::Path,
    baseline: &Baseline,
    settings: &GapSettings,
) -> Result<Diagnosis, GapError> {
    let rows = crate::kpi::table::read_parquet_rows(kpis)?;
    let maps = crate::kpi::energy_maps::read_tire_maps(kpis)?;
    if maps.is_empty() {
        tracing::warn!(
            "{} not found: candidate effects and shrinkage are skipped",
            crate::kpi::table::side_table_path(kpis, "energy_maps.parquet").display()
        );
    }
    Ok(diagnose(&rows, &maps, baseline, settings)?)
}

/// Writes `OUT/gap.json` and `OUT/gap.md` (every slice), which become
/// visible together; returns their paths.
pub fn write_diagnosis(
    d: &Diagnosis,
    out: &std::path::Path,
) -> Result<[std::path::PathBuf; 2], GapError> {
    let io = |path: &std::path::Path| {
        let path = path.display().to_string();
        move |source| GapError::Io { path, source }
    };
    std::fs::create_dir_all(out).map_err(io(out))?;
    let paths = [out.join("gap.json"), out.join("gap.md")];
    let json = crate::ingest::checksum::seal_json(
        &serde_json::to_string_pretty(d).expect("a diagnosis serialises"),
    );
    let md = super::render::render_markdown(d, usize::MAX);
    crate::atomic::write_set(
        &out.join(".gap.journal"),
        &[(&paths[0], json.as_bytes()), (&paths[1], md.as_bytes())],
    )
    .map_err(io(out))?;
    Ok(paths)
}

/// Runs the diagnosis on a KPI table: the gap's size and slices (step 1), the
/// candidate effects (step 2) and the forward selection (step 3).
pub fn diagnose(
    rows: &[KpiRow],
    maps: &BTreeMap<TireRun, EnergyMaps>,
    baseline: &Baseline,
    settings: &GapSettings,
) -> Result<Diagnosis, ModelError> {
    settings.check()?;
    let fdr = settings.fdr;
    let (measured, worn) = censor(rows);
    let censored: Vec<String> = worn.iter().map(tire_name).collect();
    let mut s = split(&measured, settings.test_events.as_deref())?;
    let (physics, imputed) = calibrate(baseline, &s, &worn, maps, settings);
    if !censored.is_empty() {
        tracing::warn!(
            tires = censored.len(),
            imputed = imputed.len(),
            left_out = censored.len() - imputed.len(),
            "tread worn through (readings at ≤ 5 % of the new depth), wear censored"
        );
    }
    let imputed_tires: Vec<String> = imputed.iter().map(tire_name).collect();
    let bounds: BTreeMap<TireRun, f64> = worn
        .iter()
        .filter(|r| imputed.iter().any(|i| i.tire_run() == r.tire_run()))
        .map(|r| (r.tire_run(), r.wear_mean_pct))
        .collect();
    s.train.extend(imputed.iter());
    let predict = |r: &KpiRow| predicted(baseline, physics.as_ref(), r, maps);
    let observed = Observed::new(&s, maps, &predict)?;
    let unpredicted = &observed.unpredicted;
    let unpredicted_lacking = lacking_in_all(unpredicted);
    if !unpredicted.is_empty() {
        tracing::warn!(
            tires = unpredicted.len(),
            lacking = unpredicted_lacking.join(", "),
            "no baseline prediction, left out of the diagnosis"
        );
    }
    let n_train = observed.n_train;
    let (trv, tev) = observed.residual.split_at(n_train);

    // Step 1 over all rows with a residual: the gap is judged where it lies, in and out of training.
    let (tested, count) = slice_residuals(&observed.rows, &observed.residual, fdr);
    let slices: Vec<Slice> = tested.into_iter().filter(|t| t.p_adjusted <= fdr).collect();

    // Steps 2 and 3: candidates scored on the training rows, added to the
    // baseline's design in turn; each step's fit applies to every row.
    let record = StepRecord {
        rows: &observed.rows,
        maps: &observed.maps,
        n_train,
        slices: &slices,
    };
    let base = base_columns(physics.as_ref(), &observed, &predict);
    let track_level = track_level(physics.is_some(), base.len());
    let mut sel = Selection::new(
        observed.data(&bounds, settings.worn_through.tail()),
        physics.as_ref(),
        &settings.wlf,
        base,
        law_rows(physics.as_ref(), &observed),
        track_level,
    );
    let mut steps = vec![record.step("baseline".into(), None, None, &observed.residual)];
    let candidates = if maps.is_empty() {
        Vec::new()
    } else {
        forward_selection(&mut sel, &record, &observed.residual, settings, &mut steps)
    };
    let terms_wear = terms_wear(&sel);
    let final_terms = final_terms(&sel, &steps, settings.scoring.seed);
    let refitted_law = sel.refitted_law;
    let mut d = Diagnosis {
        terms_wear,
        final_terms,
        baseline: baseline_name(baseline),
        physics,
        physics_with_terms: refitted_law,
        training_events: s.train_events.clone(),
        testing_events: s.test_events.clone(),
        censored,
        imputed: imputed_tires,
        imputed_wear_pct: imputed.iter().map(|r| r.wear_mean_pct).collect(),
        unpredicted: unpredicted.iter().map(|r| tire_name(r)).collect(),
        unpredicted_lacking,
        worn_through: settings.worn_through,
        exchange: settings.scoring.exchange,
        training: size(trv),
        testing: (!tev.is_empty()).then(|| size(tev)),
        fdr,
        slices_tested: count,
        slices,
        candidates,
        steps,
        findings: Vec::new(),
    };
    d.findings = super::render::findings_lines(&d);
    Ok(d)
}

/// A tire-run as the diagnosis names it: run/wheel.
fn tire_name(r: &KpiRow) -> String {
    format!("{}/{}", r.run, r.wheel)
}

/// The rows with a measured wear, and the worn-through ones apart.
///
/// A tire with readings at the worn-through depth (5 % of new): its
/// measured wear is a lower bound. Left out, or (`WornThrough::Impute`)
/// in the training events entered with its wear imputed (Buckley–James,
/// `PhysicsBaseline::fit_censored`); in the testing events always left
/// out of the gap's measure.
fn censor(rows: &[KpiRow]) -> (Vec<KpiRow>, Vec<KpiRow>) {
    rows.iter()
        .cloned()
        .partition(|r| r.worn_through_readings <= 0.0)
}

/// The physics law calibrated on the training events (None for a fixed
/// baseline), and the training events' worn-through tires with their wear
/// imputed where `settings` asks for it (none otherwise).
fn calibrate(
    baseline: &Baseline,
    s: &Split,
    worn: &[KpiRow],
    maps: &BTreeMap<TireRun, EnergyMaps>,
    settings: &GapSettings,
) -> (Option<PhysicsBaseline>, Vec<KpiRow>) {
    // Left out: nothing to impute, so the tail is moot.
    let (worn_train, tail): (Vec<&KpiRow>, _) = match settings.worn_through.tail() {
        Some(tail) => (
            worn.iter()
                .filter(|r| s.train_events.contains(&r.event))
                .collect(),
            tail,
        ),
        None => (Vec::new(), CensoredTail::KaplanMeier),
    };
    // The training rows with the worn-through ones last, flagged.
    let train_all: Vec<&KpiRow> = s.train.iter().chain(&worn_train).copied().collect();
    let is_worn: Vec<bool> = (0..train_all.len()).map(|i| i >= s.train.len()).collect();
    let (physics, imputed_wear) = match baseline {
        Baseline::Physics => {
            let train_maps: Vec<Option<&EnergyMaps>> =
                train_all.iter().map(|r| maps.get(&r.tire_run())).collect();
            let (p, y) = PhysicsBaseline::fit_censored(
                &train_all,
                &train_maps,
                &settings.wlf,
                &is_worn,
                tail,
            );
            (Some(p), y[s.train.len()..].to_vec())
        }
        _ => (None, Vec::new()),
    };
    // A fixed baseline's worn-through tires: imputed once from its own
    // predictions (nothing to calibrate again).
    let imputed_wear = if physics.is_some() || worn_train.is_empty() {
        imputed_wear
    } else {
        let predicted: Vec<f64> = train_all
            .iter()
            .map(|r| predicted(baseline, None, r, maps))
            .collect();
        impute_censored(&train_all, &is_worn, &predicted, tail)[s.train.len()..].to_vec()
    };
    let imputed = worn_train
        .iter()
        .zip(&imputed_wear)
        .filter(|(_, y)| y.is_finite())
        .map(|(r, y)| KpiRow {
            wear_mean_pct: *y,
            ..(*r).clone()
        })
        .collect();
    (physics, imputed)
}

/// The baseline's name in the report.
fn baseline_name(baseline: &Baseline) -> String {
    match baseline {
        Baseline::Physics => {
            "physics (wear = k_compound,axle · Σ E_bin·φ_compound(T_bin) · exp(s·Sk))".to_string()
        }
        Baseline::Model(m) => format!("{} model", m.method()),
        Baseline::Predictions(p) => format!("predictions from {}", p.source),
    }
}

/// The baseline's predicted wear (%) of `r` (NaN where it has none).
fn predicted(
    baseline: &Baseline,
    physics: Option<&PhysicsBaseline>,
    r: &KpiRow,
    maps: &BTreeMap<TireRun, EnergyMaps>,
) -> f64 {
    match (baseline, physics) {
        (Baseline::Model(m), _) => m.predict_row(r).unwrap_or(f64::NAN),
        (Baseline::Predictions(p), _) => p.wear_pct.get(&r.tire_run()).copied().unwrap_or(f64::NAN),
        (_, Some(p)) => p.predict(r, maps.get(&r.tire_run())),
        _ => f64::NAN,
    }
}

/// The KPI columns (the wear aside) that none of `rows` has; empty for
/// no rows.
fn lacking_in_all(rows: &[&KpiRow]) -> Vec<String> {
    if rows.is_empty() {
        return Vec::new();
    }
    KpiRow::NUMBER_COLUMNS
        .iter()
        .filter(|&&c| c != "wear_mean_pct")
        .filter(|c| {
            rows.iter()
                .all(|r| !r.number(c).is_some_and(f64::is_finite))
        })
        .map(|c| c.to_string())
        .collect()
}

/// Why training rows have no residual, for the error that too few do:
/// how many lack a measured wear, how many a prediction, and the columns
/// every row without a prediction lacks (a season without road profiles:
/// the law's skewness).
fn why_unusable(rows: &[&KpiRow], predict: &impl Fn(&KpiRow) -> f64) -> String {
    let no_wear = rows.iter().filter(|r| !r.wear_mean_pct.is_finite()).count();
    let unpredicted: Vec<&KpiRow> = rows
        .iter()
        .filter(|r| !predict(r).is_finite())
        .copied()
        .collect();
    let mut parts = Vec::new();
    if no_wear > 0 {
        parts.push(format!(
            "{no_wear} have no measured wear (no wear readings: docs/formats.md section 5)"
        ));
    }
    if !unpredicted.is_empty() {
        let lacking = lacking_in_all(&unpredicted);
        let lacking: Vec<&str> = lacking.iter().map(String::as_str).collect();
        let road = crate::kpi::table::road_hint(&lacking);
        let lacking = if lacking.is_empty() {
            String::new()
        } else if road.is_empty() {
            format!("; none of them has {}", lacking.join(", "))
        } else {
            // The law's road factor needs the skewness; a model fitted
            // without the road columns does not.
            format!(
                "; none of them has {}{road}: without road profiles, give a model fitted on \
                 the other columns as the baseline (`tirewear fit KPIS --method ffnn`, then \
                 `--baseline models/ffnn.json`: docs/gap.md)",
                lacking.join(", ")
            )
        };
        parts.push(format!(
            "{} have no baseline prediction{lacking}",
            unpredicted.len()
        ));
    }
    if parts.is_empty() {
        return String::new();
    }
    format!(
        " (of the {} training rows, {})",
        rows.len(),
        parts.join("; ")
    )
}

/// The rows the diagnosis measures the gap on: the training rows with a
/// residual first, then the testing ones.
struct Observed<'a> {
    rows: Vec<&'a KpiRow>,
    maps: Vec<Option<&'a EnergyMaps>>,
    /// Measured mean wear (%).
    y: Vec<f64>,
    /// Measured − the baseline's prediction (%).
    residual: Vec<f64>,
    n_train: usize,
    /// Rows (training, then testing) with a measured wear but no
    /// prediction: left out, and named in the diagnosis.
    unpredicted: Vec<&'a KpiRow>,
}

/// Training tires the diagnosis needs (with a measured wear and a
/// baseline prediction): fewer leave the permutation tests and the
/// track-level cross-validation nothing to stand on.
const MIN_TRAINING_TIRES: usize = 20;

impl<'a> Observed<'a> {
    fn new(
        s: &Split<'a>,
        maps: &'a BTreeMap<TireRun, EnergyMaps>,
        predict: &impl Fn(&KpiRow) -> f64,
    ) -> Result<Observed<'a>, ModelError> {
        // Each row predicted once: (row, residual) where it has one.
        let mut unpredicted = Vec::new();
        let mut observed = |set: &[&'a KpiRow]| -> Vec<(&'a KpiRow, f64)> {
            let mut kept = Vec::new();
            for &r in set {
                let residual = r.wear_mean_pct - predict(r);
                if residual.is_finite() {
                    kept.push((r, residual));
                } else if r.wear_mean_pct.is_finite() {
                    unpredicted.push(r);
                }
            }
            kept
        };
        let (tr, te) = (observed(&s.train), observed(&s.test));
        if tr.len() < MIN_TRAINING_TIRES {
            // Not TooFewObservations ("more than"): the bound is inclusive, and
            // the user needs to hear what counts and where it comes from.
            return Err(ModelError::Invalid(format!(
                "gap diagnosis{}: it needs at least {MIN_TRAINING_TIRES} training tires with a \
                 measured wear and a baseline prediction, and has {} (on {} training events, \
                 {} testing; docs/gap.md: a diagnosis is made on a season)",
                why_unusable(&s.train, predict),
                tr.len(),
                s.train_events.len(),
                s.test_events.len(),
            )));
        }
        let n_train = tr.len();
        let (rows, residual): (Vec<&KpiRow>, Vec<f64>) = tr.into_iter().chain(te).unzip();
        Ok(Observed {
            maps: rows.iter().map(|r| maps.get(&r.tire_run())).collect(),
            y: rows.iter().map(|r| r.wear_mean_pct).collect(),
            residual,
            n_train,
            rows,
            unpredicted,
        })
    }

    /// The rows for step 3; `bounds`: the imputed training tires' measured
    /// wear (their lower bounds), imputed again as terms enter.
    fn data(&self, bounds: &BTreeMap<TireRun, f64>, tail: Option<CensoredTail>) -> Rows<'_> {
        let censoring = tail.filter(|_| !bounds.is_empty()).map(|tail| {
            let train = &self.rows[..self.n_train];
            let bound_of = |i: usize| bounds.get(&train[i].tire_run()).copied();
            Censoring {
                worn: (0..self.n_train).map(|i| bound_of(i).is_some()).collect(),
                bound: (0..self.n_train)
                    .map(|i| bound_of(i).unwrap_or(self.y[i]))
                    .collect(),
                tail,
            }
        });
        Rows {
            rows: &self.rows,
            maps: &self.maps,
            y: self.y.clone(),
            n_train: self.n_train,
            censoring,
        }
    }
}

/// The baseline's design columns over every row: the physics law's
/// (`PhysicsBaseline::columns`), or an intercept and the fixed prediction.
fn base_columns(
    physics: Option<&PhysicsBaseline>,
    o: &Observed,
    predict: &impl Fn(&KpiRow) -> f64,
) -> Vec<Vec<f64>> {
    match physics {
        Some(p) => p.columns(&o.rows, &o.maps),
        None => vec![
            vec![1.0; o.rows.len()],
            o.rows.iter().map(|r| predict(r)).collect(),
        ],
    }
}

/// What the law says about each row: the mechanisms' terms are charged at
/// its abrasion per joule (`candidate_feature`).
fn law_rows(physics: Option<&PhysicsBaseline>, o: &Observed) -> Vec<LawRow> {
    o.rows
        .iter()
        .zip(&o.maps)
        .map(|(r, m)| match physics {
            Some(p) => p.law_row(r, *m),
            None => LawRow::raw(r),
        })
        .collect()
}

/// Which of `n` base columns are constant within tracks: the physics law's
/// last (its skewness derivative); road terms join them once selected.
fn track_level(physics: bool, n: usize) -> Vec<bool> {
    (0..n).map(|j| physics && j + 1 == n).collect()
}

/// What a step of the forward selection records about the rows.
struct StepRecord<'a> {
    rows: &'a [&'a KpiRow],
    maps: &'a [Option<&'a EnergyMaps>],
    n_train: usize,
    slices: &'a [Slice],
}

impl StepRecord<'_> {
    /// The step that added `added` (the baseline: no score or term) with the
    /// residuals `res` (%) over every row.
    fn step(&self, added: String, score: Option<&Score>, term: Option<&Term>, res: &[f64]) -> Step {
        let n_train = self.n_train;
        let energy_share = term.and_then(|t| {
            t.candidate
                .energy_share(&self.rows[..n_train], &self.maps[..n_train], t.threshold)
        });
        Step {
            added,
            feature: score.map(|s| s.feature),
            threshold: score.map_or(f64::NAN, |s| s.threshold),
            coefficient: score.map_or(f64::NAN, |s| s.coefficient),
            cv_gain: score.map_or(f64::NAN, |s| s.cv_gain),
            p_adjusted: score.map_or(f64::NAN, |s| s.p_adjusted),
            energy_share,
            scope: term.map(|t| t.candidate.scope_description()),
            set_up: score.is_some_and(|s| s.feature == Feature::Group)
                || (energy_share.is_some_and(|x| x >= SET_UP_SHARE)
                    && term.is_some_and(|t| t.candidate.group.is_some())),
            training: size(&res[..n_train]),
            testing: (res.len() > n_train).then(|| size(&res[n_train..])),
            slices: self
                .slices
                .iter()
                .map(|sl| {
                    let v: Vec<f64> = res
                        .iter()
                        .zip(&sl.members)
                        .filter(|(_, k)| **k)
                        .map(|(r, _)| *r)
                        .collect();
                    size(&v)
                })
                .collect(),
        }
    }
}

/// Steps 2 and 3: ranks the candidates, and adds the best significant one
/// in rounds (one per term added, plus one per term refused), each added
/// term's step pushed to `steps`. Returns the first round's ranking, with
/// where the leading candidates act among the flagged slices.
fn forward_selection(
    sel: &mut Selection,
    record: &StepRecord,
    residual: &[f64],
    settings: &GapSettings,
    steps: &mut Vec<Step>,
) -> Vec<Score> {
    let fdr = settings.fdr;
    let mut lib = library(&record.rows[..record.n_train]);
    lib.extend(settings.user_effects.iter().cloned());
    let mut candidates = Vec::new();
    let mut round = 0;
    while steps.len() <= settings.max_terms && round < 2 * settings.max_terms + 2 {
        round += 1;
        let what = format!("round {round}: scoring candidates");
        let bar = crate::progress::bar(settings.progress, lib.len() as u64, &what);
        let ranked = rank(&sel.problem(), &lib, &settings.scoring, fdr, &bar);
        bar.finish_and_clear();
        for c in ranked.iter().take(8) {
            tracing::trace!(
                round,
                candidate = %c.name,
                cv_gain = c.cv_gain,
                cv_gain_across = c.cv_gain_across,
                p = c.p,
                p_between = c.p_between,
                p_adjusted = c.p_adjusted,
                "ranked"
            );
        }
        if round == 1 {
            candidates = ranked.clone();
            let named: Vec<(&str, Vec<bool>)> = record
                .slices
                .iter()
                .map(|s| (s.name.as_str(), s.members.clone()))
                .collect();
            let leading = ACTS_FOR.min(candidates.len());
            sel.acts_in(&mut candidates[..leading], &lib, &named, residual);
        }
        let Some(best) = next_term(&ranked, &candidates, &sel.terms, &sel.used, fdr) else {
            break;
        };
        tracing::debug!(
            round,
            term = %best.name,
            cv_gain = best.cv_gain,
            cv_gain_across = best.cv_gain_across,
            p_adjusted = best.p_adjusted,
            "best significant candidate"
        );
        if let Some((refitted, res)) = sel.add(best, &lib) {
            steps.push(record.step(best.name.clone(), Some(&refitted), sel.terms.last(), &res));
        }
    }
    candidates
}

/// Each tire's wear from the final model's terms (none without terms).
fn terms_wear(sel: &Selection) -> Vec<TermsWear> {
    let n_terms = sel.terms.len();
    if n_terms == 0 {
        return Vec::new();
    }
    let (base, k) = (&sel.base, &sel.final_k);
    let first = base.len() - n_terms;
    sel.data
        .rows
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let by_term_pct: Vec<f64> = (first..base.len()).map(|j| k[j] * base[j][i]).collect();
            TermsWear {
                run: r.run.clone(),
                wheel: r.wheel,
                axle: r.axle,
                wear_pct: by_term_pct.iter().sum(),
                by_term_pct,
                predicted_pct: (0..base.len()).map(|j| k[j] * base[j][i]).sum(),
            }
        })
        .collect()
}

/// The final model's terms with their event-bootstrap 95 % intervals.
fn final_terms(sel: &Selection, steps: &[Step], seed: u64) -> Vec<FinalTerm> {
    let n_terms = sel.terms.len();
    if n_terms == 0 {
        return Vec::new();
    }
    let (base, n_train) = (&sel.base, sel.data.n_train);
    let events: Vec<&str> = sel.data.rows[..n_train]
        .iter()
        .map(|r| r.event.as_str())
        .collect();
    let ci = bootstrap_terms(base, &sel.final_w, &sel.data.y, &events, n_terms, seed);
    steps[1..]
        .iter()
        .zip(ci)
        .enumerate()
        .map(|(t, (st, ci95))| FinalTerm {
            name: st.added.clone(),
            coefficient: sel.final_k[base.len() - n_terms + t],
            ci95,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An error rate outside (0, 1] and too few permutations for a p-value
    /// to reach the rate are refused by name; the edges are accepted.
    #[test]
    fn settings_no_diagnosis_can_honour_are_refused() {
        let with = |fdr: f64, permutations: usize| GapSettings {
            fdr,
            scoring: ScoringSettings {
                permutations,
                ..Default::default()
            },
            ..Default::default()
        };
        for (fdr, n, name) in [
            (2.0, 1999, "fdr"),
            (0.0, 1999, "fdr"),
            (f64::NAN, 1999, "fdr"),
            (0.05, 0, "permutations"),
            (0.05, 18, "permutations"),
            (0.05, MAX_PERMUTATIONS + 1, "permutations"),
            (0.05, usize::MAX, "permutations"),
        ] {
            let e = with(fdr, n).check().unwrap_err().to_string();
            assert!(e.starts_with(&format!("setting {name} = ")), "{e}");
        }
        // 1/(19 + 1) = 0.05 exactly; a rate of 1 takes any permutations.
        assert!(with(0.05, 19).check().is_ok());
        assert!(with(1.0, 1).check().is_ok());
        assert!(with(0.05, MAX_PERMUTATIONS).check().is_ok());
        // The diagnosis refuses them before it reads a row.
        let e = diagnose(&[], &BTreeMap::new(), &Baseline::Physics, &with(2.0, 1999));
        assert!(matches!(e, Err(ModelError::Setting { name: "fdr", .. })));
    }

    #[test]
    fn worn_through_tires_are_imputed_in_the_training_events_only() {
        // 4 events × 6 runs × 4 wheels, wear = 1 %/MJ · E · scatter, read
        // at most 30 % (worn through there). Left out, nothing is imputed;
        // imputed by either tail, exactly the training events' worn-through
        // tires are, and the testing event's stay out.
        let mut rows = Vec::new();
        for e in 0..4 {
            for run in 0..6 {
                for (w, wheel) in Wheel::ALL.into_iter().enumerate() {
                    let energy_mj = 10.0 + 4.0 * run as f64 + w as f64;
                    let scatter =
                        1.0 + 0.25 * (((e * 24 + run * 4 + w) * 37 % 23) as f64 / 11.0 - 1.0);
                    let wear = energy_mj * scatter;
                    rows.push(KpiRow {
                        event: format!("e{e}"),
                        track: format!("t{e}"),
                        car: "car1".into(),
                        run: format!("e{e}-r{run}"),
                        wheel,
                        axle: wheel.axle(),
                        compound: "soft".into(),
                        friction_energy_j: energy_mj * 1e6,
                        t_surface_avg_c: 80.0,
                        wear_mean_pct: wear.min(30.0),
                        worn_through_readings: if wear > 30.0 { 2.0 } else { 0.0 },
                        ..Default::default()
                    });
                }
            }
        }
        let worn = |event: &str| -> Vec<String> {
            rows.iter()
                .filter(|r| r.worn_through_readings > 0.0 && r.event == event)
                .map(tire_name)
                .collect()
        };
        let training_worn: Vec<String> = ["e0", "e1", "e2"].iter().flat_map(|e| worn(e)).collect();
        assert!(!training_worn.is_empty() && !worn("e3").is_empty());
        for how in [
            WornThrough::LeaveOut,
            WornThrough::Impute,
            WornThrough::Tobit,
        ] {
            let settings = GapSettings {
                test_events: Some(vec!["e3".into()]),
                worn_through: how,
                ..GapSettings::default()
            };
            let d = diagnose(&rows, &BTreeMap::new(), &Baseline::Physics, &settings).unwrap();
            assert_eq!(d.censored.len(), training_worn.len() + worn("e3").len());
            let mut imputed = d.imputed.clone();
            imputed.sort();
            let mut want = if how == WornThrough::LeaveOut {
                Vec::new()
            } else {
                training_worn.clone()
            };
            want.sort();
            assert_eq!(imputed, want, "{how:?}");
        }
    }

    #[test]
    fn event_bootstrap_intervals_by_hand() {
        // Two events of 10 tires, y = 1·x in the first and 3·x in the
        // second, x the same in both. Drawing two events with replacement
        // gives the slope 1 (both first, p = 1/4), 2 (one of each, 1/2) or
        // 3 (both second, 1/4): the 2.5 and 97.5 percentiles are 1 and 3.
        let x: Vec<f64> = (0..20).map(|i| 1.0 + (i % 10) as f64).collect();
        let y: Vec<f64> = (0..20)
            .map(|i| if i < 10 { 1.0 } else { 3.0 } * x[i])
            .collect();
        let events: Vec<&str> = (0..20).map(|i| if i < 10 { "e1" } else { "e2" }).collect();
        let w = vec![1.0; 20];
        let ci = bootstrap_terms(std::slice::from_ref(&x), &w, &y, &events, 1, 7);
        assert!(
            (ci[0].0 - 1.0).abs() < 1e-9 && (ci[0].1 - 3.0).abs() < 1e-9,
            "{ci:?}"
        );
        // One slope everywhere: the interval is that slope.
        let y2: Vec<f64> = x.iter().map(|v| 2.0 * v).collect();
        let ci = bootstrap_terms(&[x], &w, &y2, &events, 1, 7);
        assert!(
            (ci[0].0 - 2.0).abs() < 1e-9 && (ci[0].1 - 2.0).abs() < 1e-9,
            "{ci:?}"
        );
    }
}
