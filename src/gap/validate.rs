//! `tirewear gap validate`: the proof on withheld effects. Seasons are
//! simulated with one planted effect each (at several magnitudes, seeds and
//! thresholds off the defaults) and clean ones with none; each is extracted
//! and diagnosed with the default physics baseline, which does not contain
//! the effect, and the diagnosis never reads `truth/`. Only the scoring
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
//! over the tires diagnosed.

use super::candidates::significant;
use super::error::GapError;
use super::report::{Baseline, Diagnosis, GapSettings, diagnose};
use crate::kpi::KpiRow;
use crate::model::metrics::median;
use crate::sim::{Effect, EffectKind, GeneratedEffect};
use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::{Path, PathBuf};

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
    /// Telemetry rate of the simulated seasons (Hz).
    pub rate_hz: f64,
    /// Wear variation no KPI measures in the simulated seasons.
    pub scatter: crate::sim::WearScatter,
    /// Scratch folder for the seasons.
    pub work: PathBuf,
    /// Keep each season's files instead of deleting them after scoring.
    pub keep: bool,
    pub gap: GapSettings,
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
    pub first_mechanism: Option<String>,
    pub first_front_share: f64,
    pub significant_terms: usize,
    pub hit: bool,
    pub hit_axle: bool,
    /// Testing-event RMSE (%): baseline, after the diagnosis's terms, ideal.
    pub rmse_baseline_pct: f64,
    pub rmse_diagnosed_pct: f64,
    pub rmse_ideal_pct: f64,
    /// (baseline − diagnosed) / (baseline − ideal).
    pub shrinkage_ratio: f64,
    /// Pearson correlation, over the tires diagnosed, of the wear the
    /// diagnosis's terms add with the planted wear (0 without terms).
    pub terms_correlation: f64,
    pub error: Option<String>,
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
pub fn simulate_and_extract(opts: &crate::sim::SimOptions) -> Result<PathBuf, GapError> {
    crate::sim::simulate(opts)?;
    let kpis = opts.out.join("kpis.parquet");
    crate::kpi::extract(&crate::kpi::ExtractOptions::new(&opts.out, &kpis))?;
    Ok(kpis)
}

/// Planted wear (%) per (run, wheel) from `truth/wear_truth.csv`: the
/// column `wear_<column>_pct` (None: zero).
pub fn read_planted(
    truth: &Path,
    column: Option<&str>,
) -> Result<BTreeMap<(String, String), f64>, GapError> {
    let file = truth.display().to_string();
    let mut rd = csv::Reader::from_path(truth).map_err(|e| GapError::Truth {
        file: file.clone(),
        line: 0,
        message: e.to_string(),
    })?;
    let headers = rd
        .headers()
        .map_err(|e| GapError::Truth {
            file: file.clone(),
            line: 1,
            message: e.to_string(),
        })?
        .clone();
    let col = |name: &str| {
        headers
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| GapError::Truth {
                file: file.clone(),
                line: 1,
                message: format!("no column '{name}'"),
            })
    };
    let (run, wheel) = (col("run")?, col("wheel")?);
    let effect = match column {
        Some(k) => Some(col(&format!("wear_{}_pct", k.replace('-', "_")))?),
        None => None,
    };
    let mut out = BTreeMap::new();
    for (i, rec) in rd.records().enumerate() {
        let rec = rec.map_err(|e| GapError::Truth {
            file: file.clone(),
            line: i + 2,
            message: e.to_string(),
        })?;
        let v = match effect {
            Some(c) => rec[c].parse::<f64>().map_err(|_| GapError::Truth {
                file: file.clone(),
                line: i + 2,
                message: format!("'{}' is not a number", &rec[c]),
            })?,
            None => 0.0,
        };
        out.insert((rec[run].to_string(), rec[wheel].to_string()), v);
    }
    Ok(out)
}

fn variance(v: &[f64]) -> f64 {
    let m = v.iter().sum::<f64>() / v.len() as f64;
    v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() as f64 - 1.0)
}

