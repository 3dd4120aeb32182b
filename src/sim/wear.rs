//! True wear: the frictional-energy law (Schallamach/Archard type) scaled by
//! the compound's abradability and viscoelastic temperature factor and by the
//! road, extra irregular wear on the fronts, the planted effects; then its
//! distribution across the tread width and the spot readings a tire
//! engineer would take.

use super::compound::CompoundModel;
use super::effects::{Effect, EffectKind};
use super::run::WheelTruth;
use crate::Wheel;
use crate::ingest::wear::WearReading;
use rand::Rng;
use rand_distr::{Distribution, Normal};

/// Spot positions across the tread, as fractions of the width from the inner edge.
pub const SPOT_FRACTIONS: [f64; 7] = [0.04, 0.12, 0.28, 0.50, 0.70, 0.87, 0.96];
pub const READINGS_PER_SPOT: u32 = 3;
pub const NEW_DEPTH_MM: f64 = 4.0;
/// Standard deviation of one depth reading (mm).
pub const READING_NOISE_MM: f64 = 0.04;

/// Road quantities the wear law uses (per track, from the synthesised profiles).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct RoadTruth {
    pub skewness: f64,
    pub kurtosis: f64,
    pub rq_mm: f64,
    /// rms of the micro texture (wavelengths < 0.5 mm) (mm).
    pub micro_rms_mm: f64,
    pub hurst: f64,
    pub hidden_abrasiveness: f64,
}

impl RoadTruth {
    /// Road factor of the base law: negatively skewed (plateau-like) surfaces abrade less.
    pub fn factor(&self) -> f64 {
        (0.15 * self.skewness).exp() * self.hidden_abrasiveness
    }
}

/// Mean wear of one tire and its parts, in % of the new tread depth.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TireWear {
    pub base_pct: f64,
    pub irregular_pct: f64,
    /// In `EffectKind::ALL` order.
    pub effect_pct: [f64; 4],
    /// A generated effect's wear (`sim::generated`).
    pub generated_pct: f64,
    /// Camber tilt and pressure crowning of the base-wear distribution.
    pub camber_tilt: f64,
    pub pressure_crown: f64,
    pub new_depth_mm: f64,
}

impl TireWear {
    pub fn total_pct(&self) -> f64 {
        self.base_pct
            + self.irregular_pct
            + self.effect_pct.iter().sum::<f64>()
            + self.generated_pct
    }

    /// Wear (mm) at fraction `y` of the width from the inner edge.
    pub fn wear_mm_at(&self, y: f64) -> f64 {
        let to_mm = self.new_depth_mm / 100.0;
        let base = (1.0
            + self.camber_tilt * (1.0 - 2.0 * y)
            + self.pressure_crown * (1.0 - 12.0 * (y - 0.5).powi(2)))
        .max(0.05);
        // Irregular front wear concentrates on the inner shoulder (mean 1 over the width).
        let irregular = (-y / 0.2).exp() / (0.2 * (1.0 - (-5.0f64).exp()));
        let effects: f64 = self.effect_pct.iter().sum::<f64>() + self.generated_pct;
        (to_mm * (self.base_pct * base + self.irregular_pct * irregular + effects))
            .min(0.98 * self.new_depth_mm)
    }
}

/// The compound's base abrasion on this road (mm of tread per J of
/// temperature-weighted friction energy): the unit of every effect's magnitude.
pub fn abrasion_mm_per_j(compound: &CompoundModel, road: &RoadTruth) -> f64 {
    compound.wear_mm_per_mj * road.factor() / 1e6
}

/// Applies the wear law to one wheel's integrals.
pub fn tire_wear(
    compound: &CompoundModel,
    road: &RoadTruth,
    wheel: Wheel,
    truth: &WheelTruth,
    effects: &[Effect],
    rng: &mut impl Rng,
) -> TireWear {
    let new_depth_mm = NEW_DEPTH_MM + rng.random_range(-0.05..0.05);
    let k = abrasion_mm_per_j(compound, road);
    let pct = |mm: f64| 100.0 * mm / new_depth_mm;
    let base_pct = pct(k * truth.weighted_energy_j);
    let irregular_pct = if wheel.axle() == crate::Axle::Front {
        base_pct * rng.random_range(0.05..0.45)
    } else {
        0.0
    };
    let mut effect_pct = [0.0; 4];
    for e in effects {
        let i = EffectKind::ALL
            .iter()
            .position(|k| *k == e.kind)
            .expect("listed");
        effect_pct[i] = match e.kind {
            EffectKind::RoadAbrasion => e.magnitude * base_pct * e.road_weight(road.micro_rms_mm),
            EffectKind::Graining if wheel.axle() == crate::Axle::Rear => {
                0.2 * e.magnitude * pct(k * truth.effect_energy_j[i])
            }
            _ => e.magnitude * pct(k * truth.effect_energy_j[i]),
        };
    }
    TireWear {
        base_pct,
        irregular_pct,
        effect_pct,
        generated_pct: 0.0,
        camber_tilt: -0.1 * truth.mean_camber_deg,
        pressure_crown: 2.0 * (truth.mean_pressure_pa / 130_000.0 - 1.0),
        new_depth_mm,
    }
}

/// The depth readings of one tire: each spot read several times with noise.
pub fn spot_readings(
    run: &str,
    wheel: Wheel,
    tire_set: &str,
    width_mm: f64,
    wear: &TireWear,
    rng: &mut impl Rng,
) -> Vec<WearReading> {
    let noise = Normal::new(0.0, READING_NOISE_MM).expect("positive sd");
    let mut rows = Vec::new();
    for (s, &y) in SPOT_FRACTIONS.iter().enumerate() {
        let position_mm = (y * width_mm * 10.0).round() / 10.0;
        let depth = wear.new_depth_mm - wear.wear_mm_at(position_mm / width_mm);
        for r in 1..=READINGS_PER_SPOT {
            let d = (depth + noise.sample(rng)).max(0.0);
            rows.push(WearReading {
                run: run.into(),
                wheel,
                tire_set: tire_set.into(),
                spot: s as u32 + 1,
                position_mm,
                tread_width_mm: width_mm,
                reading: r,
                depth_mm: (d * 1000.0).round() / 1000.0,
                new_depth_mm: (wear.new_depth_mm * 1000.0).round() / 1000.0,
            });
        }
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn width_distribution_keeps_the_mean() {
        let w = TireWear {
            base_pct: 30.0,
            irregular_pct: 6.0,
            effect_pct: [2.0, 0.0, 1.0, 0.0],
            generated_pct: 0.5,
            camber_tilt: 0.3,
            pressure_crown: 0.1,
            new_depth_mm: 4.0,
        };
        let n = 100_000;
        let mean: f64 = (0..n)
            .map(|i| w.wear_mm_at((i as f64 + 0.5) / n as f64))
            .sum::<f64>()
            / n as f64;
        assert!((100.0 * mean / 4.0 - w.total_pct()).abs() < 1e-6, "{mean}");
        // Negative camber (positive tilt) wears the inner edge more.
        assert!(w.wear_mm_at(0.05) > w.wear_mm_at(0.95));
    }
}
