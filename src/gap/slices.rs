//! Step 1 of the diagnosis, where the gap lies: the residual (measured −
//! baseline) sliced by the categorical columns, by predicted wear and by the
//! quartile bands of every KPI, singly and in pairs. Each slice is tested
//! against the rest allowing for the residuals' correlation within events (a
//! random intercept per event: all tires of an event share its track, day
//! and conditions), so a handful of events cannot make many overlapping
//! slices look significant; Benjamini–Hochberg controls the false
//! discovery rate over all distinct slices tested (slices with the same rows
//! are one test under several names); survivors are ranked by the part of the
//! total squared gap their offset accounts for, n·mean²/Σr².

use super::stats::{VarianceComponents, benjamini_hochberg, clustered_difference, levels};
use crate::kpi::KpiRow;
use crate::model::data::candidate_inputs;

/// Smallest slice tested.
pub(crate) const MIN_SLICE: usize = 10;

/// One slice of the residuals.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Slice {
    /// e.g. "axle = front", "t_surface_avg_c in Q4 [82.1, 96.0]" (edges:
    /// `band_edges`), "axle = front & track = x".
    pub name: String,
    pub n: usize,
    /// Mean residual in the slice (% of tread).
    pub mean_residual_pct: f64,
    /// Slice mean minus the rest's mean, with its 95 % confidence interval.
    pub difference_pct: f64,
    pub ci_pct: (f64, f64),
    /// Difference over the standard deviation of all residuals.
    pub effect_size: f64,
    pub p: f64,
    /// Benjamini–Hochberg adjusted p-value over every slice tested.
    pub p_adjusted: f64,
    /// Σ residual² in the slice / Σ residual² overall.
    pub share_of_squared_gap: f64,
    /// n·(mean residual)² / Σ residual² overall: the part of the squared gap
    /// the slice's offset accounts for (what correcting it would remove). Ranks slices.
    pub explained_share: f64,
    /// Other names of the same rows (e.g. road indices constant per track).
    pub aliases: Vec<String>,
    /// Which of the rows tested are in the slice (steps 2 and 3 measure the
    /// gap inside it).
    #[serde(skip)]
    pub members: Vec<bool>,
}

/// A named row predicate: (variable, level name, members as a [`packed`]
/// mask).
struct Single {
    variable: String,
    name: String,
    members: Vec<u64>,
}

/// Name of the predicted wear's bands (measured − residual). Slicing by
/// the *measured* wear would flag noise: with any model, cov(residual,
/// measured) = var(noise), so the top band of measured wear has a positive
/// mean residual even when the model is right.
pub(crate) const PREDICTED_WEAR: &str = "predicted_wear_pct";

fn singles(rows: &[&KpiRow], residual: &[f64]) -> Vec<Single> {
    let mut out = Vec::new();
    type Getter = fn(&KpiRow) -> &str;
    let text: [(&str, Getter); 6] = [
        ("axle", |r| r.axle.name()),
        ("wheel", |r| r.wheel.name()),
        ("track", |r| &r.track),
        ("event", |r| &r.event),
        ("compound", |r| &r.compound),
        ("car", |r| &r.car),
    ];
    for (var, get) in text {
        let mut levels: Vec<&str> = rows.iter().map(|r| get(r)).collect();
        levels.sort();
        levels.dedup();
        for l in levels {
            out.push(Single {
                variable: var.into(),
                name: format!("{var} = {l}"),
                members: packed(&rows.iter().map(|r| get(r) == l).collect::<Vec<_>>()),
            });
        }
    }
    let predicted: Vec<f64> = rows
        .iter()
        .zip(residual)
        .map(|(r, e)| r.wear_mean_pct - e)
        .collect();
    let numeric = std::iter::once(PREDICTED_WEAR).chain(
        candidate_inputs()
            .into_iter()
            .filter(|c| *c != "wear_mean_pct"),
    );
    for col in numeric {
        let v: Vec<f64> = if col == PREDICTED_WEAR {
            predicted.clone()
        } else {
            rows.iter()
                .map(|r| r.number(col).unwrap_or(f64::NAN))
                .collect()
        };
        let mut sorted: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
        sorted.sort_by(f64::total_cmp);
        if sorted.len() < 2 * MIN_SLICE || sorted[0] == sorted[sorted.len() - 1] {
            continue;
        }
        let q = |f: f64| sorted[((sorted.len() - 1) as f64 * f).round() as usize];
        let edges = [
            sorted[0],
            q(0.25),
            q(0.5),
            q(0.75),
            sorted[sorted.len() - 1],
        ];
        let shown = band_edges(&edges);
        for b in 0..4 {
            let (lo, hi) = (edges[b], edges[b + 1]);
            let members: Vec<bool> = v
                .iter()
                .map(|&x| x.is_finite() && x >= lo && (x < hi || (b == 3 && x <= hi)))
                .collect();
            out.push(Single {
                variable: col.into(),
                name: format!("{col} in Q{} [{}, {}]", b + 1, shown[b], shown[b + 1]),
                members: packed(&members),
            });
        }
    }
    out
}

