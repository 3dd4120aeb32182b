//! One run in the time domain: the car laps its quasi-steady-state profile
//! (with small lap-to-lap pace changes), wheel forces and slips follow, tire
//! temperatures evolve, and every sample goes to the telemetry writer with
//! sensor noise and the occasional logger dropout. Noise-free integrals
//! (friction energy, the wear law's weighted energy, each planted effect's
//! weighted energy) are kept as ground truth.

use super::compound::CompoundModel;
use super::effects::{Effect, EffectKind};
use super::generated::{GeneratedEffect, SampleState};
use super::lap::LapProfile;
use super::thermal::{ThermalParams, TireTemps, hot_pressure_pa};
use super::tire::slips;
use super::vehicle::{CarParams, WheelForces};
use crate::Wheel;
use crate::ingest::telemetry::proto::{TireSample, VehicleSample};
use rand::Rng;
use rand_distr::{Distribution, Normal, Poisson};

/// Everything a run needs that is shared with other runs.
pub(crate) struct RunContext<'a> {
    pub car: &'a CarParams,
    pub compound: &'a CompoundModel,
    pub lap: &'a LapProfile,
    pub thermal: ThermalParams,
    /// Road grip factor of the track.
    pub road_grip: f64,
    pub effects: &'a [Effect],
    /// A generated effect whose quantities each wheel's friction power is
    /// histogrammed by (`WheelTruth::generated_histogram`).
    pub generated: Option<&'a GeneratedEffect>,
}

/// The run's own settings.
#[derive(Debug, Clone)]
pub(crate) struct RunSettings {
    pub distance_m: f64,
    pub rate_hz: f64,
    pub start_ns: u64,
    pub air_c: f64,
    pub track_c: f64,
    /// Cold (set) gauge pressure per wheel (Pa) at 20 °C.
    pub cold_pressure_pa: [f64; 4],
    /// Tire temperature at the start (blankets, °C).
    pub blanket_c: f64,
    /// Sensor noise and logger dropouts (off: ideal sensors, for exact tests).
    pub sensor_noise: bool,
}

/// Noise-free integrals of one wheel over the run.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub(crate) struct WheelTruth {
    /// ∫ −F_x·v_sx dt (J).
    pub friction_energy_x_j: f64,
    /// ∫ −F_y·v_sy dt (J).
    pub friction_energy_y_j: f64,
    /// ∫ P·ψ(T_s) dt: friction energy weighted by the compound's temperature factor (J).
    pub weighted_energy_j: f64,
    /// Per planted effect (in `EffectKind::ALL` order): ∫ P_e·w dt (J).
    pub effect_energy_j: [f64; 4],
    /// The generated effect's component energy (J) binned by its quantities
    /// (`GeneratedEffect::bin`); empty without one.
    #[serde(skip)]
    pub generated_histogram: Vec<f64>,
    pub mean_camber_deg: f64,
    pub mean_pressure_pa: f64,
    pub mean_surface_c: f64,
    pub mean_inner_c: f64,
}

/// Run-level truth.
#[derive(Debug, Clone, Default)]
pub(crate) struct RunTruth {
    pub wheels: [WheelTruth; 4],
    pub samples: u64,
    pub dropped_samples: u64,
    pub saturated_samples: u64,
    pub laps: u64,
    pub duration_s: f64,
}

/// Standard deviations of the sensor noise.
struct Noise {
    vx: Normal<f64>,
    vy: Normal<f64>,
    omega: Normal<f64>,
    force_n: Normal<f64>,
    force_rel: Normal<f64>,
    t_surface: Normal<f64>,
    t_inner: Normal<f64>,
    pressure: Normal<f64>,
    camber: Normal<f64>,
    speed: Normal<f64>,
    t_track: Normal<f64>,
    t_air: Normal<f64>,
}