/// Scores a diagnosis of `rows` against the planted wear.
pub fn score_case(
    planted_kind: &Planted,
    seed: u64,
    rows: &[KpiRow],
    maps: &BTreeMap<(String, String), crate::kpi::energy_maps::EnergyMaps>,
    planted: &BTreeMap<(String, String), f64>,
    d: &Diagnosis,
    gap: &GapSettings,
) -> Result<Case, GapError> {
    let planted_of = |r: &KpiRow| {
        planted
            .get(&(r.run.clone(), r.wheel.to_string()))
            .copied()
            .unwrap_or(0.0)
    };
    let p: Vec<f64> = rows.iter().map(planted_of).collect();
    // The variance share over the tires the diagnosis keeps: a worn-through
    // tire's measured wear is capped while its planted wear is not.
    let (p_kept, w_kept): (Vec<f64>, Vec<f64>) = rows
        .iter()
        .zip(&p)
        .filter(|(r, _)| r.worn_through_readings <= 0.0)
        .map(|(r, v)| (*v, r.wear_mean_pct))
        .unzip();
    let total: f64 = p.iter().sum();
    let front: f64 = rows
        .iter()
        .zip(&p)
        .filter(|(r, _)| r.axle == crate::Axle::Front)
        .map(|(_, v)| v)
        .sum();
    // Ideal: the same baseline calibrated on wear minus the planted part,
    // the planted part then added back exactly.
    let cleaned: Vec<KpiRow> = rows
        .iter()
        .zip(&p)
        .map(|(r, v)| KpiRow {
            wear_mean_pct: r.wear_mean_pct - v,
            ..r.clone()
        })
        .collect();
    let ideal = diagnose(
        &cleaned,
        maps,
        &Baseline::Physics,
        &GapSettings {
            max_terms: 0,
            ..gap.clone()
        },
    )?;
    let rmse_ideal = ideal.testing.map_or(f64::NAN, |t| t.rmse_pct);
    let rmse_base = d.testing.map_or(f64::NAN, |t| t.rmse_pct);
    let last = d.steps.last().expect("the baseline step");
    let rmse_diag = last.testing.map_or(f64::NAN, |t| t.rmse_pct);
    let first = d.steps.get(1);
    let first_score = first.and_then(|st| d.candidates.iter().find(|c| c.name == st.added));
    let first_mechanism = first_score
        .and_then(|c| c.feature.mechanism())
        .map(str::to_string);
    let first_front_share = first_score.map_or(f64::NAN, |c| c.front_share);
    let truth_front_share = front / total;
    let effect = match planted_kind {
        Planted::Named(e) => Some(e),
        _ => None,
    };
    let terms_correlation = terms_correlation(d, planted);
    let hit = match planted_kind {
        Planted::Named(e) => first_mechanism.as_deref() == Some(e.kind.name()),
        Planted::Generated(_) => terms_correlation >= 0.8,
        Planted::Clean => false,
    };
    Ok(Case {
        effect: effect.cloned(),
        generated: match planted_kind {
            Planted::Generated(g) => Some(g.clone()),
            _ => None,
        },
        seed,
        terms_correlation,
        variance_share: if !matches!(planted_kind, Planted::Clean) {
            variance(&p_kept) / variance(&w_kept)
        } else {
            0.0
        },
        truth_front_share,
        first_term: first.map(|s| s.added.clone()),
        first_mechanism,
        first_front_share,
        significant_terms: d.steps.len() - 1,
        hit,
        // A generated effect's scope is judged by the correlation itself.
        hit_axle: hit
            && (effect.is_none() || (first_front_share - truth_front_share).abs() <= 0.25),
        rmse_baseline_pct: rmse_base,
        rmse_diagnosed_pct: rmse_diag,
        rmse_ideal_pct: rmse_ideal,
        shrinkage_ratio: (rmse_base - rmse_diag) / (rmse_base - rmse_ideal),
        error: None,
    })
}

/// Pearson correlation of the wear the diagnosis's terms add with the
/// planted wear, over the tires diagnosed (0 without terms or without
/// variation in either).
fn terms_correlation(d: &Diagnosis, planted: &BTreeMap<(String, String), f64>) -> f64 {
    let (terms, truth): (Vec<f64>, Vec<f64>) = d
        .terms_wear
        .iter()
        .map(|t| {
            let p = planted
                .get(&(t.run.clone(), t.wheel.to_string()))
                .copied()
                .unwrap_or(0.0);
            (t.wear_pct, p)
        })
        .unzip();
    // Too few tires or a constant side (no terms entered) is no match.
    let constant = |v: &[f64]| v.iter().all(|x| *x == v[0]);
    if terms.len() < 3 || constant(&terms) || constant(&truth) {
        return 0.0;
    }
    crate::model::data::correlation(&terms, &truth)
}