/// A KPI's band edges as the slice names show them, in the column's unit:
/// three significant digits of the column's range (a pressure spanning
/// 26 kPa in whole pascals, a temperature in tenths of a degree, a slip
/// in ten-thousandths), more where two different edges would read alike.
/// The names are labels only: a slice's rows are its member mask.
fn band_edges(edges: &[f64; 5]) -> [String; 5] {
    let span = edges[4] - edges[0];
    let from_range = 3i32.saturating_sub(span.log10().ceil() as i32);
    let mut decimals = from_range.clamp(0, 9) as usize;
    loop {
        let shown = edges.map(|x| format!("{x:.decimals$}"));
        let alike = edges
            .windows(2)
            .zip(shown.windows(2))
            .any(|(v, t)| v[0] != v[1] && t[0] == t[1]);
        if !alike || decimals >= 9 {
            return shown;
        }
        decimals += 1;
    }
}

/// A row mask packed 64 rows to a word, row `i` at bit `i % 64` of word
/// `i / 64`.
fn packed(members: &[bool]) -> Vec<u64> {
    members
        .chunks(64)
        .map(|c| {
            c.iter()
                .enumerate()
                .fold(0, |w, (i, &m)| w | (u64::from(m) << i))
        })
        .collect()
}

/// The first `n` rows of a [`packed`] mask.
fn unpacked(bits: &[u64], n: usize) -> Vec<bool> {
    (0..n).map(|i| bits[i / 64] >> (i % 64) & 1 == 1).collect()
}

/// The residuals, their events and the events' variance components.
struct Residuals<'a> {
    r: &'a [f64],
    event: Vec<usize>,
    vc: VarianceComponents,
    sd: f64,
    total_sq: f64,
}

fn test(name: String, members: &[bool], res: &Residuals) -> Option<Slice> {
    let inside: Vec<f64> = members
        .iter()
        .zip(res.r)
        .filter(|(m, _)| **m)
        .map(|(_, r)| *r)
        .collect();
    if inside.len() < MIN_SLICE || res.r.len() - inside.len() < MIN_SLICE {
        return None;
    }
    let (d, ci, p) = clustered_difference(members, res.r, &res.event, &res.vc);
    let (sd, total_sq) = (res.sd, res.total_sq);
    let mean = inside.iter().sum::<f64>() / inside.len() as f64;
    Some(Slice {
        name,
        n: inside.len(),
        mean_residual_pct: mean,
        explained_share: inside.len() as f64 * mean * mean / total_sq,
        aliases: Vec::new(),
        difference_pct: d,
        ci_pct: ci,
        effect_size: d / sd,
        p,
        p_adjusted: f64::NAN,
        share_of_squared_gap: inside.iter().map(|r| r * r).sum::<f64>() / total_sq,
        members: members.to_vec(),
    })
}

