//! Physical correlations + regression (paper section 4.3), per axle: a line
//! of wear against total friction energy for each track with two
//! reliability indexes, the per-track slopes against surface temperature,
//! the residuals of the pooled energy–temperature law against road skewness,
//! and OLS on the six inputs of table 10. Definitions: docs/models.md.

use super::ols::{OlsFit, OlsSettings};
use super::{Dataset, Fit, ModelError, data::correlation, metrics::median};
use crate::Axle;
use crate::kpi::KpiRow;

/// Table 10: skewness Sk, kurtosis Ku, T_Surf Avg, FP_TOT, CP_Area, tan δ(T*).
pub(crate) const PHYSICAL_INPUTS: [&str; 6] = [
    "skewness",
    "kurtosis",
    "t_surface_avg_c",
    "friction_energy_j",
    "contact_patch_mm2",
    "loss_factor",
];

/// Tracks whose R2 is below this are left out of the slope correlation
/// (the paper: R2 "is used to remove circuits with a lower number of acquisitions").
pub(crate) const MIN_R2_CONSISTENT: f64 = 0.5;

/// One track's line `wear = a + b·E` (E in MJ) with its reliability indexes.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrackLine {
    pub track: String,
    pub n: usize,
    #[serde(deserialize_with = "super::nullable::f64_or_nan")]
    pub intercept_pct: f64,
    /// b, in % of tread per MJ of friction energy.
    #[serde(deserialize_with = "super::nullable::f64_or_nan")]
    pub slope_pct_per_mj: f64,
    /// R1 = 1 − RMSE/(max wear − min wear): the range-normalised RMSE
    /// turned into a score (1 = every point on the line).
    #[serde(deserialize_with = "super::nullable::f64_or_nan")]
    pub r1: f64,
    /// R2 = consistent points / the most consistent points of any track.
    #[serde(deserialize_with = "super::nullable::f64_or_nan")]
    pub r2: f64,
    /// Points within 3 robust standard deviations (1.4826·MAD) of the line.
    pub n_consistent: usize,
    #[serde(deserialize_with = "super::nullable::f64_or_nan")]
    pub t_surface_avg_c: f64,
    #[serde(deserialize_with = "super::nullable::f64_or_nan")]
    pub skewness: f64,
}

/// The preliminary analysis of one axle and its regression on table 10.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AxleAnalysis {
    pub axle: Axle,
    pub lines: Vec<TrackLine>,
    /// Pearson correlation of per-track slopes with mean surface temperature,
    /// weighted by R1, over tracks with R2 ≥ 0.5 (figure 13); NaN (`null`
    /// in the file) with fewer than two such tracks or no spread.
    #[serde(deserialize_with = "super::nullable::f64_or_nan")]
    pub slope_vs_t_surface: f64,
    /// Residuals of `wear = a + b·E + c·E·T_surf` against skewness (figure
    /// 14); NaN (`null`) where either has no spread.
    #[serde(deserialize_with = "super::nullable::f64_or_nan")]
    pub residual_vs_skewness: f64,
    pub regression: OlsFit,
}

/// Least-squares line y = a + b x.
fn line(x: &[f64], y: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx).powi(2)).sum();
    let b = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    (my - b * mx, b)
}

/// Weighted Pearson correlation.
pub(crate) fn weighted_correlation(x: &[f64], y: &[f64], w: &[f64]) -> f64 {
    let sw: f64 = w.iter().sum();
    let mx = x.iter().zip(w).map(|(a, w)| a * w).sum::<f64>() / sw;
    let my = y.iter().zip(w).map(|(a, w)| a * w).sum::<f64>() / sw;
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for ((a, b), w) in x.iter().zip(y).zip(w) {
        sxy += w * (a - mx) * (b - my);
        sxx += w * (a - mx).powi(2);
        syy += w * (b - my).powi(2);
    }
    sxy / (sxx * syy).sqrt()
}

/// Per-track lines of wear against friction energy, with R1 and R2.
pub(crate) fn track_lines(rows: &[&KpiRow]) -> Vec<TrackLine> {
    let mut tracks: Vec<&str> = rows.iter().map(|r| r.track.as_str()).collect();
    tracks.sort();
    tracks.dedup();
    let mut lines: Vec<TrackLine> = tracks
        .into_iter()
        .map(|track| {
            let sub: Vec<&&KpiRow> = rows.iter().filter(|r| r.track == track).collect();
            let e: Vec<f64> = sub.iter().map(|r| r.friction_energy_j / 1e6).collect();
            let w: Vec<f64> = sub.iter().map(|r| r.wear_mean_pct).collect();
            let (a, b) = line(&e, &w);
            let res: Vec<f64> = e.iter().zip(&w).map(|(x, y)| y - a - b * x).collect();
            let rmse = (res.iter().map(|r| r * r).sum::<f64>() / res.len() as f64).sqrt();
            let range = w.iter().cloned().fold(f64::MIN, f64::max)
                - w.iter().cloned().fold(f64::MAX, f64::min);
            let mad = 1.4826 * median(res.iter().map(|r| r.abs()).collect());
            let n_consistent = res
                .iter()
                .filter(|r| mad == 0.0 || r.abs() <= 3.0 * mad)
                .count();
            let mean =
                |f: fn(&KpiRow) -> f64| sub.iter().map(|r| f(r)).sum::<f64>() / sub.len() as f64;
            TrackLine {
                track: track.to_string(),
                n: sub.len(),
                intercept_pct: a,
                slope_pct_per_mj: b,
                r1: if range > 0.0 { 1.0 - rmse / range } else { 0.0 },
                r2: 0.0,
                n_consistent,
                t_surface_avg_c: mean(|r| r.t_surface_avg_c),
                skewness: mean(|r| r.skewness),
            }
        })
        .collect();
    let most = lines
        .iter()
        .map(|l| l.n_consistent)
        .max()
        .unwrap_or(1)
        .max(1);
    for l in &mut lines {
        l.r2 = l.n_consistent as f64 / most as f64;
    }
    lines
}

