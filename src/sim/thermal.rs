//! Two-node tire thermal model: a thin tread-surface node heated by the share
//! of friction power that enters the rubber, and an inner-liner node heated by
//! carcass hysteresis (rolling loss `c_h·Fz·v`), joined by conduction. The
//! surface is cooled by the air stream and the track, the inner node weakly
//! by the rim air. Explicit Euler at the telemetry step (time constants are
//! tens of seconds and more, steps are at most 0.05 s).

#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub(crate) struct ThermalParams {
    /// Heat capacity of the surface node (J/K).
    pub c_surface: f64,
    /// Heat capacity of the inner-liner node (J/K).
    pub c_inner: f64,
    /// Share of friction power that heats the tire (the rest heats the road).
    pub friction_share: f64,
    /// Rolling-loss coefficient: hysteresis heat `c_h·Fz·v` (W).
    pub hysteresis: f64,
    /// Surface-to-air conductance `g0 + g1·v` (W/K).
    pub g_air: [f64; 2],
    /// Surface-to-track conductance (W/K).
    pub g_track: f64,
    /// Surface-to-inner conduction (W/K).
    pub g_conduction: f64,
    /// Inner-node loss to the rim air (W/K).
    pub g_inner_air: f64,
}

impl Default for ThermalParams {
    fn default() -> Self {
        ThermalParams {
            c_surface: 4000.0,
            c_inner: 30000.0,
            friction_share: 0.35,
            hysteresis: 0.017,
            g_air: [20.0, 1.6],
            g_track: 50.0,
            g_conduction: 60.0,
            g_inner_air: 8.0,
        }
    }
}

/// Surface and inner-liner temperatures (°C).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct TireTemps {
    pub surface_c: f64,
    pub inner_c: f64,
}

impl ThermalParams {
    /// Heat flows (W) into the surface and inner nodes.
    pub(crate) fn heat_flows(
        &self,
        temps: TireTemps,
        friction_power_w: f64,
        fz: f64,
        v: f64,
        t_air: f64,
        t_track: f64,
    ) -> (f64, f64) {
        let cond = self.g_conduction * (temps.inner_c - temps.surface_c);
        let q_s = self.friction_share * friction_power_w + cond
            - (self.g_air[0] + self.g_air[1] * v) * (temps.surface_c - t_air)
            - self.g_track * (temps.surface_c - t_track);
        let q_i = self.hysteresis * fz * v - cond - self.g_inner_air * (temps.inner_c - t_air);
        (q_s, q_i)
    }

    /// Advances the temperatures by `dt` seconds.
    #[allow(clippy::too_many_arguments)]
    pub fn step(
        &self,
        temps: TireTemps,
        dt: f64,
        friction_power_w: f64,
        fz: f64,
        v: f64,
        t_air: f64,
        t_track: f64,
    ) -> TireTemps {
        let (q_s, q_i) = self.heat_flows(temps, friction_power_w, fz, v, t_air, t_track);
        TireTemps {
            surface_c: temps.surface_c + dt * q_s / self.c_surface,
            inner_c: temps.inner_c + dt * q_i / self.c_inner,
        }
    }
}

/// Gauge inflation pressure (Pa) at inner temperature `t_inner_c` for a tire
/// set to `cold_gauge_pa` at `cold_c` (ideal gas at constant volume).
pub(crate) fn hot_pressure_pa(cold_gauge_pa: f64, cold_c: f64, t_inner_c: f64) -> f64 {
    const ATM: f64 = 101_325.0;
    (cold_gauge_pa + ATM) * (t_inner_c + 273.15) / (cold_c + 273.15) - ATM
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steady_state_matches_the_hand_solution() {
        // Constant inputs: integrate long enough and compare with the 2x2 linear solve by hand.
        let p = ThermalParams::default();
        let (pf, fz, v, ta, tt) = (3000.0, 4000.0, 55.0, 25.0, 40.0);
        let mut t = TireTemps {
            surface_c: 30.0,
            inner_c: 30.0,
        };
        for _ in 0..400_000 {
            t = p.step(t, 0.05, pf, fz, v, ta, tt);
        }
        // Surface: (ga+gt+gc) Ts - gc Ti = η Pf + ga Ta + gt Tt ; inner: -gc Ts + (gc+gi) Ti = ch Fz v + gi Ta
        let ga = 20.0 + 1.6 * v;
        let (a11, a12, b1) = (ga + 50.0 + 60.0, -60.0, 0.35 * pf + ga * ta + 50.0 * tt);
        let (a21, a22, b2) = (-60.0, 60.0 + 8.0, 0.017 * fz * v + 8.0 * ta);
        let det = a11 * a22 - a12 * a21;
        let ts = (b1 * a22 - a12 * b2) / det;
        let ti = (a11 * b2 - a21 * b1) / det;
        assert!((t.surface_c - ts).abs() < 1e-6 && (t.inner_c - ti).abs() < 1e-6);
        assert!(ti > ts, "the inner liner runs hotter than the surface");
    }

    #[test]
    fn pressure_follows_gas_law() {
        // 80 kPa gauge at 20 °C, heated to 100 °C: (181325)·373.15/293.15 − 101325 = 129482 Pa.
        assert!((hot_pressure_pa(80_000.0, 20.0, 100.0) - 129_482.4).abs() < 1.0);
    }
}
