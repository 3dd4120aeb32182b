//! The physics baseline of the gap ("the simulation"): the frictional-energy
//! wear law, wear = k_c · E · exp(β·(T_surf − 60 °C)), with a coefficient k_c
//! per compound and one temperature sensitivity β standing for the rubber's
//! viscoelastic temperature factor (a WLF shift is close to log-linear over a
//! race tire's working range), calibrated on the training events by least
//! squares (β on a grid, k_c in closed form for each β).

use crate::kpi::KpiRow;
use std::collections::BTreeMap;

/// Temperature of the law's reference state (°C).
pub const REFERENCE_C: f64 = 60.0;

/// A calibrated baseline.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PhysicsBaseline {
    /// % of tread per MJ of friction energy at the reference temperature, per compound.
    pub k_pct_per_mj: BTreeMap<String, f64>,
    /// β (1/K).
    pub beta_per_k: f64,
}

fn term(r: &KpiRow, beta: f64) -> f64 {
    r.friction_energy_j / 1e6 * (beta * (r.t_surface_avg_c - REFERENCE_C)).exp()
}

impl PhysicsBaseline {
    /// Calibrates on rows with finite wear, energy and temperature.
    pub fn fit(rows: &[&KpiRow]) -> PhysicsBaseline {
        let ok: Vec<&&KpiRow> = rows
            .iter()
            .filter(|r| {
                r.wear_mean_pct.is_finite()
                    && r.friction_energy_j.is_finite()
                    && r.t_surface_avg_c.is_finite()
            })
            .collect();
        let fit_for = |beta: f64| -> (f64, BTreeMap<String, f64>) {
            let mut sums: BTreeMap<String, (f64, f64)> = BTreeMap::new();
            for r in &ok {
                let x = term(r, beta);
                let s = sums.entry(r.compound.clone()).or_default();
                s.0 += x * r.wear_mean_pct;
                s.1 += x * x;
            }
            let k: BTreeMap<String, f64> =
                sums.into_iter().map(|(c, (xy, xx))| (c, xy / xx)).collect();
            let sse = ok
                .iter()
                .map(|r| (r.wear_mean_pct - k[&r.compound] * term(r, beta)).powi(2))
                .sum();
            (sse, k)
        };
        let mut best = (f64::INFINITY, BTreeMap::new(), 0.0);
        for i in 0..=200 {
            let beta = -0.05 + 0.001 * i as f64;
            let (sse, k) = fit_for(beta);
            if sse < best.0 {
                best = (sse, k, beta);
            }
        }
        PhysicsBaseline {
            k_pct_per_mj: best.1,
            beta_per_k: best.2,
        }
    }

    /// Predicted mean wear (%); NaN for a compound not seen in calibration.
    pub fn predict(&self, r: &KpiRow) -> f64 {
        self.k_pct_per_mj
            .get(&r.compound)
            .map_or(f64::NAN, |k| k * term(r, self.beta_per_k))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_planted_law() {
        // wear = k_c·E·exp(0.03(T − 60)), k = 1.5 (soft), 0.8 (hard): exact recovery.
        let rows: Vec<KpiRow> = (0..40)
            .map(|i| {
                let (c, k) = if i % 2 == 0 {
                    ("soft", 1.5)
                } else {
                    ("hard", 0.8)
                };
                let e = 5.0 + i as f64;
                let t = 50.0 + (i % 7) as f64 * 6.0;
                KpiRow {
                    compound: c.into(),
                    friction_energy_j: e * 1e6,
                    t_surface_avg_c: t,
                    wear_mean_pct: k * e * (0.03 * (t - 60.0)).exp(),
                    ..Default::default()
                }
            })
            .collect();
        let refs: Vec<&KpiRow> = rows.iter().collect();
        let b = PhysicsBaseline::fit(&refs);
        assert!((b.beta_per_k - 0.03).abs() < 1e-9);
        assert!((b.k_pct_per_mj["soft"] - 1.5).abs() < 1e-9);
        assert!((b.k_pct_per_mj["hard"] - 0.8).abs() < 1e-9);
    }
}
