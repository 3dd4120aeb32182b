//! Quasi-steady-state lap: the fastest speed profile v(s) the car can drive
//! within its g-g limit (friction with aerodynamic downforce), engine power
//! and braking, by the classic forward (acceleration) and backward (braking)
//! passes from the slowest point of the lap.

use super::track::TrackShape;
use super::vehicle::{AIR_DENSITY, CarParams, G};

/// Speed and accelerations on the track's arc-length grid.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LapProfile {
    pub ds_m: f64,
    pub v: Vec<f64>,
    /// Longitudinal acceleration (m/s²).
    pub ax: Vec<f64>,
    /// Lateral acceleration v²κ (m/s²), positive to the left.
    pub ay: Vec<f64>,
    pub curvature: Vec<f64>,
    pub lap_time_s: f64,
}

/// Grip envelope of the car with friction coefficient `mu`.
struct Envelope<'a> {
    car: &'a CarParams,
    mu: f64,
}

impl Envelope<'_> {
    /// Total acceleration the tires can give at speed v (m/s²).
    fn a_max(&self, v: f64) -> f64 {
        self.mu * (G + self.car.downforce(v) / self.car.mass_kg)
    }

    /// Fraction of the envelope left for longitudinal use after the lateral demand.
    fn remaining(&self, v: f64, ay: f64) -> f64 {
        let r = ay.abs() / self.a_max(v);
        (1.0 - r * r).max(0.0).sqrt()
    }

    /// Cornering speed limit for curvature k: m v² |k| = μ (m g + ½ρ C_L A v²).
    fn v_corner(&self, k: f64, v_top: f64) -> f64 {
        let m = self.car.mass_kg;
        let denom = m * k.abs() - self.mu * 0.5 * AIR_DENSITY * self.car.cl_a_m2;
        if denom <= 0.0 {
            return v_top;
        }
        (self.mu * m * G / denom).sqrt().min(v_top)
    }

    /// Forward acceleration: power-limited and traction-limited (rear-wheel
    /// drive, with the load transferred to the rear axle), minus drag.
    fn a_drive(&self, v: f64, ay: f64) -> f64 {
        let c = self.car;
        let m = c.mass_kg;
        let rear_static = G * (1.0 - c.front_weight_fraction)
            + c.downforce(v) * (1.0 - c.aero_front_fraction) / m;
        let traction = self.mu * rear_static / (1.0 - self.mu * c.cg_height_m / c.wheelbase_m);
        let power = c.power_w / (m * v.max(1.0));
        power.min(traction * self.remaining(v, ay)) - c.drag(v) / m
    }

    /// Braking deceleration (positive): all four tires plus drag.
    fn a_brake(&self, v: f64, ay: f64) -> f64 {
        self.a_max(v) * self.remaining(v, ay) + self.car.drag(v) / self.car.mass_kg
    }
}

/// Solves the lap for `car` on `track` with tire-road friction coefficient `mu`.
pub(crate) fn solve(track: &TrackShape, car: &CarParams, mu: f64) -> LapProfile {
    let env = Envelope { car, mu };
    let n = track.curvature.len();
    let ds = track.ds_m;
    let v_top = 0.999 * (car.power_w / (0.5 * AIR_DENSITY * car.cd_a_m2)).cbrt();
    let limit: Vec<f64> = track
        .curvature
        .iter()
        .map(|&k| env.v_corner(k, v_top))
        .collect();
    // Start both passes at the slowest corner point: its speed is known.
    let start = (0..n)
        .min_by(|&a, &b| limit[a].total_cmp(&limit[b]))
        .expect("track has points");
    let idx = |i: usize| (start + i) % n;
    let mut v = vec![0.0; n];
    v[idx(0)] = limit[idx(0)];
    for i in 1..n {
        let (p, c) = (idx(i - 1), idx(i));
        let a = env.a_drive(v[p], v[p] * v[p] * track.curvature[p]);
        v[c] = limit[c].min((v[p] * v[p] + 2.0 * a.max(0.0) * ds).sqrt());
    }
    for i in (0..n).rev() {
        let (c, nx) = (idx(i), idx(i + 1));
        let a = env.a_brake(v[nx], v[nx] * v[nx] * track.curvature[nx]);
        v[c] = v[c].min((v[nx] * v[nx] + 2.0 * a * ds).sqrt());
    }
    let ax = (0..n)
        .map(|i| {
            let nx = (i + 1) % n;
            (v[nx] * v[nx] - v[i] * v[i]) / (2.0 * ds)
        })
        .collect();
    let ay = (0..n).map(|i| v[i] * v[i] * track.curvature[i]).collect();
    let lap_time_s = (0..n).map(|i| 2.0 * ds / (v[i] + v[(i + 1) % n])).sum();
    LapProfile {
        ds_m: ds,
        v,
        ax,
        ay,
        curvature: track.curvature.clone(),
        lap_time_s,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_radius_circle_runs_at_the_closed_form_speed() {
        // On a circle of radius R the car runs at v² = μ m g / (m/R − μ ½ρ C_L A).
        let car = CarParams::single_seater("c", "c", 0.0);
        let r = 100.0;
        let n = (2.0 * std::f64::consts::PI * r) as usize;
        let track = TrackShape {
            ds_m: 2.0 * std::f64::consts::PI * r / n as f64,
            curvature: vec![1.0 / r; n],
        };
        let mu = 1.6;
        let lap = solve(&track, &car, mu);
        let m = car.mass_kg;
        let v = (mu * m * G / (m / r - mu * 0.5 * AIR_DENSITY * car.cl_a_m2)).sqrt();
        assert!(
            lap.v.iter().all(|x| (x - v).abs() < 1e-9),
            "{} vs {v}",
            lap.v[0]
        );
        assert!(lap.ay.iter().all(|a| (a - v * v / r).abs() < 1e-6));
    }

    #[test]
    fn straight_then_hairpin_respects_the_limits() {
        let car = CarParams::single_seater("c", "c", 0.0);
        let mut k = vec![0.0; 1500];
        k.extend(vec![1.0 / 20.0; 100]);
        let track = TrackShape {
            ds_m: 1.0,
            curvature: k,
        };
        let lap = solve(&track, &car, 1.7);
        let env = Envelope { car: &car, mu: 1.7 };
        for i in 0..lap.v.len() {
            // Never above the cornering limit, never braking harder than the tires allow.
            assert!(lap.v[i] <= env.v_corner(track.curvature[i], 1e9) + 1e-9);
            assert!(
                -lap.ax[i] <= env.a_brake(lap.v[i], 0.0) * 1.05 + 0.5,
                "i={i}"
            );
        }
        let vmax = lap.v.iter().cloned().fold(0.0, f64::max);
        assert!(vmax > 60.0 && vmax < 100.0, "vmax {vmax}");
    }
}