/// The generated effect as the simulator resolved it (`truth/settings.toml`).
fn read_generated(settings: &Path) -> Result<GeneratedEffect, GapError> {
    let truth = |message: String| GapError::Truth {
        file: settings.display().to_string(),
        line: 0,
        message,
    };
    let text = std::fs::read_to_string(settings).map_err(|e| truth(e.to_string()))?;
    #[derive(serde::Deserialize)]
    struct Settings {
        generated: Option<GeneratedEffect>,
    }
    let s: Settings = toml::from_str(&text).map_err(|e| truth(e.to_string()))?;
    s.generated
        .ok_or_else(|| truth("no [generated] effect".into()))
}

/// Simulates, extracts, diagnoses and scores one season.
pub fn run_case(
    planted_kind: &Planted,
    seed: u64,
    s: &ValidateSettings,
) -> Result<(Case, Diagnosis), GapError> {
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
    let dir = s.work.join(name);
    let _ = std::fs::remove_dir_all(&dir);
    let kpis = simulate_and_extract(&crate::sim::SimOptions {
        preset: s.preset,
        scale: s.scale,
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
        out: dir.clone(),
        sensor_noise: true,
        progress: false,
    })?;
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
    let planted = read_planted(&truth.join("wear_truth.csv"), column)?;
    let case = score_case(&resolved, seed, &rows, &maps, &planted, &d, &gap)?;
    if !s.keep {
        std::fs::remove_dir_all(&dir).map_err(|e| GapError::Io {
            path: dir.display().to_string(),
            source: e,
        })?;
    }
    Ok((case, d))
}