impl Noise {
    fn new(on: bool) -> Self {
        let scale = if on { 1.0 } else { 0.0 };
        let n = |sd: f64| Normal::new(0.0, sd * scale).expect("non-negative sd");
        Noise {
            vx: n(0.02),
            vy: n(0.01),
            omega: n(0.03),
            force_n: n(15.0),
            force_rel: n(0.015),
            t_surface: n(0.8),
            t_inner: n(0.3),
            pressure: n(300.0),
            camber: n(0.05),
            speed: n(0.05),
            t_track: n(0.3),
            t_air: n(0.1),
        }
    }
}

/// Lookup table of the wear law's temperature factor ψ(T) (−30..210 °C, 0.25 K).
struct PsiTable(Vec<f64>);

impl PsiTable {
    const T0: f64 = -30.0;
    const STEP: f64 = 0.25;
    fn new(c: &CompoundModel) -> Self {
        PsiTable(
            (0..=960)
                .map(|i| c.wear_temperature_factor(Self::T0 + Self::STEP * i as f64))
                .collect(),
        )
    }
    fn at(&self, t: f64) -> f64 {
        let x = ((t - Self::T0) / Self::STEP).clamp(0.0, (self.0.len() - 2) as f64);
        let i = x as usize;
        let w = x - i as f64;
        self.0[i] * (1.0 - w) + self.0[i + 1] * w
    }
}

/// What a logger records beside the archive's channels, noise-free: the
/// logger export (`super::logger`) derives its channels from these.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Motion {
    pub ax_mps2: f64,
    pub ay_mps2: f64,
    pub yaw_rate_radps: f64,
    /// Each wheel's lateral slip `v_y/v_x` (paper eq. 20).
    pub slip_y: [f64; 4],
}

/// Simulates a run, passing each recorded sample to `sink(time_ns, tires,
/// vehicle, motion)`.
pub(crate) fn simulate_run<E>(
    ctx: &RunContext,
    set: &RunSettings,
    rng: &mut impl Rng,
    mut sink: impl FnMut(u64, &[TireSample; 4], &VehicleSample, &Motion) -> Result<(), E>,
) -> Result<RunTruth, E> {
    let lap = ctx.lap;
    let dt = 1.0 / set.rate_hz;
    let period_ns = (1e9 / set.rate_hz).round() as u64;
    let lap_len = lap.ds_m * lap.v.len() as f64;
    let dropouts = logger_dropouts(set, set.distance_m / (lap_len / lap.lap_time_s), rng);
    let weather_phase = rng.random_range(0.0..std::f64::consts::TAU);
    let stepper = Stepper {
        ctx,
        psi: PsiTable::new(ctx.compound),
        noise: Noise::new(set.sensor_noise),
        dt,
        static_load: ctx.car.wheel_loads(0.0, 0.0, 0.0),
        cold_pressure_pa: set.cold_pressure_pa,
    };

    let mut temps = [TireTemps {
        surface_c: set.blanket_c,
        inner_c: set.blanket_c,
    }; 4];
    let mut truth = RunTruth::default();
    let (mut s_lap, mut distance, mut time) = (0.0f64, 0.0f64, 0.0f64);
    let mut lap_pace: f64 = 1.0;
    // The driver's tire management (1: none), following its target with a lag.
    let mut manage: f64 = 1.0;
    let mut tires = [TireSample::default(); 4];
    if let Some(g) = ctx.generated {
        for wt in &mut truth.wheels {
            wt.generated_histogram = vec![0.0; g.histogram_len()];
        }
    }
    // dT_surface/dt over the last sample, per wheel (K/s).
    let mut surface_rate = [0.0f64; 4];
    while distance < set.distance_m {
        let m = Moment::new(
            lap,
            s_lap,
            lap_pace * manage,
            (time, distance),
            weather_phase,
            set,
        );
        let forces = ctx.car.wheel_forces(m.v, m.ax, m.ay);
        let mut motion = Motion {
            ax_mps2: m.ax,
            ay_mps2: m.ay,
            yaw_rate_radps: m.yaw_rate,
            slip_y: [0.0; 4],
        };
        for wheel in Wheel::ALL {
            let k = wheel.index();
            (tires[k], motion.slip_y[k]) = stepper.wheel(
                wheel,
                forces[k],
                &m,
                (&mut temps[k], &mut surface_rate[k]),
                &mut truth,
                rng,
            );
        }
        manage += (tire_management(&temps) - manage) * (dt / MANAGE_LAG_S).min(1.0);
        let noise = &stepper.noise;
        let vehicle = VehicleSample {
            speed_mps: (m.v + noise.speed.sample(rng)) as f32,
            t_track_c: (m.t_track + noise.t_track.sample(rng)) as f32,
            t_air_c: (m.t_air + noise.t_air.sample(rng)) as f32,
            distance_m: distance,
        };
        let dropped = dropouts.iter().any(|&(a, b)| time >= a && time < b);
        if dropped {
            truth.dropped_samples += 1;
        } else {
            sink(
                set.start_ns + truth.samples * period_ns,
                &tires,
                &vehicle,
                &motion,
            )?;
        }
        truth.samples += 1;
        s_lap += m.v * dt;
        distance += m.v * dt;
        time = truth.samples as f64 * dt;
        if s_lap >= lap_len {
            s_lap -= lap_len;
            truth.laps += 1;
            lap_pace = 1.0 + 0.006 * rng.sample::<f64, _>(rand_distr::StandardNormal);
        }
    }
    let n = truth.samples.max(1) as f64;
    for wt in &mut truth.wheels {
        wt.mean_camber_deg /= n;
        wt.mean_pressure_pa /= n;
        wt.mean_surface_c /= n;
        wt.mean_inner_c /= n;
    }
    truth.duration_s = time;
    Ok(truth)
}

