//! The significance test of a track-level (road) term: a nested-model F test
//! on the tracks themselves.
//!
//! A road term is the row's energy times a value of its track, so only the
//! tracks can tell it apart from the other track-level causes (the road's
//! hidden abrasiveness, which no KPI measures). With the six or so training
//! tracks of a season, exchanging the tracks' values gives at most 6! = 720
//! distinct permutations: the p-value cannot fall below ~1/720, and after
//! Benjamini–Hochberg over some forty candidates nothing survives, however
//! strong the effect (docs/gap.md). So the test works in two stages:
//!
//! 1. each track's severity α_t: its scale in the within-track null (the
//!    baseline's columns that vary within tracks, refitted, and a scale per
//!    track and axle), on the candidate's axle. The compounds are compared
//!    within tracks, so a compound raced at few tracks does not soak up
//!    their severity.
//! 2. the tracks' severities regressed on the baseline's track-level part
//!    (an intercept and the track means of its track-level columns: the
//!    skewness factor exp(s·Sk), road terms already selected) with and
//!    without the candidate's track value v_t(θ): the F ratio of the nested
//!    models, the largest over the threshold grid.
//!
//! Under the null the severities are independent normal deviations around
//! the baseline's track-level part (the track random effect), so the largest
//! F over the grid has a distribution that depends only on the design, and
//! is simulated exactly (Monte Carlo draws of normal severities). The
//! p-value resolves to 1/(draws + 1) whatever the number of tracks.

use super::candidates::{Candidate, KpiScale, track_value};
use super::linear::{Solver, orthonormal_basis};
use super::scoring::{max_f, projected, track_cells, varying_within_tracks};
use super::stats::levels;
use crate::Axle;
use crate::kpi::KpiRow;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

/// Tracks fewer than this leave no degree of freedom for the test.
pub(crate) const MIN_TRACKS: usize = 4;

/// The tracks of the rows scored: a representative row each, each row's track.
pub(crate) struct Tracks<'a> {
    pub rows: Vec<&'a KpiRow>,
    pub of_row: Vec<usize>,
}

