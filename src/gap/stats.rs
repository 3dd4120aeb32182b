//! Small statistics of the gap diagnosis: Welch's two-sample t-test with its
//! confidence interval, and Benjamini–Hochberg false-discovery control.

use statrs::distribution::{ContinuousCDF, StudentsT};

/// Welch's test of mean(a) − mean(b): (difference, 95 % CI, two-sided p).
pub fn welch(a: &[f64], b: &[f64]) -> (f64, (f64, f64), f64) {
    let mv = |x: &[f64]| {
        let n = x.len() as f64;
        let m = x.iter().sum::<f64>() / n;
        (
            m,
            x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0),
            n,
        )
    };
    let ((ma, va, na), (mb, vb, nb)) = (mv(a), mv(b));
    let (sa, sb) = (va / na, vb / nb);
    let se = (sa + sb).sqrt();
    let df = (sa + sb).powi(2) / (sa * sa / (na - 1.0) + sb * sb / (nb - 1.0));
    let d = ma - mb;
    if se.is_nan() || se <= 0.0 || !df.is_finite() {
        return (d, (d, d), if d == 0.0 { 1.0 } else { 0.0 });
    }
    let t = StudentsT::new(0.0, 1.0, df).expect("df > 0");
    let p = 2.0 * (1.0 - t.cdf((d / se).abs()));
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