/// Logger dropouts of a run of about `duration_s`: a Poisson number per
/// hour, 0.1-1.5 s each, sorted by start (none with ideal sensors).
fn logger_dropouts(set: &RunSettings, duration_s: f64, rng: &mut impl Rng) -> Vec<(f64, f64)> {
    let n_drop = match set.sensor_noise {
        true => Poisson::new(1.5 * duration_s / 3600.0 + 0.5)
            .map(|p| p.sample(rng) as usize)
            .unwrap_or(0),
        false => 0,
    };
    let mut dropouts: Vec<(f64, f64)> = (0..n_drop)
        .map(|_| {
            let t0 = rng.random_range(5.0..duration_s.max(6.0));
            (t0, t0 + rng.random_range(0.1..1.5))
        })
        .collect();
    dropouts.sort_by(|a, b| a.0.total_cmp(&b.0));
    dropouts
}

/// The car at one sample: the lap profile at its distance into the lap,
/// scaled by the pace, and the weather's slow drift.
struct Moment {
    v: f64,
    ax: f64,
    ay: f64,
    yaw_rate: f64,
    t_air: f64,
    t_track: f64,
    time_s: f64,
    distance_m: f64,
}

impl Moment {
    fn new(
        lap: &LapProfile,
        s_lap: f64,
        pace: f64,
        (time_s, distance_m): (f64, f64),
        weather_phase: f64,
        set: &RunSettings,
    ) -> Self {
        // Interpolate the lap profile at s, scaled by this lap's pace.
        let x = s_lap / lap.ds_m;
        let i = (x as usize).min(lap.v.len() - 1);
        let j = (i + 1) % lap.v.len();
        let w = x - i as f64;
        let lerp = |a: &[f64]| a[i] * (1.0 - w) + a[j] * w;
        let v = lerp(&lap.v) * pace.sqrt();
        let kappa = lerp(&lap.curvature);
        let weather = (std::f64::consts::TAU * time_s / 3600.0 + weather_phase).sin();
        Moment {
            v,
            ax: lerp(&lap.ax) * pace,
            ay: lerp(&lap.ay) * pace,
            yaw_rate: v * kappa,
            t_air: set.air_c + 1.0 * weather,
            t_track: set.track_c + 2.5 * weather,
            time_s,
            distance_m,
        }
    }
}

