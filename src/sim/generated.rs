//! Randomly generated wear effects: the proof that the gap diagnosis finds
//! mechanisms it was not written for (`tirewear gap validate --random`).
//!
//! A generated effect is drawn from a space wider than the diagnosis's
//! candidates: any of [`Quantity::ALL`] (the condition maps' quantities and
//! others they do not bin: bulk temperature, the surface temperature's rate,
//! load relative to the static load, accelerations, time and distance since
//! the run started), one of [`Form`]'s shapes (a smooth onset above or
//! below a threshold, a band, two conditions holding together, a power
//! law), on the total, longitudinal or lateral friction energy, with a
//! random scope (every tire, an axle, a wheel position, a car, a car's axle)
//! and a set-up form that the telemetry does not show at all (more wear per
//! joule on one car, car axle or wheel position).
//!
//! The simulator bins each tire's friction power by the effect's quantities
//! on fine histograms of its own ([`Quantity::range`], [`BINS_1D`],
//! [`BINS_2D`]): thresholds are drawn as energy quantiles of the season, so
//! every effect acts on a known share of the energy, and the magnitude is
//! solved so that the effect's wear has the drawn share of the wear's
//! variance. None of this goes through tirewear's KPI extraction or maps.

use crate::{Axle, Wheel};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::fmt;

/// Bins of a one-quantity histogram.
pub const BINS_1D: usize = 512;
/// Bins per axis of a two-quantity histogram.
pub const BINS_2D: usize = 128;

/// A per-sample quantity of the simulator's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Quantity {
    /// |κ| = |v_sx| / v_x.
    SlipRatio,
    /// |tan α| = |v_sy| / v_x.
    SlipAngle,
    /// √(κ² + tan²α).
    CombinedSlip,
    /// |v_s| (m/s).
    SlidingSpeed,
    /// F_z (N).
    Load,
    /// F_z over the wheel's static load.
    RelativeLoad,
    /// √(F_x² + F_y²) / F_z.
    Utilisation,
    SurfaceTemperature,
    InnerTemperature,
    /// Mean of surface and inner-liner temperature (°C).
    BulkTemperature,
    /// dT_surface/dt (K/s) over the last sample.
    SurfaceTemperatureRate,
    Pressure,
    Camber,
    /// Vehicle speed (m/s).
    Speed,
    /// Longitudinal acceleration (m/s², braking negative).
    LongitudinalAcceleration,
    /// |lateral acceleration| (m/s²).
    LateralAcceleration,
    /// Time since the run started (s).
    TimeSinceStart,
    /// Distance since the run started (m).
    DistanceSinceStart,
}

impl Quantity {
    pub const ALL: [Quantity; 18] = [
        Quantity::SlipRatio,
        Quantity::SlipAngle,
        Quantity::CombinedSlip,
        Quantity::SlidingSpeed,
        Quantity::Load,
        Quantity::RelativeLoad,
        Quantity::Utilisation,
        Quantity::SurfaceTemperature,
        Quantity::InnerTemperature,
        Quantity::BulkTemperature,
        Quantity::SurfaceTemperatureRate,
        Quantity::Pressure,
        Quantity::Camber,
        Quantity::Speed,
        Quantity::LongitudinalAcceleration,
        Quantity::LateralAcceleration,
        Quantity::TimeSinceStart,
        Quantity::DistanceSinceStart,
    ];

    /// Histogram range (values outside go to the end bins) and unit.
    pub(crate) fn range(self) -> (f64, f64, &'static str) {
        match self {
            Quantity::SlipRatio | Quantity::SlipAngle => (0.0, 0.5, ""),
            Quantity::CombinedSlip => (0.0, 0.6, ""),
            Quantity::SlidingSpeed => (0.0, 15.0, "m/s"),
            Quantity::Load => (0.0, 15_000.0, "N"),
            Quantity::RelativeLoad => (0.0, 4.0, "× static"),
            Quantity::Utilisation => (0.0, 2.5, ""),
            Quantity::SurfaceTemperature
            | Quantity::InnerTemperature
            | Quantity::BulkTemperature => (0.0, 200.0, "°C"),
            Quantity::SurfaceTemperatureRate => (-40.0, 40.0, "K/s"),
            Quantity::Pressure => (80e3, 260e3, "Pa"),
            Quantity::Camber => (-8.0, 4.0, "°"),
            Quantity::Speed => (0.0, 100.0, "m/s"),
            Quantity::LongitudinalAcceleration => (-50.0, 30.0, "m/s²"),
            Quantity::LateralAcceleration => (0.0, 50.0, "m/s²"),
            Quantity::TimeSinceStart => (0.0, 7200.0, "s"),
            Quantity::DistanceSinceStart => (0.0, 400e3, "m"),
        }
    }