/// Every slice tested, with BH-adjusted p-values; those with p_adjusted ≤
/// `fdr` first, by the squared gap their offset accounts for, then the rest by p.
pub(crate) fn slice_residuals(rows: &[&KpiRow], residual: &[f64], fdr: f64) -> (Vec<Slice>, usize) {
    let n = residual.len() as f64;
    let mean = residual.iter().sum::<f64>() / n;
    let sd = (residual.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let total_sq: f64 = residual.iter().map(|r| r * r).sum();
    let (_, event) = levels(rows.iter().map(|r| r.event.as_str()));
    let vc = VarianceComponents::estimate(residual, &event);
    let res = Residuals {
        r: residual,
        event,
        vc,
        sd,
        total_sq,
    };
    // Slices with the same rows are one test under several names; the rows
    // are keyed packed 64 to a word (hashing a bool per row cost 0.8 % of a
    // one-thread diagnosis), and a slice too small or too large for `test`
    // is passed over by its count before its mask is built.
    let n_rows = residual.len();
    let mut seen: std::collections::HashMap<Vec<u64>, usize> = std::collections::HashMap::new();
    let mut tested: Vec<Slice> = Vec::new();
    let mut add = |name: String, bits: Vec<u64>, tested: &mut Vec<Slice>| {
        let count = bits.iter().map(|w| w.count_ones() as usize).sum::<usize>();
        if count < MIN_SLICE || n_rows - count < MIN_SLICE {
            return;
        }
        if let Some(&i) = seen.get(&bits) {
            tested[i].aliases.push(name);
        } else if let Some(t) = test(name, &unpacked(&bits, n_rows), &res) {
            seen.insert(bits, tested.len());
            tested.push(t);
        }
    };
    let s = singles(rows, residual);
    for a in &s {
        add(a.name.clone(), a.members.clone(), &mut tested);
    }
    for (i, a) in s.iter().enumerate() {
        for b in &s[i + 1..] {
            if a.variable != b.variable {
                let both = a.members.iter().zip(&b.members).map(|(x, y)| x & y);
                add(
                    format!("{} & {}", a.name, b.name),
                    both.collect(),
                    &mut tested,
                );
            }
        }
    }
    let adj = benjamini_hochberg(&tested.iter().map(|t| t.p).collect::<Vec<_>>());
    for (t, a) in tested.iter_mut().zip(adj) {
        t.p_adjusted = a;
    }
    let count = tested.len();
    tested.sort_by(|a, b| {
        let (sa, sb) = (a.p_adjusted <= fdr, b.p_adjusted <= fdr);
        sb.cmp(&sa).then(if sa {
            b.explained_share.total_cmp(&a.explained_share)
        } else {
            a.p.total_cmp(&b.p)
        })
    });
    (tested, count)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// Packing keeps every row and its place, across word boundaries and
    /// a last word only partly used; the words read by hand.
    #[test]
    fn packed_masks_keep_each_row() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        for n in [1usize, 63, 64, 65, 130, 316] {
            let m: Vec<bool> = (0..n)
                .map(|_| rand::Rng::random_bool(&mut rng, 0.4))
                .collect();
            let bits = packed(&m);
            assert_eq!(bits.len(), n.div_ceil(64));
            assert_eq!(unpacked(&bits, n), m);
        }
        let mut m = vec![false; 70];
        (m[0], m[63], m[64], m[69]) = (true, true, true, true);
        assert_eq!(packed(&m), vec![1 | 1 << 63, 1 | 1 << 5]);
    }

    /// Edges to three significant digits of the range, more only where
    /// two different edges would print alike (values worked by hand).
    #[test]
    fn band_edges_read_in_the_columns_unit() {
        // A pressure over 26 224 Pa: ⌈log10⌉ = 5, so whole pascals.
        let p = band_edges(&[104505.968, 118315.1958, 123812.9825, 130729.8106, 131002.4]);
        assert_eq!(p, ["104506", "118315", "123813", "130730", "131002"]);
        // 130729.8 and 130730.3 differ but read alike in whole pascals: one
        // decimal more for all five.
        let p = band_edges(&[104505.968, 118315.1958, 123812.9825, 130729.8, 130730.3]);
        assert_eq!(
            p,
            ["104506.0", "118315.2", "123813.0", "130729.8", "130730.3"]
        );
        // A temperature over 14 K: tenths (⌈log10 14⌉ = 2).
        assert_eq!(
            band_edges(&[82.14, 85.0, 88.25, 91.0, 96.0]),
            ["82.1", "85.0", "88.2", "91.0", "96.0"]
        );
        // A slip ratio over 0.04: ten-thousandths (⌈log10 0.04⌉ = −1).
        assert_eq!(
            band_edges(&[0.01234, 0.02, 0.031, 0.04, 0.05]),
            ["0.0123", "0.0200", "0.0310", "0.0400", "0.0500"]
        );
    }

    /// A right model with noise: measured = predicted + e. Banding by the
    /// measured wear puts the large e in its top band (cov(e, y) = var(e));
    /// banding by the prediction does not.
    #[test]
    fn noise_alone_flags_no_band_of_predicted_wear() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let noise = Normal::new(0.0, 1.0).unwrap();
        let n = 400;
        let mut rows = Vec::new();
        let mut residual = Vec::new();
        for i in 0..n {
            let predicted = 10.0 + 5.0 * (i as f64 / n as f64);
            let e = noise.sample(&mut rng);
            residual.push(e);
            rows.push(KpiRow {
                event: format!("E{}", i % 40),
                wear_mean_pct: predicted + e,
                ..KpiRow::default()
            });
        }
        let refs: Vec<&KpiRow> = rows.iter().collect();
        let s = singles(&refs, &residual);
        let band = |name: &str| s.iter().find(|x| x.name.starts_with(name)).unwrap();
        let top = unpacked(&band("predicted_wear_pct in Q4").members, n);
        let mean_in = |m: &[bool]| {
            let v: Vec<f64> = m
                .iter()
                .zip(&residual)
                .filter(|(k, _)| **k)
                .map(|(_, r)| *r)
                .collect();
            v.iter().sum::<f64>() / v.len() as f64
        };
        assert!(mean_in(&top).abs() < 0.25, "{}", mean_in(&top));
        // The measured wear's top band, for contrast: its mean residual is
        // var(e)/sd(y)·E[z | z > 0.67] ≈ 0.5 here.
        let measured: Vec<f64> = rows.iter().map(|r| r.wear_mean_pct).collect();
        let mut sorted = measured.clone();
        sorted.sort_by(f64::total_cmp);
        let q75 = sorted[(n as f64 * 0.75) as usize];
        let top_measured: Vec<bool> = measured.iter().map(|&y| y >= q75).collect();
        assert!(mean_in(&top_measured) > 0.4, "{}", mean_in(&top_measured));
        // And the whole step flags nothing.
        let (tested, _) = slice_residuals(&refs, &residual, 0.05);
        assert!(
            tested.iter().all(|t| t.p_adjusted > 0.05),
            "{:?}",
            tested.first().map(|t| &t.name)
        );
    }
}