impl<'a> Tracks<'a> {
    pub fn new(rows: &[&'a KpiRow]) -> Tracks<'a> {
        let (names, of_row) = levels(rows.iter().map(|r| r.track.as_str()));
        let track_rows = names
            .iter()
            .map(|t| *rows.iter().find(|r| r.track == *t).expect("listed"))
            .collect();
        Tracks {
            rows: track_rows,
            of_row,
        }
    }
}

/// Stage 2's data for one choice of axles: the tracks kept, their
/// severities and the orthonormal basis of the track-level null.
struct Design {
    kept: Vec<usize>,
    severity: Vec<f64>,
    q: Vec<Vec<f64>>,
}

/// The track severities of a problem, for both axles and each axle alone.
pub(crate) struct Severities<'a> {
    tracks: Tracks<'a>,
    /// Both axles, front, rear.
    designs: [Option<Design>; 3],
    /// Front less rear, rear less front: a one-axle term's between-track
    /// part ([`Severities::p_between`]).
    contrasts: [Option<Design>; 2],
    /// How many of stage 1's columns (the base columns that vary within
    /// tracks, then the (track, axle) scales) are base columns.
    n_within: usize,
    /// Stage 1 factored once: a within-track candidate's own track scales
    /// ([`Severities::p_between`]) are one solve each.
    solver: Solver,
    /// Each row's scale among the cells (None: its axle's reference track).
    cell_of_row: Vec<Option<usize>>,
    axle_of_row: Vec<Axle>,
}

/// The design slot of an axle scope: both axles, front, rear.
fn slot(axle: Option<Axle>) -> usize {
    match axle {
        None => 0,
        Some(Axle::Front) => 1,
        Some(Axle::Rear) => 2,
    }
}

impl Design {
    /// The design of `kept` tracks' `severity` against the null's
    /// `covariates` (one value per kept track each); None when too few
    /// tracks are left beyond the null's columns.
    fn new(kept: Vec<usize>, severity: Vec<f64>, covariates: &[Vec<f64>]) -> Option<Design> {
        let idx: Vec<usize> = (0..kept.len()).collect();
        let refs: Vec<&[f64]> = covariates.iter().map(|c| c.as_slice()).collect();
        let q = orthonormal_basis(&refs, &idx);
        (kept.len() >= MIN_TRACKS && kept.len() > q.len() + 1).then_some(Design {
            severity,
            kept,
            q,
        })
    }
}

/// The other axle.
fn other_axle(axle: Axle) -> Axle {
    match axle {
        Axle::Front => Axle::Rear,
        Axle::Rear => Axle::Front,
    }
}

/// Per track and axle scope: the rows counted and the sums of the base's
/// track-level columns (stage 2's null).
struct TrackMeans {
    /// Per slot (both, front, rear): rows per track.
    count: [Vec<usize>; 3],
    /// Per slot, per track-level column: its sum per track.
    sums: [Vec<Vec<f64>>; 3],
}

impl TrackMeans {
    fn new(s: &Severities, base: &[Vec<f64>], track_level: &[bool]) -> TrackMeans {
        let nt = s.tracks.rows.len();
        let columns: Vec<&Vec<f64>> = base
            .iter()
            .zip(track_level)
            .filter(|(_, t)| **t)
            .map(|(c, _)| c)
            .collect();
        let mut count: [Vec<usize>; 3] = Default::default();
        let mut sums: [Vec<Vec<f64>>; 3] = Default::default();
        for axle in [None, Some(Axle::Front), Some(Axle::Rear)] {
            let (n, sum) = (&mut count[slot(axle)], &mut sums[slot(axle)]);
            *n = vec![0; nt];
            *sum = vec![vec![0.0; nt]; columns.len()];
            for (i, &t) in s.tracks.of_row.iter().enumerate() {
                if axle.is_none_or(|a| s.axle_of_row[i] == a) {
                    n[t] += 1;
                    for (j, c) in columns.iter().enumerate() {
                        sum[j][t] += c[i];
                    }
                }
            }
        }
        TrackMeans { count, sums }
    }

    /// The tracks with rows in every one of `scopes`.
    fn kept(&self, scopes: &[Option<Axle>]) -> Vec<usize> {
        (0..self.count[0].len())
            .filter(|&t| scopes.iter().all(|&a| self.count[slot(a)][t] > 0))
            .collect()
    }