    /// Bin of `x` among `bins` over [`Quantity::range`].
    pub fn bin(self, x: f64, bins: usize) -> usize {
        let (lo, hi, _) = self.range();
        let b = ((x - lo) / (hi - lo) * bins as f64).floor();
        if b.is_nan() {
            0
        } else {
            (b.max(0.0) as usize).min(bins - 1)
        }
    }

    /// Centre of bin `b` among `bins`.
    pub fn centre(self, b: usize, bins: usize) -> f64 {
        let (lo, hi, _) = self.range();
        lo + (b as f64 + 0.5) * (hi - lo) / bins as f64
    }

    fn name(self) -> String {
        let s = serde_json::to_value(self).expect("serialisable");
        s.as_str().unwrap_or_default().replace('_', " ")
    }
}

/// The simulator's state of one wheel at one sample, in [`Quantity`]'s terms.
#[derive(Debug, Clone, Copy, Default)]
pub struct SampleState {
    pub slip_ratio: f64,
    pub slip_angle: f64,
    pub sliding_speed_mps: f64,
    pub load_n: f64,
    pub static_load_n: f64,
    pub utilisation: f64,
    pub t_surface_c: f64,
    pub t_inner_c: f64,
    pub t_surface_rate_kps: f64,
    pub pressure_pa: f64,
    pub camber_deg: f64,
    pub speed_mps: f64,
    pub ax_mps2: f64,
    pub ay_mps2: f64,
    pub time_s: f64,
    pub distance_m: f64,
}

impl SampleState {
    pub fn value(&self, q: Quantity) -> f64 {
        match q {
            Quantity::SlipRatio => self.slip_ratio.abs(),
            Quantity::SlipAngle => self.slip_angle.abs(),
            Quantity::CombinedSlip => self.slip_ratio.hypot(self.slip_angle),
            Quantity::SlidingSpeed => self.sliding_speed_mps,
            Quantity::Load => self.load_n,
            Quantity::RelativeLoad => self.load_n / self.static_load_n.max(1.0),
            Quantity::Utilisation => self.utilisation,
            Quantity::SurfaceTemperature => self.t_surface_c,
            Quantity::InnerTemperature => self.t_inner_c,
            Quantity::BulkTemperature => 0.5 * (self.t_surface_c + self.t_inner_c),
            Quantity::SurfaceTemperatureRate => self.t_surface_rate_kps,
            Quantity::Pressure => self.pressure_pa,
            Quantity::Camber => self.camber_deg,
            Quantity::Speed => self.speed_mps,
            Quantity::LongitudinalAcceleration => self.ax_mps2,
            Quantity::LateralAcceleration => self.ay_mps2.abs(),
            Quantity::TimeSinceStart => self.time_s,
            Quantity::DistanceSinceStart => self.distance_m,
        }
    }
}

/// Which friction energy the effect weights.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Component {
    Total,
    Longitudinal,
    Lateral,
}

impl Component {
    /// The component's share of the power (p_x, p_y in W).
    pub fn power(self, p_x: f64, p_y: f64) -> f64 {
        match self {
            Component::Total => p_x + p_y,
            Component::Longitudinal => p_x,
            Component::Lateral => p_y,
        }
    }
}

/// A smooth onset on one quantity: logistic in (x − threshold)/width,
/// rising above the threshold or below it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Onset {
    pub quantity: Quantity,
    pub above: bool,
    /// Drawn as an energy quantile of the season (0..1), resolved to a value.
    pub quantile: f64,
    /// Width as a fraction of the 5–95 % energy quantile span.
    pub width_fraction: f64,
    /// Resolved threshold and width (NaN until resolved).
    pub threshold: f64,
    pub width: f64,
}

impl Onset {
    pub fn weight(&self, x: f64) -> f64 {
        let z = (x - self.threshold) / self.width;
        let z = if self.above { z } else { -z };
        1.0 / (1.0 + (-z).exp())
    }
}

