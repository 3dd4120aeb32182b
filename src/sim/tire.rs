//! Tire force model: a normalised Magic Formula `F = μ Fz sin(C atan(Bσ −
//! E(Bσ − atan Bσ)))` in the combined slip magnitude σ, inverted through a
//! lookup table to get the slip that produces a demanded force. Peak friction
//! μ depends on compound, surface temperature, load and road.

use std::sync::OnceLock;

const B: f64 = 17.0;
const C: f64 = 1.6;
const E: f64 = 0.3;
/// Largest normalised force handled on the rising branch; demands above it slide past the peak.
pub(crate) const U_MAX: f64 = 0.995;
const TABLE_N: usize = 2048;

/// Normalised force F/(μ Fz) at combined slip σ.
pub(crate) fn magic_formula(sigma: f64) -> f64 {
    let bs = B * sigma;
    (C * (bs - E * (bs - bs.atan())).atan()).sin()
}

/// Slip σ at the force peak (solves C·atan(...) = π/2 by bisection once).
pub(crate) fn sigma_peak() -> f64 {
    static PEAK: OnceLock<f64> = OnceLock::new();
    *PEAK.get_or_init(|| {
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            let bs = B * mid;
            if C * (bs - E * (bs - bs.atan())).atan() < std::f64::consts::FRAC_PI_2 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    })
}

/// σ(u) on an even grid of u in [0, U_MAX] (rising branch).
fn inverse_table() -> &'static [f64] {
    static TABLE: OnceLock<Vec<f64>> = OnceLock::new();
    TABLE.get_or_init(|| {
        let peak = sigma_peak();
        (0..=TABLE_N)
            .map(|i| {
                let u = U_MAX * i as f64 / TABLE_N as f64;
                let (mut lo, mut hi) = (0.0, peak);
                for _ in 0..60 {
                    let mid = 0.5 * (lo + hi);
                    if magic_formula(mid) < u {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                0.5 * (lo + hi)
            })
            .collect()
    })
}

/// Combined slip σ that produces the normalised force `u` = F/(μ Fz) ≥ 0.
/// Above [`U_MAX`] the tire is past its peak: σ grows steeply (sliding).
pub(crate) fn slip_for_force(u: f64) -> f64 {
    let t = inverse_table();
    if u >= U_MAX {
        return t[TABLE_N] * (1.0 + 4.0 * (u - U_MAX));
    }
    let x = u.max(0.0) / U_MAX * TABLE_N as f64;
    let i = (x as usize).min(TABLE_N - 1);
    let w = x - i as f64;
    t[i] * (1.0 - w) + t[i + 1] * w
}

/// Peak-friction model of a compound.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct GripParams {
    /// Peak friction at the optimum temperature and nominal load.
    pub mu_peak: f64,
    /// Surface temperature of best grip (°C).
    pub t_opt_c: f64,
    /// Half-width of the temperature window (°C): grip drops by 15 % at ±this.
    pub window_c: f64,
}

/// Nominal load of the load-sensitivity law (N).
pub(crate) const FZ_NOMINAL: f64 = 4000.0;

impl GripParams {
    /// Peak friction μ at surface temperature `t_c`, load `fz`, on a road of grip factor `road`.
    pub(crate) fn mu(&self, t_c: f64, fz: f64, road: f64) -> f64 {
        let dt = (t_c - self.t_opt_c) / self.window_c;
        let temp = (1.0 - 0.15 * dt * dt).max(0.8);
        let load = 1.0 - 0.1 * (fz / FZ_NOMINAL - 1.0);
        self.mu_peak * temp * load * road
    }
}

/// Slip of one wheel for demanded forces: `(s_x, s_y)` with the paper's
/// definitions `s_x = (v_x − ΩR)/v_x` (eq. 19), `s_y = v_y/v_x` (eq. 20).
/// The friction force opposes sliding, so `s` points against the force.
pub(crate) fn slips(fx: f64, fy: f64, fz: f64, mu: f64) -> (f64, f64, bool) {
    let f = fx.hypot(fy);
    if f <= 0.0 {
        return (0.0, 0.0, false);
    }
    let u = f / (mu * fz);
    let sigma = slip_for_force(u);
    (-sigma * fx / f, -sigma * fy / f, u > U_MAX)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inversion_reproduces_the_force() {
        for u in [0.0, 0.05, 0.3, 0.7, 0.9, 0.99] {
            let s = slip_for_force(u);
            assert!((magic_formula(s) - u).abs() < 2e-4, "u={u}");
        }
        // Peak value 1 at σ_peak.
        assert!((magic_formula(sigma_peak()) - 1.0).abs() < 1e-12);
        assert!(sigma_peak() > 0.08 && sigma_peak() < 0.12);
    }

    #[test]
    fn slip_opposes_force() {
        let (sx, sy, _) = slips(-3000.0, 4000.0, 5000.0, 1.8);
        assert!(sx > 0.0 && sy < 0.0);
        // Friction power −(Fx·s_x + Fy·s_y)·v_x is positive.
        assert!(-(-3000.0 * sx + 4000.0 * sy) > 0.0);
    }
}