    /// The null's columns on `kept` for `axle`: an intercept, then each
    /// track-level column's mean per track.
    fn covariates(&self, axle: Option<Axle>, kept: &[usize]) -> Vec<Vec<f64>> {
        let (n, sums) = (&self.count[slot(axle)], &self.sums[slot(axle)]);
        let mut out = vec![vec![1.0; kept.len()]];
        out.extend(
            sums.iter()
                .map(|sum| kept.iter().map(|&t| sum[t] / n[t] as f64).collect()),
        );
        out
    }
}

impl<'a> Severities<'a> {
    /// `y` and `base` on the scale scored (relative for the physics law);
    /// `prediction`: the baseline's prediction on that scale (1 on the
    /// relative scale); `track_level[j]`: base column j is constant within
    /// tracks up to the relative weights (goes to stage 2).
    pub fn new(
        rows: &[&'a KpiRow],
        y: &[f64],
        base: &[Vec<f64>],
        track_level: &[bool],
        prediction: &[f64],
    ) -> Severities<'a> {
        let tracks = Tracks::new(rows);
        let all: Vec<usize> = (0..rows.len()).collect();
        let mut stage1 = varying_within_tracks(base, track_level);
        let n_within = stage1.len();
        let (cells, cell_cols) = track_cells(rows, prediction, &all);
        stage1.extend(cell_cols);
        let cell_of_row: Vec<Option<usize>> = rows
            .iter()
            .map(|r| {
                cells
                    .iter()
                    .position(|(a, t)| *a == r.axle && *t == r.track)
            })
            .collect();
        let refs: Vec<&[f64]> = stage1.iter().map(|c| c.as_slice()).collect();
        let solver = Solver::new(&refs, &all);
        let k = solver.coefficients(y);
        let mut s = Severities {
            tracks,
            designs: [None, None, None],
            contrasts: [None, None],
            n_within,
            solver,
            cell_of_row,
            axle_of_row: rows.iter().map(|r| r.axle).collect(),
        };
        let means = TrackMeans::new(&s, base, track_level);
        for axle in [None, Some(Axle::Front), Some(Axle::Rear)] {
            let kept = means.kept(&[axle]);
            let covariates = means.covariates(axle, &kept);
            let severity = s.track_means(&k[n_within..], axle, &kept);
            // What the between-track test regresses, for tracing a season
            // whose effect lies between tracks (docs/gap.md).
            tracing::debug!(
                axle = ?axle,
                severities = ?kept
                    .iter()
                    .zip(&severity)
                    .map(|(&t, v)| (s.tracks.rows[t].track.as_str(), *v))
                    .collect::<Vec<_>>(),
                "stage-1 track severities"
            );
            s.designs[slot(axle)] = Design::new(kept, severity, &covariates);
        }
        for axle in Axle::ALL {
            let other = Some(other_axle(axle));
            let kept = means.kept(&[Some(axle), other]);
            let mut covariates = means.covariates(Some(axle), &kept);
            for (c, o) in covariates.iter_mut().zip(means.covariates(other, &kept)) {
                c.iter_mut().zip(o).for_each(|(a, b)| *a -= b);
            }
            // The intercept: a constant ratio of the axles' severities.
            covariates[0] = vec![1.0; kept.len()];
            let severity = s.track_contrast(&k[n_within..], axle, &kept);
            s.contrasts[slot(Some(axle)) - 1] = Design::new(kept, severity, &covariates);
        }
        s
    }

    /// Per track of `kept`: the severity (`scales` as in
    /// [`Severities::track_means`]) on `axle` less that on the other axle.
    fn track_contrast(&self, scales: &[f64], axle: Axle, kept: &[usize]) -> Vec<f64> {
        let on = self.track_means(scales, Some(axle), kept);
        let off = self.track_means(scales, Some(other_axle(axle)), kept);
        on.iter().zip(off).map(|(a, b)| a - b).collect()
    }

    /// Per track of `kept`: the mean over its rows on `axle` (None: both)
    /// of their cell's scale in `scales` (stage 1's cell coefficients; 0 for
    /// the axle's reference track).
    fn track_means(&self, scales: &[f64], axle: Option<Axle>, kept: &[usize]) -> Vec<f64> {
        let nt = self.tracks.rows.len();
        let (mut sum, mut count) = (vec![0.0; nt], vec![0usize; nt]);
        for (i, cell) in self.cell_of_row.iter().enumerate() {
            if axle.is_none_or(|a| self.axle_of_row[i] == a) {
                let t = self.tracks.of_row[i];
                sum[t] += cell.map_or(0.0, |c| scales[c]);
                count[t] += 1;
            }
        }
        kept.iter().map(|&t| sum[t] / count[t] as f64).collect()
    }

    /// p-value of the track-level candidate `c`: the largest F over its
    /// thresholds against `draws` Monte Carlo draws; 1 when fewer than
    /// [`MIN_TRACKS`] tracks (or too few beyond the null's columns) carry
    /// rows on its axle.
    pub(crate) fn p_value(
        &self,
        c: &Candidate,
        kpi_scale: KpiScale,
        draws: usize,
        seed: u64,
    ) -> f64 {
        let Some(d) = &self.designs[slot(c.axle)] else {
            return 1.0;
        };
        let values: Vec<Vec<f64>> = c
            .thresholds
            .iter()
            .map(|&t| {
                d.kept
                    .iter()
                    .map(|&k| track_value(c, self.tracks.rows[k], t, kpi_scale))
                    .collect()
            })
            .collect();
        if values.iter().flatten().any(|v| !v.is_finite()) {
            return 1.0;
        }
        monte_carlo_p(d, &values, c.adds_wear_only(), draws, None, seed)
    }