/// The shape of a generated effect's weight per sample.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "form")]
pub enum Form {
    /// One onset.
    Onset { onset: Onset },
    /// Between two thresholds of one quantity (`low` above, `high` below).
    Band { low: Onset, high: Onset },
    /// Two onsets that must hold together (their product).
    Pair { first: Onset, second: Onset },
    /// (x / x_median)^exponent, x the quantity (made positive by its range's
    /// start), x_median its energy-weighted median.
    Power {
        quantity: Quantity,
        exponent: f64,
        median: f64,
    },
    /// Weight 1: more wear per joule on the scope's tires (a set-up effect).
    SetUp,
}

/// Which tires the effect acts on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "scope")]
pub enum Scope {
    All,
    Axle {
        axle: Axle,
    },
    Wheel {
        wheel: Wheel,
    },
    /// Car index (0-based; the season's `car{index+1}`).
    Car {
        car: usize,
    },
    CarAxle {
        car: usize,
        axle: Axle,
    },
}

impl Scope {
    /// The tires in words, as the gap diagnosis names a term's scope:
    /// "every tire", "the front axle", "the FL tire of every car", "car2",
    /// "car2's front axle" (cars by their id, `car{index+1}`).
    pub fn describe(&self) -> String {
        match *self {
            Scope::All => "every tire".into(),
            Scope::Axle { axle } => format!("the {axle} axle"),
            Scope::Wheel { wheel } => format!("the {wheel} tire of every car"),
            Scope::Car { car } => format!("car{}", car + 1),
            Scope::CarAxle { car, axle } => format!("car{}'s {axle} axle", car + 1),
        }
    }

    pub fn contains(&self, car: usize, wheel: Wheel) -> bool {
        match *self {
            Scope::All => true,
            Scope::Axle { axle } => wheel.axle() == axle,
            Scope::Wheel { wheel: w } => wheel == w,
            Scope::Car { car: c } => car == c,
            Scope::CarAxle { car: c, axle } => car == c && wheel.axle() == axle,
        }
    }
}

/// A generated effect: drawn by [`GeneratedEffect::draw`], resolved on the
/// season by [`GeneratedEffect::resolve`] (thresholds) and
/// [`GeneratedEffect::magnitude_for`] (magnitude).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GeneratedEffect {
    /// The draw's seed.
    pub seed: u64,
    pub form: Form,
    pub component: Component,
    pub scope: Scope,
    /// Target share of the wear's variance (0..1).
    pub variance_share: f64,
    /// Multiple of the compound's base abrasion per joule where the weight
    /// is 1 (NaN until solved).
    pub magnitude: f64,
}