/// What a run's samples share: the wheel step's constants.
struct Stepper<'a> {
    ctx: &'a RunContext<'a>,
    psi: PsiTable,
    noise: Noise,
    dt: f64,
    /// Each wheel's load at rest (N).
    static_load: [f64; 4],
    cold_pressure_pa: [f64; 4],
}

/// One wheel at one sample, before its temperatures are stepped.
struct WheelState {
    k: usize,
    f: WheelForces,
    temps: TireTemps,
    /// dT_surface/dt over the last sample (K/s).
    surface_rate: f64,
    sx: f64,
    sy: f64,
    vx: f64,
    v_sx: f64,
    v_sy: f64,
    p_x: f64,
    p_y: f64,
    p: f64,
    radius: f64,
    omega: f64,
    camber: f64,
    pressure: f64,
}

impl Stepper<'_> {
    /// `wheel` at moment `m` under forces `f`: its noise-free integrals
    /// added to `truth`, its temperatures and their rate stepped; its
    /// recorded sample (with sensor noise) and lateral slip returned.
    fn wheel(
        &self,
        wheel: Wheel,
        f: WheelForces,
        m: &Moment,
        (temps, surface_rate): (&mut TireTemps, &mut f64),
        truth: &mut RunTruth,
        rng: &mut impl Rng,
    ) -> (TireSample, f64) {
        let ctx = self.ctx;
        let k = wheel.index();
        let mu = ctx.compound.grip.mu(temps.surface_c, f.fz, ctx.road_grip);
        let (sx, sy, saturated) = slips(f.fx, f.fy, f.fz, mu);
        truth.saturated_samples += saturated as u64;
        let y_w = wheel.side_sign() * 0.5 * ctx.car.track_width(wheel);
        let vx = (m.v - m.yaw_rate * y_w).max(0.5);
        let v_sx = sx * vx; // paper eq. 21
        let v_sy = sy * vx; // paper eq. 22
        let p_x = -f.fx * v_sx; // paper eq. 23, dissipated (≥ 0)
        let p_y = -f.fy * v_sy; // paper eq. 24
        let radius = ctx.car.rolling_radius(wheel) - f.fz / RADIAL_STIFFNESS_N_PER_M;
        let s = WheelState {
            k,
            f,
            temps: *temps,
            surface_rate: *surface_rate,
            sx,
            sy,
            vx,
            v_sx,
            v_sy,
            p_x,
            p_y,
            p: p_x + p_y, // paper eq. 25
            radius,
            omega: vx * (1.0 - sx) / radius,
            camber: ctx.car.camber_deg(wheel, m.ay),
            pressure: hot_pressure_pa(self.cold_pressure_pa[k], 20.0, temps.inner_c),
        };
        self.account(&mut truth.wheels[k], &s, m);
        let sample = self.recorded(&s, rng);
        let before = temps.surface_c;
        *temps = ctx
            .thermal
            .step(*temps, self.dt, s.p, f.fz, vx, m.t_air, m.t_track);
        *surface_rate = (temps.surface_c - before) / self.dt;
        (sample, sy)
    }

    /// Adds the sample to the wheel's noise-free integrals: friction
    /// energy, the wear law's weighted energy, each planted effect's, the
    /// generated effect's histogram, and the sums of the means.
    fn account(&self, wt: &mut WheelTruth, s: &WheelState, m: &Moment) {
        let (ctx, dt) = (self.ctx, self.dt);
        wt.friction_energy_x_j += s.p_x * dt;
        wt.friction_energy_y_j += s.p_y * dt;
        wt.weighted_energy_j += s.p * self.psi.at(s.temps.surface_c) * dt;
        for e in ctx.effects {
            let idx = EffectKind::ALL
                .iter()
                .position(|k| *k == e.kind)
                .expect("listed");
            let power = if e.kind == EffectKind::Graining {
                s.p_y
            } else {
                s.p
            };
            wt.effect_energy_j[idx] += power * e.weight(s.temps.surface_c, s.temps.inner_c) * dt;
        }
        if let Some(g) = ctx.generated {
            let f = s.f;
            let state = SampleState {
                slip_ratio: s.sx,
                slip_angle: s.sy,
                sliding_speed_mps: s.v_sx.hypot(s.v_sy),
                load_n: f.fz,
                static_load_n: self.static_load[s.k],
                utilisation: f.fx.hypot(f.fy) / f.fz.max(100.0),
                t_surface_c: s.temps.surface_c,
                t_inner_c: s.temps.inner_c,
                t_surface_rate_kps: s.surface_rate,
                pressure_pa: s.pressure,
                camber_deg: s.camber,
                speed_mps: m.v,
                ax_mps2: m.ax,
                ay_mps2: m.ay,
                time_s: m.time_s,
                distance_m: m.distance_m,
            };
            wt.generated_histogram[g.bin(&state)] += g.component.power(s.p_x, s.p_y) * dt;
        }
        wt.mean_camber_deg += s.camber;
        wt.mean_pressure_pa += s.pressure;
        wt.mean_surface_c += s.temps.surface_c;
        wt.mean_inner_c += s.temps.inner_c;
    }

    /// The wheel's sample as its sensors record it (noise drawn in field
    /// order).
    fn recorded(&self, s: &WheelState, rng: &mut impl Rng) -> TireSample {
        let (noise, f) = (&self.noise, s.f);
        let rel = 1.0 + noise.force_rel.sample(rng);
        TireSample {
            vx_mps: (s.vx + noise.vx.sample(rng)) as f32,
            vy_mps: (s.v_sy + noise.vy.sample(rng)) as f32,
            omega_radps: (s.omega + noise.omega.sample(rng)) as f32,
            rolling_radius_m: s.radius as f32,
            fx_n: (f.fx * rel + noise.force_n.sample(rng)) as f32,
            fy_n: (f.fy * rel + noise.force_n.sample(rng)) as f32,
            fz_n: (f.fz * rel + noise.force_n.sample(rng)) as f32,
            t_surface_c: (s.temps.surface_c + noise.t_surface.sample(rng)) as f32,
            t_inner_c: (s.temps.inner_c + noise.t_inner.sample(rng)) as f32,
            pressure_pa: (s.pressure + noise.pressure.sample(rng)) as f32,
            camber_deg: (s.camber + noise.camber.sample(rng)) as f32,
        }
    }
}

