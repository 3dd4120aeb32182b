//! Small statistics of the gap diagnosis: the difference of a slice's mean
//! residual from the rest's for residuals clustered in events (a random
//! intercept per event), Benjamini–Hochberg false-discovery control, and
//! the Kaplan–Meier and censored-normal (Tobit) tail means that impute
//! worn-through tires' wear.

use statrs::distribution::{Continuous, ContinuousCDF, Normal, StudentsT};

/// The distinct levels of `keys` (sorted) and each key's level index.
pub(crate) fn levels<'a>(
    keys: impl Iterator<Item = &'a str> + Clone,
) -> (Vec<&'a str>, Vec<usize>) {
    let mut names: Vec<&str> = keys.clone().collect();
    names.sort();
    names.dedup();
    let index = keys
        .map(|k| names.binary_search(&k).expect("listed"))
        .collect();
    (names, index)
}

/// One-way variance components of residuals grouped in clusters (events):
/// r = e_cluster + ε, by the ANOVA method of moments (unbalanced).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VarianceComponents {
    /// Within-cluster variance σ_w² (the mean square within), N − G degrees of freedom.
    pub within: f64,
    /// Between-cluster variance σ_e² (floored at 0), G − 1 degrees of freedom.
    pub between: f64,
    pub clusters: usize,
    pub n: usize,
}

impl VarianceComponents {
    /// `cluster[i]` in 0..G for each residual.
    pub fn estimate(r: &[f64], cluster: &[usize]) -> VarianceComponents {
        let g = cluster.iter().copied().max().map_or(0, |m| m + 1);
        let (mut sum, mut count) = (vec![0.0; g], vec![0usize; g]);
        for (v, &c) in r.iter().zip(cluster) {
            sum[c] += v;
            count[c] += 1;
        }
        let n = r.len();
        let groups = count.iter().filter(|&&c| c > 0).count();
        let grand = r.iter().sum::<f64>() / n as f64;
        let mean = |c: usize| sum[c] / count[c] as f64;
        let ssw: f64 = r
            .iter()
            .zip(cluster)
            .map(|(v, &c)| (v - mean(c)).powi(2))
            .sum();
        let ssb: f64 = (0..g)
            .filter(|&c| count[c] > 0)
            .map(|c| count[c] as f64 * (mean(c) - grand).powi(2))
            .sum();
        let within = if n > groups {
            ssw / (n - groups) as f64
        } else {
            0.0
        };
        let between = if groups > 1 {
            let msb = ssb / (groups - 1) as f64;
            let sq: f64 = count.iter().map(|&c| (c * c) as f64).sum();
            let n0 = (n as f64 - sq / n as f64) / (groups - 1) as f64;
            ((msb - within) / n0).max(0.0)
        } else {
            0.0
        };
        VarianceComponents {
            within,
            between,
            clusters: groups,
            n,
        }
    }

    /// The same for clusters nested in cells (`cell[i]`, constant within a
    /// cluster): σ_e² is the clusters' scatter around their own cell's mean,
    /// so a shift that every cluster of a cell shares (one car at one event:
    /// a set-up of that car) is not counted as scatter between clusters.
    /// Nested ANOVA by moments: MS_b = Σ_g m_g (ē_g − ē_cell(g))² / (G − C)
    /// and n₀ = (N − Σ_cells Σ_g m_g² / N_cell) / (G − C); one cell gives
    /// [`VarianceComponents::estimate`].
    pub fn estimate_nested(r: &[f64], cluster: &[usize], cell: &[usize]) -> VarianceComponents {
        let one = VarianceComponents::estimate(r, cluster);
        let g = cluster.iter().copied().max().map_or(0, |m| m + 1);
        let c = cell.iter().copied().max().map_or(0, |m| m + 1);
        let (mut sum, mut count, mut cell_of) = (vec![0.0; g], vec![0usize; g], vec![0; g]);
        let (mut cell_sum, mut cell_n) = (vec![0.0; c], vec![0usize; c]);
        for ((v, &k), &e) in r.iter().zip(cluster).zip(cell) {
            sum[k] += v;
            count[k] += 1;
            cell_of[k] = e;
            cell_sum[e] += v;
            cell_n[e] += 1;
        }
        let cells = cell_n.iter().filter(|&&m| m > 0).count();
        let df = one.clusters.saturating_sub(cells);
        let between = if df > 0 {
            let (mut ssb, mut sq) = (0.0, 0.0);
            for k in (0..g).filter(|&k| count[k] > 0) {
                let e = cell_of[k];
                let m = count[k] as f64;
                ssb += m * (sum[k] / m - cell_sum[e] / cell_n[e] as f64).powi(2);
                sq += m * m / cell_n[e] as f64;
            }
            let n0 = (r.len() as f64 - sq) / df as f64;
            ((ssb / df as f64 - one.within) / n0).max(0.0)
        } else {
            0.0
        };
        VarianceComponents { between, ..one }
    }
}