impl GeneratedEffect {
    /// Draws an effect from `seed`. A car is drawn as a number below 840
    /// (divisible by every count up to 8) and taken modulo the season's
    /// cars when resolved.
    pub fn draw(seed: u64) -> GeneratedEffect {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6765_6e65_7261_7465);
        let pick = |rng: &mut ChaCha8Rng| Quantity::ALL[rng.random_range(0..Quantity::ALL.len())];
        let onset = |rng: &mut ChaCha8Rng, q: Quantity, above: bool| Onset {
            quantity: q,
            above,
            // Above: the top 5–50 % of the energy; below: the bottom 5–50 %.
            quantile: if above {
                rng.random_range(0.5..0.95)
            } else {
                rng.random_range(0.05..0.5)
            },
            width_fraction: rng.random_range(0.02..0.15),
            threshold: f64::NAN,
            width: f64::NAN,
        };
        let cars = 840;
        let form = match rng.random_range(0..100) {
            0..40 => {
                let q = pick(&mut rng);
                let above = rng.random_bool(0.6);
                Form::Onset {
                    onset: onset(&mut rng, q, above),
                }
            }
            40..52 => {
                let q = pick(&mut rng);
                let mut low = onset(&mut rng, q, true);
                let mut high = onset(&mut rng, q, false);
                // A band holding 20–60 % of the energy.
                low.quantile = rng.random_range(0.1..0.5);
                high.quantile =
                    low.quantile + rng.random_range(0.2..0.6f64).min(0.95 - low.quantile);
                Form::Band { low, high }
            }
            52..72 => {
                let a = pick(&mut rng);
                let mut b = pick(&mut rng);
                while b == a {
                    b = pick(&mut rng);
                }
                let (ua, ub) = (rng.random_bool(0.6), rng.random_bool(0.6));
                let mut first = onset(&mut rng, a, ua);
                let mut second = onset(&mut rng, b, ub);
                // Thresholds at the 30–70 % energy quantiles: each onset
                // alone acts on 30–70 % of the energy, so together they act
                // on enough.
                first.quantile = rng.random_range(0.3..0.7);
                second.quantile = rng.random_range(0.3..0.7);
                Form::Pair { first, second }
            }
            72..87 => {
                let q = pick(&mut rng);
                let exponent = if rng.random_bool(0.7) {
                    rng.random_range(0.5..3.0)
                } else {
                    -rng.random_range(0.5..2.0)
                };
                Form::Power {
                    quantity: q,
                    exponent,
                    median: f64::NAN,
                }
            }
            _ => Form::SetUp,
        };
        let axle = |rng: &mut ChaCha8Rng| {
            if rng.random_bool(0.5) {
                Axle::Front
            } else {
                Axle::Rear
            }
        };
        let scope = match (form, rng.random_range(0..100)) {
            // A set-up effect on every tire or a whole axle is a change of
            // the law's k (per compound and axle): only narrower scopes.
            (Form::SetUp, r) if r < 30 => Scope::Wheel {
                wheel: Wheel::ALL[rng.random_range(0..4)],
            },
            (Form::SetUp, r) if r < 60 => Scope::Car {
                car: rng.random_range(0..cars),
            },
            (Form::SetUp, _) => Scope::CarAxle {
                car: rng.random_range(0..cars),
                axle: axle(&mut rng),
            },
            (_, 0..35) => Scope::All,
            (_, 35..70) => Scope::Axle {
                axle: axle(&mut rng),
            },
            (_, 70..80) => Scope::Wheel {
                wheel: Wheel::ALL[rng.random_range(0..4)],
            },
            (_, 80..90) => Scope::Car {
                car: rng.random_range(0..cars),
            },
            _ => Scope::CarAxle {
                car: rng.random_range(0..cars),
                axle: axle(&mut rng),
            },
        };
        let component = match rng.random_range(0..100) {
            0..60 => Component::Total,
            60..80 => Component::Longitudinal,
            _ => Component::Lateral,
        };
        GeneratedEffect {
            seed,
            form,
            component,
            scope,
            variance_share: rng.random_range(0.05..0.40),
            magnitude: f64::NAN,
        }
    }

    /// Form and scope in a word or two each, for grouping.
    pub(crate) fn kind_label(&self) -> (&'static str, &'static str) {
        let form = match self.form {
            Form::Onset { .. } => "onset",
            Form::Band { .. } => "band",
            Form::Pair { .. } => "pair",
            Form::Power { .. } => "power",
            Form::SetUp => "set-up",
        };
        let scope = match self.scope {
            Scope::All => "every tire",
            Scope::Axle { .. } => "axle",
            Scope::Wheel { .. } => "wheel",
            Scope::Car { .. } => "car",
            Scope::CarAxle { .. } => "car axle",
        };
        (form, scope)
    }

    /// The quantities the simulator histograms for this effect (none, one or two).
    pub(crate) fn quantities(&self) -> Vec<Quantity> {
        match self.form {
            Form::Onset { onset } => vec![onset.quantity],
            Form::Band { low, .. } => vec![low.quantity],
            Form::Pair { first, second } => vec![first.quantity, second.quantity],
            Form::Power { quantity, .. } => vec![quantity],
            Form::SetUp => Vec::new(),
        }
    }

    /// Length of a tire's histogram.
    pub(crate) fn histogram_len(&self) -> usize {
        match self.quantities().len() {
            0 => 1,
            1 => BINS_1D,
            _ => BINS_2D * BINS_2D,
        }
    }

    /// Histogram bin of a sample.
    pub fn bin(&self, s: &SampleState) -> usize {
        match self.quantities().as_slice() {
            [] => 0,
            [q] => q.bin(s.value(*q), BINS_1D),
            [a, b, ..] => a.bin(s.value(*a), BINS_2D) * BINS_2D + b.bin(s.value(*b), BINS_2D),
        }
    }

    /// Resolves the draw on a season of `cars` cars and its histograms
    /// (summed over every tire): the car, thresholds, widths and the power
    /// law's median.
    pub(crate) fn resolve(&mut self, cars: usize, season: &[f64]) {
        match &mut self.scope {
            Scope::Car { car } | Scope::CarAxle { car, .. } => *car %= cars.max(1),
            _ => {}
        }
        let qs = self.quantities();
        let marginal = |axis: usize| -> (Quantity, Vec<f64>) {
            let q = qs[axis];
            if qs.len() == 1 {
                return (q, season.to_vec());
            }
            let mut m = vec![0.0; BINS_2D];
            for (i, e) in season.iter().enumerate() {
                let b = if axis == 0 { i / BINS_2D } else { i % BINS_2D };
                m[b] += e;
            }
            (q, m)
        };
        let fix = |o: &mut Onset, axis: usize| {
            let (q, m) = marginal(axis);
            let at = |p: f64| quantile(q, &m, p);
            o.threshold = at(o.quantile);
            let span = (at(0.95) - at(0.05)).max(1e-9 * (q.range().1 - q.range().0));
            o.width = o.width_fraction * span;
        };
        match &mut self.form {
            Form::Onset { onset } => fix(onset, 0),
            Form::Band { low, high } => {
                fix(low, 0);
                fix(high, 0);
            }
            Form::Pair { first, second } => {
                fix(first, 0);
                fix(second, 1);
            }
            Form::Power {
                quantity, median, ..
            } => {
                let (q, m) = marginal(0);
                *median = quantile(q, &m, 0.5) - q.range().0;
                debug_assert_eq!(q, *quantity);
            }
            Form::SetUp => {}
        }
    }

    /// Weight of histogram bin `b` (after [`GeneratedEffect::resolve`]).
    pub fn weight(&self, b: usize) -> f64 {
        match self.form {
            Form::Onset { onset } => onset.weight(onset.quantity.centre(b, BINS_1D)),
            Form::Band { low, high } => {
                let x = low.quantity.centre(b, BINS_1D);
                low.weight(x) * high.weight(x)
            }
            Form::Pair { first, second } => {
                first.weight(first.quantity.centre(b / BINS_2D, BINS_2D))
                    * second.weight(second.quantity.centre(b % BINS_2D, BINS_2D))
            }
            Form::Power {
                quantity,
                exponent,
                median,
            } => {
                let x = quantity.centre(b, BINS_1D) - quantity.range().0;
                (x / median.max(1e-12)).max(0.0).powf(exponent).min(1e3)
            }
            Form::SetUp => 1.0,
        }
    }

    /// The effect's energy (J, at weight) of one tire's histogram.
    pub fn weighted_energy_j(&self, histogram: &[f64]) -> f64 {
        histogram
            .iter()
            .enumerate()
            .filter(|(_, e)| **e != 0.0)
            .map(|(b, e)| e * self.weight(b))
            .sum()
    }

    /// The magnitude at which the effect's wear `unit·m` (per tire, at
    /// magnitude 1: `unit`) has `variance_share` of the variance of
    /// `other + unit·m` (the rest of the wear): the positive root of
    /// m²·var(g)·(1 − s) − 2·s·cov(T, g)·m − s·var(T) = 0.
    pub(crate) fn magnitude_for(&self, other: &[f64], unit: &[f64]) -> f64 {
        let n = other.len() as f64;
        let mean = |v: &[f64]| v.iter().sum::<f64>() / n;
        let (mt, mg) = (mean(other), mean(unit));
        let (mut a, mut b, mut c) = (0.0, 0.0, 0.0);
        for (t, g) in other.iter().zip(unit) {
            a += (g - mg) * (g - mg);
            b += (t - mt) * (g - mg);
            c += (t - mt) * (t - mt);
        }
        let s = self.variance_share;
        if a <= 0.0 {
            return 0.0;
        }
        let disc = (s * b).powi(2) + a * (1.0 - s) * s * c;
        (s * b + disc.sqrt()) / (a * (1.0 - s))
    }
}

