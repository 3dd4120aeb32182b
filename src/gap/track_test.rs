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
use super::linear::{lstsq, orthonormal_basis};
use super::scoring::{max_f, projected, track_cells};
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
        let mut cols: Vec<&[f64]> = base
            .iter()
            .zip(track_level)
            .filter(|(_, t)| !**t)
            .map(|(c, _)| c.as_slice())
            .collect();
        let n_within = cols.len();
        let (cells, cell_cols) = track_cells(rows, prediction, &all);
        cols.extend(cell_cols.iter().map(|c| c.as_slice()));
        let k = lstsq(&cols, y, &all);
        // The scale of each (track, axle) cell; each axle's reference track is 0.
        let scale = |track: &str, axle: Axle| -> f64 {
            cells
                .iter()
                .position(|(a, t)| *a == axle && *t == track)
                .map_or(0.0, |j| k[n_within + j])
        };
        let design = |axle: Option<Axle>| -> Option<Design> {
            let nt = tracks.rows.len();
            let (mut sum, mut count) = (vec![0.0; nt], vec![0usize; nt]);
            let mut cov_sum = vec![vec![0.0; nt]; base.len()];
            for (i, r) in rows.iter().enumerate() {
                if axle.is_none_or(|a| r.axle == a) {
                    let t = tracks.of_row[i];
                    sum[t] += scale(&r.track, r.axle);
                    count[t] += 1;
                    for (j, c) in base.iter().enumerate() {
                        cov_sum[j][t] += c[i];
                    }
                }
            }
            let kept: Vec<usize> = (0..nt).filter(|&t| count[t] > 0).collect();
            let mean =
                |v: &[f64]| -> Vec<f64> { kept.iter().map(|&t| v[t] / count[t] as f64).collect() };
            let mut covariates = vec![vec![1.0; kept.len()]];
            for (j, _) in track_level.iter().enumerate().filter(|(_, t)| **t) {
                covariates.push(mean(&cov_sum[j]));
            }
            let idx: Vec<usize> = (0..kept.len()).collect();
            let refs: Vec<&[f64]> = covariates.iter().map(|c| c.as_slice()).collect();
            let q = orthonormal_basis(&refs, &idx);
            let severity = mean(&sum);
            (kept.len() >= MIN_TRACKS && kept.len() > q.len() + 1).then_some(Design {
                severity,
                kept,
                q,
            })
        };
        let designs = [
            design(None),
            design(Some(Axle::Front)),
            design(Some(Axle::Rear)),
        ];
        Severities { tracks, designs }
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
        let slot = match c.axle {
            None => 0,
            Some(Axle::Front) => 1,
            Some(Axle::Rear) => 2,
        };
        let Some(d) = &self.designs[slot] else {
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
        let (ft, nf) = projected(&d.q, &values);
        let positive = c.adds_wear_only();
        let observed = max_f(&d.severity, &d.q, &ft, &nf, positive);
        if observed <= 0.0 {
            return 1.0;
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut e = vec![0.0; d.kept.len()];
        let mut exceed = 0usize;
        for _ in 0..draws {
            for v in e.iter_mut() {
                *v = StandardNormal.sample(&mut rng);
            }
            if max_f(&e, &d.q, &ft, &nf, positive) >= observed {
                exceed += 1;
            }
        }
        (1 + exceed) as f64 / (1 + draws) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::candidates::Feature;

    /// 7 tracks × 10 tires (alternating axles), each tire's relative wear
    /// `1 + severity(Ra_micro, track)` plus a within-track wobble; the
    /// baseline's design is one column of ones (relative scale).
    fn p_of(severity: impl Fn(f64, usize) -> f64, draws: usize, seed: u64) -> f64 {
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
        let refs: Vec<&KpiRow> = rows.iter().collect();
        let n = rows.len();
        let base = vec![vec![1.0; n]];
        let s = Severities::new(&refs, &y, &base, &[false], &vec![1.0; n]);
        let road = Candidate {
            name: "road".into(),
            feature: Feature::RoughRoadEnergy,
            thresholds: vec![0.0, 0.008, 0.012],
            axle: None,
            user: None,
            group: None,
            scopes: Vec::new(),
        };
        s.p_value(&road, KpiScale::NONE, draws, seed)
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
        // Under the null, p is about uniform: over 40 noise patterns, about
        // 5 % fall at or below 0.05 (binomial(40, 0.05): at most 6 with 99 %
        // odds), and a fair share lies above one half.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let ps: Vec<f64> = (0..40)
            .map(|rep| {
                let noise: Vec<f64> = (0..7)
                    .map(|_| {
                        let z: f64 = StandardNormal.sample(&mut rng);
                        0.02 * z
                    })
                    .collect();
                p_of(|_, t| noise[t], 499, rep)
            })
            .collect();
        let small = ps.iter().filter(|p| **p <= 0.05).count();
        let large = ps.iter().filter(|p| **p > 0.5).count();
        assert!(small <= 6, "{small} of 40 at or below 0.05: {ps:?}");
        assert!(large >= 10, "{large} of 40 above 0.5: {ps:?}");
    }
}