/// mean(r | inside) − mean(r | outside) for residuals with a random
/// intercept per cluster: (difference, 95 % CI, two-sided p). Its variance
/// σ_w²(1/n_a + 1/n_b) + σ_e² Σ_g (n_ag/n_a − n_bg/n_b)² is exact under the
/// model: a slice that is one event carries that event's whole offset, a
/// slice spread evenly over the events (an axle) none. Student's t with
/// Satterthwaite's degrees of freedom (σ_w² on N − G, σ_e² on G − 1).
pub fn clustered_difference(
    inside: &[bool],
    r: &[f64],
    cluster: &[usize],
    vc: &VarianceComponents,
) -> (f64, (f64, f64), f64) {
    let g = cluster.iter().copied().max().map_or(0, |m| m + 1);
    let (mut na_g, mut nb_g) = (vec![0.0; g], vec![0.0; g]);
    let (mut sa, mut sb) = (0.0, 0.0);
    for ((&m, &v), &c) in inside.iter().zip(r).zip(cluster) {
        if m {
            na_g[c] += 1.0;
            sa += v;
        } else {
            nb_g[c] += 1.0;
            sb += v;
        }
    }
    let (na, nb): (f64, f64) = (na_g.iter().sum(), nb_g.iter().sum());
    let d = sa / na - sb / nb;
    let a = vc.within * (1.0 / na + 1.0 / nb);
    let b = vc.between
        * na_g
            .iter()
            .zip(&nb_g)
            .map(|(x, y)| (x / na - y / nb).powi(2))
            .sum::<f64>();
    let var = a + b;
    let df_w = (vc.n as f64 - vc.clusters as f64).max(1.0);
    let df_b = (vc.clusters as f64 - 1.0).max(1.0);
    let df = var * var / (a * a / df_w + b * b / df_b);
    if var.is_nan() || var <= 0.0 || !df.is_finite() {
        return (d, (d, d), if d == 0.0 { 1.0 } else { 0.0 });
    }
    let se = var.sqrt();
    let t = StudentsT::new(0.0, 1.0, df).expect("df > 0");
    let p = crate::model::ols::two_sided_p(&t, d / se);
    let q = t.inverse_cdf(0.975);
    (d, (d - q * se, d + q * se), p)
}

/// Benjamini–Hochberg adjusted p-values (step-up, monotone), in input order.
pub fn benjamini_hochberg(p: &[f64]) -> Vec<f64> {
    let m = p.len();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| p[b].total_cmp(&p[a])); // largest first
    let mut adj = vec![0.0; m];
    let mut running = 1.0f64;
    for (rank_from_top, &i) in order.iter().enumerate() {
        let rank = m - rank_from_top; // 1-based rank in ascending order
        running = running.min(p[i] * m as f64 / rank as f64);
        adj[i] = running.min(1.0);
    }
    adj
}

/// The Kaplan–Meier estimate of a distribution from right-censored values:
/// each value is observed, or censored (the true value is at least it).
/// What Buckley–James regression needs of it: the mean of the distribution
/// beyond a censored value, [`KaplanMeier::mean_beyond`].
#[derive(Debug, Clone)]
pub struct KaplanMeier {
    /// The observed values in ascending order and the probability mass the
    /// estimate puts on each; where the largest value is censored, the mass
    /// left beyond it sits on it (Efron's convention: treated as observed).
    atoms: Vec<(f64, f64)>,
}

impl KaplanMeier {
    /// From values and whether each is censored; non-finite values are
    /// left out. Ties: the observed before the censored (a censored value
    /// is still at risk at its own value).
    pub fn new(values: &[f64], censored: &[bool]) -> KaplanMeier {
        let mut v: Vec<(f64, bool)> = values
            .iter()
            .zip(censored)
            .filter(|(x, _)| x.is_finite())
            .map(|(x, c)| (*x, *c))
            .collect();
        v.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut atoms = Vec::new();
        let mut survival = 1.0;
        let n = v.len();
        for (i, &(x, c)) in v.iter().enumerate() {
            let at_risk = (n - i) as f64;
            let last = i + 1 == n;
            if !c || last {
                // Mass S(x−)·(1/at_risk) for an observed value; the whole
                // remaining mass on the largest value.
                let mass = if last { survival } else { survival / at_risk };
                atoms.push((x, mass));
                survival -= mass;
            }
        }
        KaplanMeier { atoms }
    }