/// Radial stiffness of the simulated tires (N/m): loaded radius `R0 − F_z/k`.
pub(crate) const RADIAL_STIFFNESS_N_PER_M: f64 = 600_000.0;

/// Surface temperature (°C) above which the driver manages the tires.
pub(crate) const MANAGE_ABOVE_C: f64 = 105.0;

/// Reaction time (s) of the driver's tire management.
pub(crate) const MANAGE_LAG_S: f64 = 3.0;

/// The pace factor a driver aims for: with the hottest tire's surface
/// above [`MANAGE_ABOVE_C`] they back off 2 % per kelvin over, at most 25 %,
/// as drivers do to save an overheating tire (followed with a lag of
/// [`MANAGE_LAG_S`]). Without it a hot tire's lower grip means more
/// sliding, more heat, and a run-away that wore tires several times
/// through their tread in long stints at two of the twelve tracks.
pub(crate) fn tire_management(temps: &[TireTemps; 4]) -> f64 {
    let hottest = temps.iter().map(|t| t.surface_c).fold(f64::MIN, f64::max);
    (1.0 - 0.02 * (hottest - MANAGE_ABOVE_C).max(0.0)).max(0.75)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn management_backs_off_only_above_the_window() {
        let at = |hot: f64| {
            let mut t = [TireTemps {
                surface_c: 90.0,
                inner_c: 100.0,
            }; 4];
            t[3].surface_c = hot;
            tire_management(&t)
        };
        // Exactly 1 up to 105 °C (seasons that stay below are unchanged),
        // 2 %/K above, floored at 0.75.
        assert_eq!(at(104.9), 1.0);
        assert!((at(110.0) - 0.9).abs() < 1e-12);
        assert_eq!(at(150.0), 0.75);
    }
}