/// Runs the whole matrix; a season that fails is recorded with its error and the rest go on.
pub fn validate(s: &ValidateSettings) -> Vec<Case> {
    let cases = matrix(s);
    let pb = crate::progress::bar(s.progress, cases.len() as u64, "validating seasons");
    let mut out = Vec::new();
    for (planted, seed) in &cases {
        pb.set_message(planted.label());
        let case = match run_case(planted, *seed, s) {
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
                    first_mechanism: None,
                    first_front_share: f64::NAN,
                    significant_terms: 0,
                    hit: false,
                    hit_axle: false,
                    rmse_baseline_pct: f64::NAN,
                    rmse_diagnosed_pct: f64::NAN,
                    rmse_ideal_pct: f64::NAN,
                    shrinkage_ratio: f64::NAN,
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

/// The summary table (per effect and magnitude) and the clean seasons' false discoveries.
pub fn render(cases: &[Case]) -> String {
    let mut s = String::from(
        "| effect | magnitude | seasons | variance share (median) | hit rate | hit incl. axle | shrinkage / ideal (median) | within 20 % of ideal |\n|---|---|---|---|---|---|---|---|\n",
    );
    let mut groups: BTreeMap<(String, String), Vec<&Case>> = BTreeMap::new();
    for c in cases.iter().filter(|c| c.effect.is_some()) {
        let e = c.effect.as_ref().expect("planted");
        groups
            .entry((e.kind.name().to_string(), format!("{:.2}", e.magnitude)))
            .or_default()
            .push(c);
    }
    for ((kind, mag), g) in &groups {
        let n = g.len();
        let rate = |f: &dyn Fn(&Case) -> bool| {
            format!(
                "{}/{n} ({:.0} %)",
                g.iter().filter(|c| f(c)).count(),
                100.0 * g.iter().filter(|c| f(c)).count() as f64 / n as f64
            )
        };
        let _ = writeln!(
            s,
            "| {kind} | {mag} | {n} | {:.1} % | {} | {} | {:.2} | {} |",
            100.0 * median(g.iter().map(|c| c.variance_share).collect()),
            rate(&|c| c.hit),
            rate(&|c| c.hit_axle),
            median(g.iter().map(|c| c.shrinkage_ratio).collect()),
            rate(&|c| (c.shrinkage_ratio - 1.0).abs() <= 0.2),
        );
    }
    // The targets, over the seasons where the planted effect carries
    // at least 10 % of the wear variance (whatever the magnitude).
    let mut kinds: BTreeMap<String, Vec<&Case>> = BTreeMap::new();
    for c in cases.iter().filter(|c| c.error.is_none()) {
        if let Some(e) = &c.effect {
            kinds.entry(e.kind.name().to_string()).or_default().push(c);
        }
    }
    if !kinds.is_empty() {
        s.push_str(
            "\nTargets, over the seasons where the planted effect carries ≥ 10 % of the wear variance: hit rate ≥ 90 %, shrinkage within 20 % of the ideal.\n\n| effect | seasons ≥ 10 % | hit rate | hit incl. axle | shrinkage within 20 % |\n|---|---|---|---|---|\n",
        );
        for (kind, g) in &kinds {
            let big: Vec<&&Case> = g.iter().filter(|c| c.variance_share >= 0.1).collect();
            let n = big.len();
            let count = |f: &dyn Fn(&Case) -> bool| big.iter().filter(|c| f(c)).count();
            let pct = |k: usize| {
                if n == 0 {
                    "–".to_string()
                } else {
                    format!("{k}/{n} ({:.0} %)", 100.0 * k as f64 / n as f64)
                }
            };
            let _ = writeln!(
                s,
                "| {kind} | {n} | {} | {} | {} |",
                pct(count(&|c| c.hit)),
                pct(count(&|c| c.hit_axle)),
                pct(count(&|c| (c.shrinkage_ratio - 1.0).abs() <= 0.2)),
            );
        }
    }
    // Where it stops working, season by season: those at ≥ 10 % of the
    // variance that miss a target.
    let misses: Vec<&Case> = cases
        .iter()
        .filter(|c| c.error.is_none() && c.effect.is_some() && c.variance_share >= 0.1)
        .filter(|c| !c.hit_axle || (c.shrinkage_ratio - 1.0).abs() > 0.2)
        .collect();
    if !misses.is_empty() {
        s.push_str(
            "\nSeasons at ≥ 10 % of the variance that miss a target (testing RMSE in %):\n\n| effect (magnitude, threshold) | seed | variance share | first term | front share (truth) | RMSE baseline / diagnosed / ideal | shrinkage / ideal |\n|---|---|---|---|---|---|---|\n",
        );
        for c in misses {
            let e = c.effect.as_ref().expect("planted");
            let _ = writeln!(
                s,
                "| {} ({}, {}) | {} | {:.1} % | {} | {:.2} ({:.2}) | {:.3} / {:.3} / {:.3} | {:.3} |",
                e.kind.name(),
                e.magnitude,
                significant(e.threshold),
                c.seed,
                100.0 * c.variance_share,
                c.first_term.as_deref().unwrap_or("none"),
                c.first_front_share,
                c.truth_front_share,
                c.rmse_baseline_pct,
                c.rmse_diagnosed_pct,
                c.rmse_ideal_pct,
                c.shrinkage_ratio,
            );
        }
    }
    render_generated(&mut s, cases);
    let clean: Vec<&Case> = cases
        .iter()
        .filter(|c| c.effect.is_none() && c.generated.is_none())
        .collect();
    if !clean.is_empty() {
        let fd = clean.iter().filter(|c| c.significant_terms > 0).count();
        let _ = writeln!(
            s,
            "\nClean seasons: {fd} of {} report a significant effect ({:.0} %).",
            clean.len(),
            100.0 * fd as f64 / clean.len() as f64
        );
        for c in clean.iter().filter(|c| c.significant_terms > 0) {
            let _ = writeln!(
                s,
                "- seed {}: {}",
                c.seed,
                c.first_term.as_deref().unwrap_or("?")
            );
        }
    }
    let failed: Vec<&Case> = cases.iter().filter(|c| c.error.is_some()).collect();
    for c in failed {
        let _ = writeln!(
            s,
            "- failed: {:?} seed {}: {}",
            c.effect.as_ref().map(|e| e.to_string()),
            c.seed,
            c.error.as_deref().unwrap_or("")
        );
    }
    s
}

/// The generated effects: the targets over those at ≥ 10 % of the
/// variance (median shrinkage ≥ 0.8 of the ideal, hit ≥ 80 %), by form and
/// scope, then season by season.
fn render_generated(s: &mut String, cases: &[Case]) {
    let generated: Vec<&Case> = cases
        .iter()
        .filter(|c| c.generated.is_some() && c.error.is_none())
        .collect();
    if generated.is_empty() {
        return;
    }
    let big: Vec<&Case> = generated
        .iter()
        .copied()
        .filter(|c| c.variance_share >= 0.1)
        .collect();
    let line = |s: &mut String, label: &str, g: &[&Case]| {
        let n = g.len();
        if n == 0 {
            return;
        }
        let hits = g.iter().filter(|c| c.hit).count();
        let _ = writeln!(
            s,
            "| {label} | {n} | {hits}/{n} ({:.0} %) | {:.2} | {:.2} | {} |",
            100.0 * hits as f64 / n as f64,
            median(g.iter().map(|c| c.terms_correlation).collect()),
            median(g.iter().map(|c| c.shrinkage_ratio).collect()),
            g.iter().filter(|c| c.significant_terms == 0).count(),
        );
    };
    s.push_str(
        "\nGenerated effects (targets over those at ≥ 10 % of the wear variance: hit ≥ 80 %, median shrinkage ≥ 0.8 of the ideal; hit: the terms' wear correlates ≥ 0.8 with the planted wear):\n\n| seasons | n | hit | correlation (median) | shrinkage / ideal (median) | no term |\n|---|---|---|---|---|---|\n",
    );
    line(s, "all generated", &generated);
    line(s, "≥ 10 % of the variance", &big);
    // By form, then by scope.
    for part in 0..2 {
        let mut groups: BTreeMap<String, Vec<&Case>> = BTreeMap::new();
        for c in &big {
            let g = c.generated.as_ref().expect("generated");
            let (form, scope) = g.kind_label();
            let key = if part == 0 { form } else { scope };
            groups.entry(key.to_string()).or_default().push(c);
        }
        for (label, g) in &groups {
            line(s, &format!("≥ 10 %: {label}"), g);
        }
    }
    s.push_str(
        "\n| effect | variance share | terms | correlation | RMSE baseline / diagnosed / ideal | shrinkage / ideal |\n|---|---|---|---|---|---|\n",
    );
    for c in &generated {
        let g = c.generated.as_ref().expect("generated");
        let _ = writeln!(
            s,
            "| {g} | {:.1} % | {} | {:.2} | {:.3} / {:.3} / {:.3} | {:.2} |",
            100.0 * c.variance_share,
            c.first_term
                .as_deref()
                .map_or("none".to_string(), |t| format!(
                    "{} (of {})",
                    t, c.significant_terms
                )),
            c.terms_correlation,
            c.rmse_baseline_pct,
            c.rmse_diagnosed_pct,
            c.rmse_ideal_pct,
            c.shrinkage_ratio,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn case(kind: EffectKind, seed: u64, share: f64, shrinkage: f64) -> Case {
        Case {
            effect: Some(Effect::with_defaults(kind, 2.0)),
            seed,
            variance_share: share,
            truth_front_share: 0.32,
            first_term: Some("road abrasion (energy × squared micro-roughness)".into()),
            first_mechanism: Some(kind.name().into()),
            first_front_share: 0.35,
            significant_terms: 1,
            hit: true,
            hit_axle: true,
            rmse_baseline_pct: 9.0,
            rmse_diagnosed_pct: 9.0 - shrinkage * 7.0,
            rmse_ideal_pct: 2.0,
            shrinkage_ratio: shrinkage,
            terms_correlation: f64::NAN,
            generated: None,
            error: None,
        }
    }

    #[test]
    fn the_seasons_that_miss_a_target_are_listed() {
        let cases = [
            case(EffectKind::RoadAbrasion, 1, 0.184, 0.799),
            case(EffectKind::RoadAbrasion, 2, 0.254, 0.95),
            // Under 10 % of the variance: no target, not listed.
            case(EffectKind::RoadAbrasion, 3, 0.05, 0.3),
        ];
        let md = render(&cases);
        assert!(
            md.contains("| road-abrasion (2, 0.03000) | 1 | 18.4 % |"),
            "{md}"
        );
        assert!(md.contains("| 9.000 / 3.407 / 2.000 | 0.799 |"), "{md}");
        assert!(!md.contains("| road-abrasion (2, 0.03000) | 2 |"), "{md}");
        assert!(!md.contains("| road-abrasion (2, 0.03000) | 3 |"), "{md}");
        assert!(md.contains("| road-abrasion | 2 | 2/2 (100 %) | 2/2 (100 %) | 1/2 (50 %) |"));
    }
}