    /// E[X | X > c] under the estimate; `c` itself where it puts no mass
    /// beyond `c` (nothing larger was observed).
    pub fn mean_beyond(&self, c: f64) -> f64 {
        let (mut mass, mut moment) = (0.0, 0.0);
        for &(x, m) in self.atoms.iter().filter(|(x, _)| *x > c) {
            mass += m;
            moment += m * x;
        }
        if mass > 0.0 { moment / mass } else { c }
    }
}

/// A normal distribution fitted by maximum likelihood to right-censored
/// values (a Tobit model without covariates): each value is observed, or
/// censored (the true value is at least it). Unlike the Kaplan–Meier
/// estimate it reaches beyond the largest observed value, which is where a
/// heavily worn tire's wear lies when most tires like it wore through.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CensoredNormal {
    pub mean: f64,
    pub sd: f64,
}

/// Most EM iterations of [`CensoredNormal::fit`]; each raises the
/// likelihood, and at 40 % censoring a few hundred reach 1e-12.
const CENSORED_NORMAL_ITERATIONS: usize = 10_000;

impl CensoredNormal {
    /// The maximum-likelihood fit by EM: each censored value replaced by its
    /// conditional first and second moments under the current fit (the
    /// truncated normal's), then the mean and variance of the whole sample
    /// taken again. Non-finite values are left out. None with fewer than two
    /// distinct observed values (the scale is not identified).
    pub fn fit(values: &[f64], censored: &[bool]) -> Option<CensoredNormal> {
        let v: Vec<(f64, bool)> = values
            .iter()
            .zip(censored)
            .filter(|(x, _)| x.is_finite())
            .map(|(x, c)| (*x, *c))
            .collect();
        let observed: Vec<f64> = v.iter().filter(|(_, c)| !c).map(|(x, _)| *x).collect();
        if observed.len() < 2 {
            return None;
        }
        let n = v.len() as f64;
        let m = observed.len() as f64;
        let mut mean = observed.iter().sum::<f64>() / m;
        let mut var = observed.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / m;
        if var <= 0.0 {
            return None;
        }
        for _ in 0..CENSORED_NORMAL_ITERATIONS {
            let sd = var.sqrt();
            let (mut s1, mut s2) = (0.0, 0.0);
            for &(x, c) in &v {
                if c {
                    // X | X > x: mean μ + σλ, second moment μ² + 2μσλ + σ²(1 + aλ).
                    let a = (x - mean) / sd;
                    let l = inverse_mills(a);
                    s1 += mean + sd * l;
                    s2 += mean * mean + 2.0 * mean * sd * l + var * (1.0 + a * l);
                } else {
                    s1 += x;
                    s2 += x * x;
                }
            }
            let next_mean = s1 / n;
            let next_var = (s2 / n - next_mean * next_mean).max(f64::MIN_POSITIVE);
            let settled = (next_mean - mean).abs() <= 1e-12 * (1.0 + mean.abs())
                && (next_var - var).abs() <= 1e-12 * var;
            mean = next_mean;
            var = next_var;
            if settled {
                break;
            }
        }
        Some(CensoredNormal {
            mean,
            sd: var.sqrt(),
        })
    }

    /// E[X | X > c].
    pub fn mean_beyond(&self, c: f64) -> f64 {
        self.mean + self.sd * inverse_mills((c - self.mean) / self.sd)
    }

    /// E[exp X | X > c] = exp(μ + σ²/2)·Φ((μ + σ² − c)/σ) / Φ((μ − c)/σ):
    /// the mean beyond a bound on the log scale, for a log-normal quantity.
    /// exp(c), the bound itself, where c lies so far out that Φ underflows.
    pub fn mean_exp_beyond(&self, c: f64) -> f64 {
        let (m, s) = (self.mean, self.sd);
        let beyond = normal_cdf((m - c) / s);
        let v = (m + s * s / 2.0).exp() * normal_cdf((m + s * s - c) / s) / beyond;
        if beyond > 0.0 && v.is_finite() {
            v.max(c.exp())
        } else {
            c.exp()
        }
    }
}