/// Inputs of table 10 of one row.
pub(crate) fn inputs_of(r: &KpiRow) -> Vec<f64> {
    PHYSICAL_INPUTS
        .iter()
        .map(|c| r.number(c).expect("table-10 column"))
        .collect()
}

/// The whole analysis of one axle's training rows.
pub(crate) fn analyse_axle(axle: Axle, rows: &[&KpiRow]) -> Result<AxleAnalysis, ModelError> {
    let lines = track_lines(rows);
    let reliable: Vec<&TrackLine> = lines
        .iter()
        .filter(|l| l.r2 >= MIN_R2_CONSISTENT && l.n >= 3)
        .collect();
    let slope_vs_t_surface = weighted_correlation(
        &reliable
            .iter()
            .map(|l| l.slope_pct_per_mj)
            .collect::<Vec<_>>(),
        &reliable
            .iter()
            .map(|l| l.t_surface_avg_c)
            .collect::<Vec<_>>(),
        &reliable.iter().map(|l| l.r1.max(0.0)).collect::<Vec<_>>(),
    );
    // The slope rises with temperature: a pooled law with an E·T term, whose
    // residuals are then held against the road (figure 14).
    let pooled: Vec<Vec<f64>> = rows
        .iter()
        .map(|r| {
            let e = r.friction_energy_j / 1e6;
            vec![e, e * r.t_surface_avg_c]
        })
        .collect();
    let y: Vec<f64> = rows.iter().map(|r| r.wear_mean_pct).collect();
    let law_inputs = ["energy_mj".to_string(), "energy_x_t_surface".to_string()];
    let law = OlsSettings.fit(Dataset::new(&pooled, &y, &law_inputs))?;
    let residuals: Vec<f64> = law
        .predict(&pooled)
        .iter()
        .zip(&y)
        .map(|(p, y)| y - p)
        .collect();
    let skew: Vec<f64> = rows.iter().map(|r| r.skewness).collect();
    let x: Vec<Vec<f64>> = rows.iter().map(|r| inputs_of(r)).collect();
    let names: Vec<String> = PHYSICAL_INPUTS.iter().map(|s| s.to_string()).collect();
    Ok(AxleAnalysis {
        axle,
        lines,
        slope_vs_t_surface,
        residual_vs_skewness: correlation(&residuals, &skew),
        regression: OlsSettings.fit(Dataset::new(&x, &y, &names))?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(track: &str, e_mj: f64, wear: f64) -> KpiRow {
        KpiRow {
            track: track.into(),
            friction_energy_j: e_mj * 1e6,
            wear_mean_pct: wear,
            t_surface_avg_c: 70.0,
            ..Default::default()
        }
    }

    #[test]
    fn reliability_indexes_by_hand() {
        // Track A: wear = 2 + 3E exactly on 4 points → R1 = 1, 4 consistent.
        // Track B: points (0,0) (1,1) (2,0) (3,1): line 0.2 + 0.2E, residuals
        // (−0.2, 0.6, −0.6, 0.2), RMSE = √0.2, range 1 → R1 = 1 − √0.2;
        // MAD = 1.4826·0.4 = 0.593, 3·MAD = 1.78 → all 4 consistent.
        // Track C: 2 points → 2 consistent, R2 = 2/4.
        let rows = [
            row("A", 0.0, 2.0),
            row("A", 1.0, 5.0),
            row("A", 2.0, 8.0),
            row("A", 3.0, 11.0),
            row("B", 0.0, 0.0),
            row("B", 1.0, 1.0),
            row("B", 2.0, 0.0),
            row("B", 3.0, 1.0),
            row("C", 1.0, 1.0),
            row("C", 2.0, 3.0),
        ];
        let refs: Vec<&KpiRow> = rows.iter().collect();
        let l = track_lines(&refs);
        assert!(
            (l[0].slope_pct_per_mj - 3.0).abs() < 1e-12 && (l[0].intercept_pct - 2.0).abs() < 1e-12
        );
        assert!((l[0].r1 - 1.0).abs() < 1e-12 && l[0].r2 == 1.0);
        assert!((l[1].slope_pct_per_mj - 0.2).abs() < 1e-12);
        assert!((l[1].r1 - (1.0 - 0.2f64.sqrt())).abs() < 1e-12);
        assert_eq!(l[1].n_consistent, 4);
        assert_eq!(l[2].r2, 0.5);
    }

    #[test]
    fn weighted_correlation_with_equal_weights_is_pearson() {
        let x = [1.0, 2.0, 3.0, 5.0];
        let y = [2.0, 1.0, 4.0, 3.0];
        let w = [0.7; 4];
        assert!((weighted_correlation(&x, &y, &w) - correlation(&x, &y)).abs() < 1e-12);
        // A zero weight removes a point.
        let c3 = correlation(&x[..3], &y[..3]);
        assert!((weighted_correlation(&x, &y, &[1.0, 1.0, 1.0, 0.0]) - c3).abs() < 1e-12);
    }
}