    /// The design a within-track term of `axle`'s scope is tested on
    /// between tracks: the severities of both axles, or the axles' contrast.
    fn design_between(&self, axle: Option<Axle>) -> Option<&Design> {
        match axle {
            None => self.designs[0].as_ref(),
            Some(a) => self.contrasts[slot(Some(a)) - 1].as_ref(),
        }
    }

    /// p-value of a within-track term's **between-track part**: how the
    /// tracks' severities follow the term's own track scales.
    ///
    /// `columns`: the term on the scale scored, one per scope and threshold,
    /// with the scope's axle (None: both). Stage 1 is linear, so were the
    /// wear to carry `c` times a column, each severity would move by `c`
    /// times that column's own scale at the track (its coefficient on the
    /// track's cell when it is regressed on stage 1's columns): that is the
    /// track value stage 2 tests, the largest F over the columns of each
    /// axle scope. The scopes' p-values are combined by Bonferroni (the
    /// smallest times the number of scopes tested).
    ///
    /// An effect on every tire or on one axle, with wear that differs
    /// between runs rather than between a run's tires, lies mostly between
    /// tracks: the within-track test, whose null has a scale per track and
    /// axle, weighs it against the run-level scatter alone (docs/gap.md,
    /// "At real-data noise"). This is the other half of its evidence.
    ///
    /// A term on one axle is tested on the tracks' **contrast** of the
    /// axles, its axle's severity less the other's: what a track and its
    /// day do to every tire (the road's hidden abrasiveness, the grip, the
    /// drivers' runs) cancels there, and what is left is the tires' own
    /// scatter and the term. Its null has an intercept (the axles' ratio
    /// the baseline's calibration sets) and the contrasts of the base's
    /// track-level columns.
    ///
    /// The Monte Carlo stops at 20 exceedances (Besag and Clifford's
    /// sequential p-value): most candidates are far from significant.
    pub(crate) fn p_between(
        &self,
        columns: &[(Option<Axle>, &[f64])],
        positive: bool,
        draws: usize,
        seed: u64,
    ) -> f64 {
        let mut values: [Vec<Vec<f64>>; 3] = Default::default();
        for (axle, x) in columns {
            let Some(d) = self.design_between(*axle) else {
                continue;
            };
            let k = self.solver.coefficients(x);
            let v = match axle {
                None => self.track_means(&k[self.n_within..], None, &d.kept),
                Some(a) => self.track_contrast(&k[self.n_within..], *a, &d.kept),
            };
            if v.iter().all(|x| x.is_finite()) {
                values[slot(*axle)].push(v);
            }
        }
        let tested: Vec<f64> = values
            .iter()
            .zip([None, Some(Axle::Front), Some(Axle::Rear)])
            .enumerate()
            .filter_map(|(s, (v, axle))| {
                let d = self.design_between(axle)?;
                (!v.is_empty())
                    .then(|| monte_carlo_p(d, v, positive, draws, Some(20), seed ^ s as u64))
            })
            .collect();
        let smallest = tested.iter().fold(1.0f64, |m, p| m.min(*p));
        (smallest * tested.len().max(1) as f64).min(1.0)
    }
}

/// The Monte Carlo p-value of the largest F of the tracks' severities
/// against the track values `values` (one vector per threshold), under
/// independent normal severities around the track-level null. With `stop`,
/// the draws end at that many exceedances, p = stop / draws so far (Besag
/// and Clifford); otherwise p = (1 + exceedances) / (1 + draws).
fn monte_carlo_p(
    d: &Design,
    values: &[Vec<f64>],
    positive: bool,
    draws: usize,
    stop: Option<usize>,
    seed: u64,
) -> f64 {
    let (ft, nf) = projected(&d.q, values);
    let observed = max_f(&d.severity, &d.q, &ft, &nf, positive);
    if observed <= 0.0 {
        return 1.0;
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut e = vec![0.0; d.kept.len()];
    let mut exceed = 0usize;
    for drawn in 1..=draws {
        for v in e.iter_mut() {
            *v = StandardNormal.sample(&mut rng);
        }
        if max_f(&e, &d.q, &ft, &nf, positive) >= observed {
            exceed += 1;
            if stop == Some(exceed) {
                return exceed as f64 / drawn as f64;
            }
        }
    }
    (1 + exceed) as f64 / (1 + draws) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::candidates::Feature;

    /// 7 tracks × 10 tires (alternating axles), each tire's relative wear
    /// `1 + severity(Ra_micro, track)` plus a within-track wobble.
    fn road_rows(severity: impl Fn(f64, usize) -> f64) -> (Vec<KpiRow>, Vec<f64>) {
        let mut rows = Vec::new();
        let mut y = Vec::new();
        for t in 0..7 {
            let ra = 0.005 + 0.002 * t as f64;
            for k in 0..10 {
                rows.push(KpiRow {
                    track: format!("T{t}"),
                    axle: if k % 2 == 0 { Axle::Front } else { Axle::Rear },
                    ra_micro_mm: ra,
                    skewness: [-0.5, 0.1, -0.9, -0.2, 0.0, -0.7, -0.3][t],
                    friction_energy_j: 1e6,
                    ..Default::default()
                });
                y.push(1.0 + severity(ra, t) + 0.01 * ((k * 5 % 7) as f64 - 3.0));
            }
        }
        (rows, y)
    }

    /// Road abrasion on both axles at three thresholds of Ra_micro.
    fn road_candidate() -> Candidate {
        Candidate {
            name: "road".into(),
            feature: Feature::RoughRoadEnergy,
            thresholds: vec![0.0, 0.008, 0.012],
            axle: None,
            user: None,
            group: None,
            scopes: Vec::new(),
        }
    }

    /// The road test's p on [`road_rows`]; the baseline's design is one
    /// column of ones (relative scale).
    fn p_of(severity: impl Fn(f64, usize) -> f64, draws: usize, seed: u64) -> f64 {
        let (rows, y) = road_rows(severity);
        let refs: Vec<&KpiRow> = rows.iter().collect();
        let n = rows.len();
        let base = vec![vec![1.0; n]];
        let s = Severities::new(&refs, &y, &base, &[false], &vec![1.0; n]);
        let road = road_candidate();
        s.p_value(&road, KpiScale::NONE, draws, seed)
    }

    /// 12 tires (alternating axles) per track of `track_noise` (8 in the
    /// tests) on the relative scale: a
    /// term `x` whose level differs between tracks (0.1 … 0.8) with a small
    /// within-track spread, wear `1 + c·x + track noise + tire wobble`.
    /// The between-track p-value of `x` on both axles.
    fn between_p(c: f64, track_noise: &[f64], draws: usize, seed: u64) -> f64 {
        let mut rows = Vec::new();
        let (mut x, mut y) = (Vec::new(), Vec::new());
        for (t, noise) in track_noise.iter().enumerate() {
            let level = 0.1 * (1 + (t * 5) % 8) as f64;
            for k in 0..12 {
                rows.push(KpiRow {
                    track: format!("T{t}"),
                    axle: if k % 2 == 0 { Axle::Front } else { Axle::Rear },
                    ..Default::default()
                });
                let xi = level * (1.0 + 0.05 * ((k * 7 % 5) as f64 - 2.0));
                x.push(xi);
                y.push(1.0 + c * xi + noise + 0.01 * ((k * 5 % 7) as f64 - 3.0));
            }
        }
        let refs: Vec<&KpiRow> = rows.iter().collect();
        let n = rows.len();
        let s = Severities::new(&refs, &y, &[vec![1.0; n]], &[false], &vec![1.0; n]);
        s.p_between(&[(None, &x)], true, draws, seed)
    }

    #[test]
    fn a_term_between_tracks_is_found_on_the_severities() {
        // Track noise 0.02 (sd); the term moves the severities by 0.3·x,
        // 0.03 … 0.24: significant at the Monte Carlo floor.
        let noise = [0.02, -0.03, 0.01, 0.025, -0.015, -0.005, 0.015, -0.02];
        assert_eq!(between_p(0.3, &noise, 1999, 5), 1.0 / 2000.0);
        // The same tracks without the term: nothing to see.
        assert!(between_p(0.0, &noise, 1999, 5) > 0.05);
    }

    /// Under the null, p is about uniform: over 40 patterns of normal track
    /// noise (`tracks` tracks, sd `sd`, seeded), about 5 % fall at or below
    /// 0.05 (binomial(40, 0.05): at most 6 with 99 % odds), and a fair
    /// share lies above one half. `p_of(noise, rep)`: a pattern's p-value.
    fn holds_its_level(seed: u64, tracks: usize, sd: f64, p_of: impl Fn(&[f64], u64) -> f64) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let ps: Vec<f64> = (0..40)
            .map(|rep| {
                let noise: Vec<f64> = (0..tracks)
                    .map(|_| {
                        let z: f64 = StandardNormal.sample(&mut rng);
                        sd * z
                    })
                    .collect();
                p_of(&noise, rep)
            })
            .collect();
        let small = ps.iter().filter(|p| **p <= 0.05).count();
        let large = ps.iter().filter(|p| **p > 0.5).count();
        assert!(small <= 6, "{small} of 40 at or below 0.05: {ps:?}");
        assert!(large >= 10, "{large} of 40 above 0.5: {ps:?}");
    }

    #[test]
    fn a_term_between_tracks_holds_its_level_on_track_noise() {
        holds_its_level(11, 8, 0.03, |noise, rep| between_p(0.0, noise, 499, rep));
    }

    /// 12 tires (alternating axles) per track: wear `1 + shared[t] +
    /// own[t]·(±1 by axle) + c·x` with a term `x` on the rear tires only
    /// (0.1 … 0.8 by track). `shared`: what a track does to every tire,
    /// `own`: each axle's own track noise. (p of the rear term on the axles'
    /// contrast, p on the rears' severities alone.)
    fn rear_term_p(c: f64, shared: &[f64], own: &[f64], draws: usize, seed: u64) -> (f64, f64) {
        let mut rows = Vec::new();
        let (mut x, mut y) = (Vec::new(), Vec::new());
        for (t, (s, o)) in shared.iter().zip(own).enumerate() {
            let level = 0.1 * (1 + (t * 5) % 8) as f64;
            for k in 0..12 {
                let axle = if k % 2 == 0 { Axle::Front } else { Axle::Rear };
                rows.push(KpiRow {
                    track: format!("T{t}"),
                    axle,
                    ..Default::default()
                });
                let xi = if axle == Axle::Rear {
                    level * (1.0 + 0.05 * ((k * 7 % 5) as f64 - 2.0))
                } else {
                    0.0
                };
                let sign = if axle == Axle::Rear { 1.0 } else { -1.0 };
                x.push(xi);
                y.push(1.0 + s + sign * o + c * xi + 0.01 * ((k * 5 % 7) as f64 - 3.0));
            }
        }
        let refs: Vec<&KpiRow> = rows.iter().collect();
        let n = rows.len();
        let sev = Severities::new(&refs, &y, &[vec![1.0; n]], &[false], &vec![1.0; n]);
        let contrast = sev.p_between(&[(Some(Axle::Rear), &x)], true, draws, seed);
        // The same term's track values on the rears' severities alone.
        let k = sev.solver.coefficients(&x);
        let d = sev.designs[slot(Some(Axle::Rear))]
            .as_ref()
            .expect("8 tracks");
        let v = sev.track_means(&k[sev.n_within..], Some(Axle::Rear), &d.kept);
        let alone = monte_carlo_p(d, &[v], true, draws, None, seed);
        (contrast, alone)
    }

    #[test]
    fn a_term_on_one_axle_is_tested_on_the_axles_contrast() {
        // What each track does to every tire (sd 0.2) hides a rear term
        // of 0.03 … 0.24 on the rears' severities; on the contrast it
        // cancels, and the axles' own noise (sd 0.02) is all that is left.
        let shared = [0.25, -0.3, 0.1, -0.2, 0.35, -0.05, 0.15, -0.25];
        let own = [0.02, -0.03, 0.01, 0.025, -0.015, -0.005, 0.015, -0.02];
        let (contrast, alone) = rear_term_p(0.3, &shared, &own, 1999, 5);
        assert_eq!(contrast, 1.0 / 2000.0);
        assert!(alone > 0.05, "{alone}");
        // Without the term: nothing to see on either.
        let (contrast, _) = rear_term_p(0.0, &shared, &own, 1999, 5);
        assert!(contrast > 0.05, "{contrast}");
    }

    #[test]
    fn the_axles_contrast_holds_its_level_on_track_noise() {
        // Large shared track noise, the axles' own noise normal (sd 0.03).
        let shared = [0.25, -0.3, 0.1, -0.2, 0.35, -0.05, 0.15, -0.25];
        holds_its_level(13, 8, 0.03, |own, rep| {
            rear_term_p(0.0, &shared, own, 499, rep).0
        });
    }

    #[test]
    fn a_track_level_column_between_tracks_is_the_road_test() {
        // A column constant within each track has its track value (less the
        // reference track's, which stage 2's intercept takes) as its own
        // scales: its between-track p equals the road test's, draw for draw.
        let noise = [0.004, -0.006, 0.002, 0.005, -0.003, -0.001, 0.003];
        let severity = |ra: f64, t: usize| 20.0 * (ra - 0.008).max(0.0) + noise[t];
        let (rows, y) = road_rows(severity);
        let refs: Vec<&KpiRow> = rows.iter().collect();
        let n = rows.len();
        let s = Severities::new(&refs, &y, &[vec![1.0; n]], &[false], &vec![1.0; n]);
        let road = road_candidate();
        let columns: Vec<Vec<f64>> = road
            .thresholds
            .iter()
            .map(|&th| {
                rows.iter()
                    .map(|r| track_value(&road, r, th, KpiScale::NONE))
                    .collect()
            })
            .collect();
        // The scales themselves: v_t − v_0 on both axles, on each axle.
        for (column, &th) in columns.iter().zip(&road.thresholds) {
            let k = s.solver.coefficients(column);
            let v: Vec<f64> = s
                .tracks
                .rows
                .iter()
                .map(|r| track_value(&road, r, th, KpiScale::NONE))
                .collect();
            for axle in [None, Some(Axle::Front), Some(Axle::Rear)] {
                let d = s.designs[slot(axle)].as_ref().expect("7 tracks");
                let got = s.track_means(&k[s.n_within..], axle, &d.kept);
                for (g, &t) in got.iter().zip(&d.kept) {
                    assert!((g - (v[t] - v[0])).abs() < 1e-9, "{got:?} vs {v:?}");
                }
            }
        }
        let refs: Vec<(Option<Axle>, &[f64])> =
            columns.iter().map(|c| (None, c.as_slice())).collect();
        for (draws, seed) in [(199, 3), (1999, 7)] {
            assert_eq!(
                s.p_between(&refs, true, draws, seed),
                s.p_value(&road, KpiScale::NONE, draws, seed)
            );
        }
    }

    #[test]
    fn a_road_law_is_significant_beyond_the_permutation_floor() {
        // Severity grows with Ra_micro above 8 µm, plus track noise of 0.5 %.
        let noise = [0.004, -0.006, 0.002, 0.005, -0.003, -0.001, 0.003];
        let p = p_of(|ra, t| 20.0 * (ra - 0.008).max(0.0) + noise[t], 1999, 7);
        // 7 tracks exchanged give at most 5040 orders, and many of them fit a
        // hinge nearly as well; a fit this close reaches the Monte Carlo floor.
        assert_eq!(p, 1.0 / 2000.0);
    }

    #[test]
    fn track_noise_alone_gives_about_uniform_p() {
        holds_its_level(3, 7, 0.02, |noise, rep| p_of(|_, t| noise[t], 499, rep));
    }
}
