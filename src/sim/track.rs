//! Tracks as closed curvature profiles κ(s): straights and constant-radius
//! corners joined by clothoids (linear curvature ramps), with a net turning
//! of exactly 2π so the lap closes in heading.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;

/// Road texture parameters of a track (the simulator's truth).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RoadParams {
    /// Hurst exponent H of the self-affine band.
    pub hurst: f64,
    /// rms height of the synthesised profile before the height transform (mm).
    pub rms_mm: f64,
    /// Long-wavelength roll-off λ_r (mm): the PSD is flat above it.
    pub rolloff_mm: f64,
    /// Short-wavelength cut-off λ_s (mm): no content below it.
    pub cutoff_mm: f64,
    /// Quadratic coefficient of the height transform (sets skewness).
    pub skew_coef: f64,
    /// Cubic coefficient of the height transform (sets kurtosis).
    pub kurt_coef: f64,
}

/// A track definition: geometry seed and target length, grip and road texture.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackDef {
    pub id: String,
    pub name: String,
    pub seed: u64,
    pub length_target_m: f64,
    pub corners: usize,
    /// Multiplies tire peak friction on this surface.
    pub grip: f64,
    /// Hidden abrasiveness not captured by the road indexes (multiplies wear).
    pub hidden_abrasiveness: f64,
    pub road: RoadParams,
}

/// A track discretised on a uniform arc-length grid.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackShape {
    pub ds_m: f64,
    /// Curvature (1/m), positive for left turns, at s = i·ds.
    pub curvature: Vec<f64>,
}

impl TrackShape {
    pub(crate) fn length_m(&self) -> f64 {
        self.ds_m * self.curvature.len() as f64
    }

    /// Net turning angle ∫κ ds (rad): a closed track's is 2π.
    #[cfg(test)]
    pub(crate) fn total_turning(&self) -> f64 {
        self.curvature.iter().sum::<f64>() * self.ds_m
    }
}

struct Corner {
    radius: f64,
    angle: f64, // signed
    ramp: f64,
}

impl TrackDef {
    /// Builds the curvature profile on a grid of `ds_m`.
    pub(crate) fn shape(&self, ds_m: f64) -> TrackShape {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let mut corners: Vec<Corner> = (0..self.corners)
            .map(|_| {
                let radius = (rng.random_range(16f64.ln()..260f64.ln())).exp();
                let angle = rng.random_range(25f64..160.0).to_radians();
                let sign = if rng.random_bool(0.72) { 1.0 } else { -1.0 };
                Corner {
                    radius,
                    angle: sign * angle,
                    ramp: 0.0,
                }
            })
            .collect();
        // Scale the left turns so the net turning is exactly 2π.
        let left: f64 = corners
            .iter()
            .filter(|c| c.angle > 0.0)
            .map(|c| c.angle)
            .sum();
        let right: f64 = corners
            .iter()
            .filter(|c| c.angle < 0.0)
            .map(|c| -c.angle)
            .sum();
        let k = (2.0 * PI + right) / left.max(1e-9);
        for c in corners.iter_mut().filter(|c| c.angle > 0.0) {
            c.angle *= k;
        }
        // Clothoid ramps: 30 % of the corner's arc, at most 60 m.
        let mut corner_len = 0.0;
        for c in &mut corners {
            let arc = c.radius * c.angle.abs();
            c.ramp = (0.3 * arc).min(60.0);
            corner_len += arc; // ramps + arc together turn the same angle over the same length
        }
        // Straights share the remaining length (at least 25 % of the lap), one is the main straight.
        let straight_total = (self.length_target_m - corner_len).max(0.25 * self.length_target_m);
        let mut weights: Vec<f64> = (0..corners.len())
            .map(|_| rng.random_range(0.3..1.5))
            .collect();
        weights[0] = 4.0;
        let wsum: f64 = weights.iter().sum();
        let mut kappa = Vec::new();
        let push_const = |kappa: &mut Vec<f64>, len: f64, k: f64| {
            let n = (len / ds_m).round() as usize;
            kappa.extend(std::iter::repeat_n(k, n));
        };
        for (c, w) in corners.iter().zip(&weights) {
            push_const(&mut kappa, straight_total * w / wsum, 0.0);
            let k_c = c.angle.signum() / c.radius;
            let n_ramp = (c.ramp / ds_m).round().max(1.0) as usize;
            let arc = c.radius * c.angle.abs() - c.ramp; // ramp in + ramp out turn like one ramp length of arc
            for i in 0..n_ramp {
                kappa.push(k_c * (i as f64 + 0.5) / n_ramp as f64);
            }
            push_const(&mut kappa, arc.max(ds_m), k_c);
            for i in 0..n_ramp {
                kappa.push(k_c * (n_ramp as f64 - i as f64 - 0.5) / n_ramp as f64);
            }
        }
        // Grid rounding leaves a small residue: rescale the left turns so the net turning is exactly 2π.
        let mut shape = TrackShape {
            ds_m,
            curvature: kappa,
        };
        let left: f64 = shape.curvature.iter().filter(|k| **k > 0.0).sum::<f64>() * ds_m;
        let right: f64 = -shape.curvature.iter().filter(|k| **k < 0.0).sum::<f64>() * ds_m;
        let fix = (2.0 * PI + right) / left;
        for k in shape.curvature.iter_mut().filter(|k| **k > 0.0) {
            *k *= fix;
        }
        shape
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::preset::track_catalogue;

    #[test]
    fn every_track_closes_in_heading() {
        for t in track_catalogue() {
            let s = t.shape(1.0);
            assert!((s.total_turning() - 2.0 * PI).abs() < 1e-9, "{}", t.id);
            assert!(
                s.length_m() > 2500.0 && s.length_m() < 9000.0,
                "{} {}",
                t.id,
                s.length_m()
            );
            let r_min = 1.0 / s.curvature.iter().fold(0.0f64, |a, k| a.max(k.abs()));
            assert!(r_min > 10.0, "{} min radius {r_min}", t.id);
        }
    }
}