/// The energy quantile `p` of a histogram over `q`'s range (linear inside the bin).
fn quantile(q: Quantity, hist: &[f64], p: f64) -> f64 {
    let total: f64 = hist.iter().sum();
    let (lo, hi, _) = q.range();
    let w = (hi - lo) / hist.len() as f64;
    if total <= 0.0 {
        return lo + 0.5 * (hi - lo);
    }
    let mut acc = 0.0;
    for (b, e) in hist.iter().enumerate() {
        if acc + e >= p * total && *e > 0.0 {
            return lo + w * (b as f64 + (p * total - acc) / e);
        }
        acc += e;
    }
    hi
}

fn describe_onset(o: &Onset) -> String {
    let unit = o.quantity.range().2;
    format!(
        "{} {} {:.4} {unit} (width {:.3})",
        o.quantity.name(),
        if o.above { "above" } else { "below" },
        o.threshold,
        o.width
    )
}

impl fmt::Display for GeneratedEffect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let energy = match self.component {
            Component::Total => "energy",
            Component::Longitudinal => "longitudinal energy",
            Component::Lateral => "lateral energy",
        };
        let what = match self.form {
            Form::Onset { onset } => format!("{energy} with {}", describe_onset(&onset)),
            Form::Band { low, high } => format!(
                "{energy} with {} between {:.4} and {:.4} {}",
                low.quantity.name(),
                low.threshold,
                high.threshold,
                low.quantity.range().2
            ),
            Form::Pair { first, second } => format!(
                "{energy} with {} and {}",
                describe_onset(&first),
                describe_onset(&second)
            ),
            Form::Power {
                quantity,
                exponent,
                median,
            } => format!(
                "{energy} × ({} / {:.4})^{exponent:.2}",
                quantity.name(),
                median + quantity.range().0
            ),
            Form::SetUp => format!("all {energy} (set-up)"),
        };
        let scope = match self.scope {
            Scope::All => "every tire".to_string(),
            Scope::Axle { axle } => format!("{axle} axle"),
            Scope::Wheel { wheel } => format!("wheel {wheel}"),
            Scope::Car { car } => format!("car{}", car + 1),
            Scope::CarAxle { car, axle } => format!("car{} {axle} axle", car + 1),
        };
        write!(
            f,
            "#{}: {what}, {scope}, magnitude {:.3}",
            self.seed, self.magnitude
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_magnitude_gives_the_drawn_variance_share() {
        let other: Vec<f64> = (0..50)
            .map(|i| 10.0 + (i as f64 * 0.7).sin() * 3.0)
            .collect();
        let unit: Vec<f64> = (0..50)
            .map(|i| 1.0 + (i as f64 * 1.3).cos() + 0.01 * i as f64)
            .collect();
        for s in [0.05, 0.2, 0.4] {
            let e = GeneratedEffect {
                variance_share: s,
                ..GeneratedEffect::draw(1)
            };
            let m = e.magnitude_for(&other, &unit);
            let var = |v: &[f64]| {
                let mu = v.iter().sum::<f64>() / v.len() as f64;
                v.iter().map(|x| (x - mu).powi(2)).sum::<f64>()
            };
            let planted: Vec<f64> = unit.iter().map(|g| m * g).collect();
            let total: Vec<f64> = other.iter().zip(&planted).map(|(t, g)| t + g).collect();
            assert!((var(&planted) / var(&total) - s).abs() < 1e-9, "{s}");
        }
    }

    #[test]
    fn a_drawn_car_is_taken_modulo_the_seasons_cars() {
        let mut e = GeneratedEffect {
            scope: Scope::CarAxle {
                car: 841,
                axle: Axle::Rear,
            },
            form: Form::SetUp,
            ..GeneratedEffect::draw(3)
        };
        e.resolve(3, &[0.0]);
        assert_eq!(
            e.scope,
            Scope::CarAxle {
                car: 1,
                axle: Axle::Rear
            }
        );
    }

    #[test]
    fn quantiles_are_read_off_the_histogram() {
        // Uniform energy over 0..100 °C of a 0..200 °C range: the 0.3
        // quantile is 30 °C.
        let q = Quantity::SurfaceTemperature;
        let mut h = vec![0.0; BINS_1D];
        h[..BINS_1D / 2].fill(1.0);
        assert!((quantile(q, &h, 0.3) - 30.0).abs() < 1e-9);
    }

    #[test]
    fn draws_cover_every_form_and_scope() {
        let effects: Vec<GeneratedEffect> = (0..400).map(GeneratedEffect::draw).collect();
        for f in ["onset", "band", "pair", "power", "set_up"] {
            assert!(
                effects
                    .iter()
                    .any(|e| serde_json::to_value(e.form).unwrap()["form"] == f),
                "{f}"
            );
        }
        assert!(
            effects
                .iter()
                .any(|e| matches!(e.scope, Scope::CarAxle { .. }))
        );
        assert!(
            effects
                .iter()
                .all(|e| (0.05..0.40).contains(&e.variance_share))
        );
    }
}