/// Φ(z), the standard normal distribution function.
fn normal_cdf(z: f64) -> f64 {
    Normal::standard().cdf(z)
}

/// The inverse Mills ratio φ(a) / (1 − Φ(a)); its asymptotic series where
/// both parts underflow.
fn inverse_mills(a: f64) -> f64 {
    if a > 30.0 {
        return a + 1.0 / a - 2.0 / a.powi(3);
    }
    let n = Normal::standard();
    n.pdf(a) / n.sf(a)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nested_components_by_hand() {
        // Two cells of two runs of two tires: runs (1, 3), (5, 7) in one,
        // (11, 13), (15, 17) in the other. Within: 8 / (8 − 4) = 2. Between
        // runs of a cell: 2·(2² + 2² + 2² + 2²) / (4 − 2) = 16, n₀ =
        // (8 − 8/4 − 8/4) / 2 = 2, so (16 − 2) / 2 = 7. Unnested, the cells'
        // shift counts too: run means 2, 6, 12, 16 around 9, MS_b = 232/3,
        // n₀ = (8 − 16/8)/3 = 2, (232/3 − 2)/2 = 37.67.
        let r = [1.0, 3.0, 5.0, 7.0, 11.0, 13.0, 15.0, 17.0];
        let run = [0, 0, 1, 1, 2, 2, 3, 3];
        let cell = [0, 0, 0, 0, 1, 1, 1, 1];
        let nested = VarianceComponents::estimate_nested(&r, &run, &cell);
        assert!((nested.within - 2.0).abs() < 1e-12, "{nested:?}");
        assert!((nested.between - 7.0).abs() < 1e-12, "{nested:?}");
        assert_eq!((nested.clusters, nested.n), (4, 8));
        let plain = VarianceComponents::estimate(&r, &run);
        assert!((plain.between - (232.0 / 3.0 - 2.0) / 2.0).abs() < 1e-12);
        // One cell: the plain estimate (unbalanced runs of 3, 1 and 2).
        let r = [0.3, -1.2, 0.8, 2.5, -0.4, 1.1];
        let run = [0, 0, 0, 1, 2, 2];
        let one = VarianceComponents::estimate_nested(&r, &run, &[0; 6]);
        let plain = VarianceComponents::estimate(&r, &run);
        assert!((one.between - plain.between).abs() < 1e-12);
        assert_eq!(one.within, plain.within);
    }

    #[test]
    fn kaplan_meier_tail_means_by_hand() {
        // 0.1, 0.2+, 0.3, 0.5+, 0.6 (+: censored). S drops at 0.1 by 1/5 to
        // 0.8; at 0.3, three at risk, to 0.8·2/3 = 8/15; at 0.6, one at
        // risk, to 0. Masses 1/5, 4/15, 8/15.
        let km = KaplanMeier::new(
            &[0.3, 0.5, 0.1, 0.6, 0.2, f64::NAN],
            &[false, true, false, false, true, false],
        );
        // Beyond 0.2: (0.3·4/15 + 0.6·8/15)/(12/15) = 0.5.
        assert!((km.mean_beyond(0.2) - 0.5).abs() < 1e-12);
        assert!((km.mean_beyond(0.5) - 0.6).abs() < 1e-12);
        // Beyond everything: the value itself.
        assert_eq!(km.mean_beyond(0.7), 0.7);
        // Below everything: the estimate's mean, 0.1/5 + 0.3·4/15 + 0.6·8/15.
        assert!((km.mean_beyond(-1.0) - (0.02 + 0.08 + 0.32)).abs() < 1e-12);
        // The largest value censored: 0.1, 0.4+ → mass 1/2 each (Efron).
        let km = KaplanMeier::new(&[0.1, 0.4], &[false, true]);
        assert!((km.mean_beyond(0.0) - 0.25).abs() < 1e-12);
        assert!((km.mean_beyond(0.2) - 0.4).abs() < 1e-12);
        // Without censoring: the sample mean of what lies beyond.
        let km = KaplanMeier::new(&[1.0, 2.0, 3.0, 4.0], &[false; 4]);
        assert!((km.mean_beyond(1.5) - 3.0).abs() < 1e-12);
    }

    #[test]
    fn censored_normal_by_hand() {
        // Nothing censored: the sample mean and the population sd, 2.5 and
        // sqrt(1.25), non-finite values left out.
        let fit = CensoredNormal::fit(&[1.0, 2.0, 3.0, 4.0, f64::NAN], &[false; 5]).unwrap();
        assert!((fit.mean - 2.5).abs() < 1e-12 && (fit.sd - 1.25f64.sqrt()).abs() < 1e-12);
        // A censored value below the mean hardly moves it; one far above
        // raises it (its conditional mean lies beyond its bound).
        let low = CensoredNormal::fit(
            &[1.0, 2.0, 3.0, 4.0, -20.0],
            &[false, false, false, false, true],
        );
        let high = CensoredNormal::fit(
            &[1.0, 2.0, 3.0, 4.0, 6.0],
            &[false, false, false, false, true],
        );
        assert!((low.unwrap().mean - 2.5).abs() < 1e-9, "{low:?}");
        assert!(high.unwrap().mean > 6.0 / 5.0 + 2.0, "{high:?}");
        // Not identified: fewer than two observed values, or all equal.
        assert_eq!(CensoredNormal::fit(&[1.0, 2.0], &[false, true]), None);
        assert_eq!(
            CensoredNormal::fit(&[1.0, 1.0, 2.0], &[false, false, true]),
            None
        );
        // The tail means: at c = −∞ the distribution's means, E[e^X] =
        // exp(μ + σ²/2); far beyond, the bound itself.
        let d = CensoredNormal { mean: 0.1, sd: 0.3 };
        assert!((d.mean_beyond(f64::NEG_INFINITY) - 0.1).abs() < 1e-12);
        assert!((d.mean_exp_beyond(-1e3) - (0.1f64 + 0.045).exp()).abs() < 1e-12);
        assert_eq!(d.mean_exp_beyond(100.0), 100f64.exp());
        // 30 sd out, E[e^(X−c) | X > c] ≈ 1/(1 − σ²/(c − μ)) = 1.0101.
        let c = 0.1 + 0.3 * 30.0;
        let far = d.mean_exp_beyond(c) / c.exp();
        assert!((far - 1.0101).abs() < 5e-4, "{far}");
    }

    #[test]
    fn clustered_difference_by_hand() {
        // Two events of 4 residuals: event 0 = [1, 3, 1, 3], event 1 = [−1, 1, −1, 1].
        // Means 2 and 0, grand 1; SSW = 4 + 4 = 8 on 6 df → σ_w² = 4/3;
        // MSB = 4·1 + 4·1 = 8 on 1 df, n0 = (8 − 32/8)/1 = 4 → σ_e² = (8 − 4/3)/4 = 5/3.
        let r = [1.0, 3.0, 1.0, 3.0, -1.0, 1.0, -1.0, 1.0];
        let cl = [0, 0, 0, 0, 1, 1, 1, 1];
        let vc = VarianceComponents::estimate(&r, &cl);
        assert!((vc.within - 4.0 / 3.0).abs() < 1e-12 && (vc.between - 5.0 / 3.0).abs() < 1e-12);
        // Slice = event 0: d = 2, var = σ_w²(1/4 + 1/4) + σ_e²(1 + 1) = 2/3 + 10/3 = 4.
        let event0 = [true, true, true, true, false, false, false, false];
        let (d, ci, _) = clustered_difference(&event0, &r, &cl, &vc);
        let (a, b) = (2.0f64 / 3.0, 10.0f64 / 3.0);
        let df = 16.0 / (a * a / 6.0 + b * b / 1.0);
        let q = StudentsT::new(0.0, 1.0, df).unwrap().inverse_cdf(0.975);
        assert!(
            (d - 2.0).abs() < 1e-12 && (ci.1 - d - 2.0 * q).abs() < 1e-9,
            "{ci:?}"
        );
        // Slice = the second and fourth tire of each event: balanced over the
        // events, so no event variance: d = 2, var = σ_w²(1/4 + 1/4) = 2/3,
        // df = N − G = 6; t = 2/sqrt(2/3).
        let inside = [false, true, false, true, false, true, false, true];
        let (d, ci, p) = clustered_difference(&inside, &r, &cl, &vc);
        let se = (2.0f64 / 3.0).sqrt();
        let t = StudentsT::new(0.0, 1.0, 6.0).unwrap();
        assert!((d - 2.0).abs() < 1e-12);
        assert!((p - 2.0 * (1.0 - t.cdf(2.0 / se))).abs() < 1e-12);
        assert!((ci.1 - (2.0 + t.inverse_cdf(0.975) * se)).abs() < 1e-12);
    }
}
