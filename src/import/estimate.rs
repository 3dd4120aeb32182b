//! Virtual sensors: the archive's per-wheel channels from what a logger
//! records and the vehicle description (`docs/import.md`, "Virtual
//! sensors"). Quasi-static: loads from static weight, downforce and load
//! transfer; forces from the measured accelerations; wheel-centre
//! velocities from speed and yaw rate; lateral sliding from body slip and
//! steering (kinematics) or, without them, from a linear tyre.

use super::align::Aligned;
use super::car::{CarDescription, DrivenAxle, Suspension};
use super::channel_map::Quantity;
use super::error::ImportError;
use super::units::STANDARD_GRAVITY as G;
use crate::Wheel;
use crate::ingest::telemetry::proto::{TireSample, VehicleSample};
use std::borrow::Cow;
use std::path::Path;

/// How the lateral sliding velocity was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LateralMethod {
    /// Body slip angle, yaw rate and steer angle (rigid-body kinematics).
    Kinematic,
    /// Lateral force over cornering stiffness (`car.toml` `[tyres]`).
    TyreModel,
}

/// The estimated samples of a run.
#[derive(Debug, Clone, Default)]
pub(crate) struct Estimated {
    pub tires: Vec<[TireSample; 4]>,
    pub vehicle: Vec<VehicleSample>,
    /// Archive channels that were estimated, each with how (`fz_n: load transfer`).
    pub estimated: Vec<String>,
    pub lateral: Option<LateralMethod>,
    /// The rolling-radius check on the wheels that roll freely (docs/import.md).
    pub radius_checks: Vec<RadiusCheck>,
}

/// How far a free-rolling wheel's `Ω·R` is from its centre's speed: the
/// median longitudinal slip `(v_x − ΩR)/v_x` over the samples where the
/// wheel carries no longitudinal force (the non-driven axle while the car
/// drives or cruises: speed ≥ 15 m/s, |a_y| ≤ 0.1 g). Zero when the radius
/// (car.toml's loaded radius and wheel-speed radius) is right; `s` means R
/// is `s` too small.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RadiusCheck {
    pub wheel: Wheel,
    pub samples: usize,
    pub median_slip: f64,
    /// The factor the wheel's radius was multiplied by (1 unless calibrated).
    pub applied_factor: f64,
}

/// Fewest free-rolling samples a radius check needs.
const MIN_FREE_ROLLING: usize = 50;

/// Checks (and with `calibrate`, corrects) the rolling radius of the wheels
/// that roll freely; see [`RadiusCheck`].
fn check_radius(est: &mut Estimated, car: &CarDescription, calibrate: bool) {
    let free_axle = match car.driven_axle {
        DrivenAxle::Rear => crate::Axle::Front,
        DrivenAxle::Front => crate::Axle::Rear,
        DrivenAxle::All => return,
    };
    for w in Wheel::ALL.into_iter().filter(|w| w.axle() == free_axle) {
        let k = w.index();
        let mut slips: Vec<f64> = est
            .tires
            .iter()
            .zip(&est.vehicle)
            .filter(|(t, v)| {
                let t = &t[k];
                // No drive or brake force, and a lateral force under a
                // tenth of the load (|a_y| below about 0.1 g).
                v.speed_mps >= 15.0 && t.fx_n == 0.0 && t.fy_n.abs() <= 0.1 * t.fz_n
            })
            .map(|(t, _)| {
                let t = &t[k];
                let vx = t.vx_mps as f64;
                (vx - t.omega_radps as f64 * t.rolling_radius_m as f64) / vx
            })
            .collect();
        if slips.len() < MIN_FREE_ROLLING {
            continue;
        }
        slips.sort_by(f64::total_cmp);
        let median_slip = slips[slips.len() / 2];
        let applied_factor = if calibrate {
            1.0 / (1.0 - median_slip)
        } else {
            1.0
        };
        if calibrate {
            for t in &mut est.tires {
                t[k].rolling_radius_m = (t[k].rolling_radius_m as f64 * applied_factor) as f32;
            }
        }
        est.radius_checks.push(RadiusCheck {
            wheel: w,
            samples: slips.len(),
            median_slip,
            applied_factor,
        });
    }
    if calibrate && !est.radius_checks.is_empty() {
        let s: Vec<String> = est
            .radius_checks
            .iter()
            .map(|c| format!("{} ×{:.5}", c.wheel.name(), c.applied_factor))
            .collect();
        est.estimated.push(format!(
            "rolling_radius_m: calibrated on free-rolling samples ({})",
            s.join(", ")
        ));
    }
}

/// Values the log may lack that the manifest's event has.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct EventConditions {
    pub air_c: Option<f64>,
    pub track_c: Option<f64>,
}

/// Half-width (s) of the centred difference that derives the longitudinal
/// acceleration from speed when the log has none.
const DERIVATIVE_HALF_WIDTH_S: f64 = 0.25;

/// A required quantity is missing: the error lists the names the map
/// tried for `quantities` and every channel the log has.
fn missing(path: &Path, what: &str, quantities: &[Quantity], a: &Aligned) -> ImportError {
    let tried: Vec<String> = quantities
        .iter()
        .map(|q| match a.tried.get(q) {
            Some(names) => format!(
                "{}: {}",
                q.key(),
                names
                    .iter()
                    .map(|n| format!("'{n}'"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            None => format!("{}: no names in the map", q.key()),
        })
        .collect();
    ImportError::Missing {
        path: path.to_path_buf(),
        quantity: what.into(),
        tried: tried.join("; "),
        available: a.source_names.join(", "),
    }
}

/// Centred difference over ±half-width of the grid (one-sided at the ends).
fn derivative(a: &Aligned, v: &[f64]) -> Vec<f64> {
    let h = (DERIVATIVE_HALF_WIDTH_S * a.rate_hz).round().max(1.0) as usize;
    let n = v.len();
    (0..n)
        .map(|i| {
            let (lo, hi) = (i.saturating_sub(h), (i + h).min(n - 1));
            if hi == lo {
                return 0.0;
            }
            let dt = (a.index[hi] - a.index[lo]) as f64 / a.rate_hz;
            (v[hi] - v[lo]) / dt
        })
        .collect()
}

/// Estimates every archive channel for each aligned sample.
pub(crate) fn estimate(
    path: &Path,
    a: &Aligned,
    car: &CarDescription,
    cond: EventConditions,
    calibrate_radius: bool,
) -> Result<Estimated, ImportError> {
    let mut notes = Vec::new();
    let sources = Sources::gather(path, a, car, cond, &mut notes)?;
    let n = a.len();
    let mut est = Estimated {
        lateral: Some(sources.lateral.method()),
        estimated: notes,
        ..Estimated::default()
    };
    est.tires.reserve(n);
    est.vehicle.reserve(n);
    for i in 0..n {
        let (tires, vehicle) = sources.sample(i);
        est.tires.push(tires);
        est.vehicle.push(vehicle);
    }
    check_radius(&mut est, car, calibrate_radius);
    Ok(est)
}

/// What a run's samples are estimated from: the log's series, what stands
/// in for those it lacks, and the car.
struct Sources<'a> {
    car: &'a CarDescription,
    speed_mps: &'a [f64],
    accel_long_mps2: Vec<f64>,
    accel_lat_mps2: Vec<f64>,
    yaw_rate_radps: Vec<f64>,
    /// Per wheel, as logged: Ω (rad/s) where `angular`, else Ω·R (m/s).
    wheel_speed: Vec<&'a [f64]>,
    angular: [bool; 4],
    surface_c: Vec<&'a [f64]>,
    pressure_pa: Vec<Cow<'a, [f64]>>,
    /// TPMS gas temperature per wheel; the surface's where absent.
    inner_c: Vec<Option<&'a [f64]>>,
    loads: Loads<'a>,
    lateral: Lateral<'a>,
    air_c: Temperature<'a>,
    track_c: Temperature<'a>,
    distance_m: Vec<f64>,
    /// CG to front and to rear axle (m): a and b.
    cg_to_front_m: f64,
    cg_to_rear_m: f64,
}

/// Where the wheel loads come from.
enum Loads<'a> {
    /// Logged per wheel.
    Measured(Vec<&'a [f64]>),
    /// Static load plus wheel rate times wheel travel from the damper
    /// positions (m).
    Springs {
        dampers: Vec<&'a [f64]>,
        suspension: &'a Suspension,
        static_load_n: [f64; 4],
    },
    /// Static weight, downforce and load transfer.
    Transfer,
}

/// Where the lateral sliding comes from (see [`LateralMethod`]).
enum Lateral<'a> {
    Kinematic {
        body_slip_deg: &'a [f64],
        steer_deg: Vec<f64>,
    },
    TyreModel {
        cornering_stiffness_per_rad: [f64; 2],
    },
}

/// A temperature the log has, or the event's.
enum Temperature<'a> {
    Logged(&'a [f64]),
    Event(f64),
}

/// One sample's car-level estimates, which its four tires share.
struct CarSample {
    speed_mps: f64,
    accel_lat_mps2: f64,
    yaw_rate_radps: f64,
    fz_n: [f64; 4],
    axle_fx_n: [f64; 2],
    axle_fy_n: [f64; 2],
    axle_slip: AxleSlip,
}

/// Each axle's lateral slip: from kinematics, or (per tire, from its
/// lateral force and load) through the axle's cornering stiffness (1/rad).
enum AxleSlip {
    Kinematic([f64; 2]),
    TyreModel {
        cornering_stiffness_per_rad: [f64; 2],
    },
}

impl<'a> Sources<'a> {
    /// The run's sources, each estimated one noted (`notes`, in the order
    /// the archive lists them); an error names what is missing.
    fn gather(
        path: &Path,
        a: &'a Aligned,
        car: &'a CarDescription,
        cond: EventConditions,
        notes: &mut Vec<String>,
    ) -> Result<Sources<'a>, ImportError> {
        let speed = a
            .get(Quantity::GroundSpeed, None)
            .ok_or_else(|| missing(path, "ground_speed", &[Quantity::GroundSpeed], a))?;
        let (accel_lat_mps2, yaw_rate_radps) = lateral_motion(path, a, speed, notes)?;
        let accel_long_mps2 = match a.get(Quantity::AccelLong, None) {
            Some(x) => x.to_vec(),
            None => {
                notes.push("longitudinal acceleration: d(speed)/dt over ±0.25 s".into());
                derivative(a, speed)
            }
        };
        let wheel_speed = per_wheel(path, a, Quantity::WheelSpeed, "wheel_speed")?;
        // A linear wheel speed (the unit said km/h, m/s...) is Ω·R at the
        // logger's radius; an angular one (rpm, rad/s) is Ω.
        let angular: [bool; 4] = std::array::from_fn(|k| {
            matches!(
                a.wheel_speed_dimension[k],
                Some(super::units::Dimension::AngularSpeed)
            )
        });
        let surface_c = per_wheel(path, a, Quantity::TyreTemp, "tyre_temp")?;
        let pressure_pa = pressures(path, a, car, notes)?;
        let inner_c: Vec<Option<&[f64]>> = Wheel::ALL
            .iter()
            .map(|&w| a.get(Quantity::TpmsTemp, Some(w)))
            .collect();
        notes.push(if inner_c.iter().any(Option::is_none) {
            "t_inner_c: the surface temperature (no TPMS gas temperature)".into()
        } else {
            "t_inner_c: TPMS gas temperature".into()
        });
        let loads = Loads::choose(a, car, notes);
        notes.push("fx_n, fy_n: the accelerations distributed over the wheels (car.toml)".into());
        notes.push("vx_mps: speed and yaw rate at the wheel centre".into());
        notes.push("rolling_radius_m: car.toml".into());
        let lateral = Lateral::choose(path, a, car, notes)?;
        notes.push(if car.camber.is_some() {
            "camber_deg: static camber and roll (car.toml)".into()
        } else {
            "camber_deg: 0 (car.toml has no [camber])".into()
        });
        let air_c = Temperature::of(path, a, Quantity::AirTemp, "air", cond.air_c, notes)?;
        let track_c = Temperature::of(path, a, Quantity::TrackTemp, "track", cond.track_c, notes)?;
        let distance_m = distance_m(a, speed, notes);
        Ok(Sources {
            car,
            speed_mps: speed,
            accel_long_mps2,
            accel_lat_mps2,
            yaw_rate_radps,
            wheel_speed,
            angular,
            surface_c,
            pressure_pa,
            inner_c,
            loads,
            lateral,
            air_c,
            track_c,
            distance_m,
            cg_to_front_m: car.cg_to_front_m(),
            cg_to_rear_m: car.cg_to_rear_m(),
        })
    }

    /// Sample `i`'s four tires and the car's own channels.
    fn sample(&self, i: usize) -> ([TireSample; 4], VehicleSample) {
        let state = self.car_sample(i);
        let mut tires = [TireSample::default(); 4];
        for w in Wheel::ALL {
            tires[w.index()] = self.tire(i, w, &state);
        }
        let vehicle = VehicleSample {
            speed_mps: state.speed_mps as f32,
            t_track_c: self.track_c.at(i) as f32,
            t_air_c: self.air_c.at(i) as f32,
            distance_m: self.distance_m[i],
        };
        (tires, vehicle)
    }

    /// Sample `i`'s loads, axle forces and kinematic slips.
    fn car_sample(&self, i: usize) -> CarSample {
        let car = self.car;
        let v = self.speed_mps[i].max(0.0);
        let (ax, ay, r) = (
            self.accel_long_mps2[i],
            self.accel_lat_mps2[i],
            self.yaw_rate_radps[i],
        );
        let fz_n = self.loads.at(car, i, v, ax, ay);
        let (axle_fx_n, axle_fy_n) = axle_forces(car, v, ax, ay);
        let vv = v.max(1.0);
        let axle_slip = match &self.lateral {
            Lateral::Kinematic {
                body_slip_deg,
                steer_deg,
            } => {
                let tb = body_slip_deg[i].to_radians().tan();
                let td = steer_deg[i].to_radians().tan();
                AxleSlip::Kinematic([
                    tb + self.cg_to_front_m * r / vv - td,
                    tb - self.cg_to_rear_m * r / vv,
                ])
            }
            Lateral::TyreModel {
                cornering_stiffness_per_rad,
            } => AxleSlip::TyreModel {
                cornering_stiffness_per_rad: *cornering_stiffness_per_rad,
            },
        };
        CarSample {
            speed_mps: v,
            accel_lat_mps2: ay,
            yaw_rate_radps: r,
            fz_n,
            axle_fx_n,
            axle_fy_n,
            axle_slip,
        }
    }

    /// Wheel `w`'s sample `i`: its axle's forces shared by load, the wheel
    /// centre's velocities, and its own channels.
    fn tire(&self, i: usize, w: Wheel, s: &CarSample) -> TireSample {
        let car = self.car;
        let (fz, k) = (&s.fz_n, w.index());
        let ax_i = CarDescription::axle_of(w);
        let (l_, r_) = if ax_i == 0 {
            (fz[0], fz[1])
        } else {
            (fz[2], fz[3])
        };
        let share = fz[k] / (l_ + r_);
        let fx = s.axle_fx_n[ax_i] * share;
        let fy = s.axle_fy_n[ax_i] * share;
        let y_w = w.side_sign() * 0.5 * car.track_width(w);
        let vx = (s.speed_mps - s.yaw_rate_radps * y_w).max(0.5);
        let s_y = match &s.axle_slip {
            AxleSlip::Kinematic(slip) => slip[ax_i],
            AxleSlip::TyreModel {
                cornering_stiffness_per_rad: c,
            } => -fy / (c[ax_i] * fz[k]),
        };
        let ws = self.wheel_speed[k][i];
        let omega = if self.angular[k] {
            ws
        } else {
            ws / car.wheel_speed_radius(w)
        };
        let camber = car.camber.as_ref().map_or(0.0, |c| {
            let roll = c.roll_gradient_deg_per_g * s.accel_lat_mps2 / G;
            c.static_deg[ax_i] - w.side_sign() * c.change_per_roll * roll
        });
        TireSample {
            vx_mps: vx as f32,
            vy_mps: (s_y * vx) as f32,
            omega_radps: omega as f32,
            rolling_radius_m: car.loaded_radius(w, fz[k]) as f32,
            fx_n: fx as f32,
            fy_n: fy as f32,
            fz_n: fz[k] as f32,
            t_surface_c: self.surface_c[k][i] as f32,
            t_inner_c: self.inner_c[k].unwrap_or(self.surface_c[k])[i] as f32,
            pressure_pa: self.pressure_pa[k][i] as f32,
            camber_deg: camber as f32,
        }
    }
}

/// The lateral acceleration (m/s²) and yaw rate (rad/s): as logged, or
/// one from the other and the speed.
fn lateral_motion(
    path: &Path,
    a: &Aligned,
    speed: &[f64],
    notes: &mut Vec<String>,
) -> Result<(Vec<f64>, Vec<f64>), ImportError> {
    match (
        a.get(Quantity::AccelLat, None),
        a.get(Quantity::YawRate, None),
    ) {
        (Some(ay), Some(r)) => Ok((ay.to_vec(), r.to_vec())),
        (Some(ay), None) => {
            notes.push("yaw rate: lateral acceleration / speed".into());
            Ok((
                ay.to_vec(),
                ay.iter().zip(speed).map(|(y, v)| y / v.max(1.0)).collect(),
            ))
        }
        (None, Some(r)) => {
            notes.push("lateral acceleration: speed · yaw rate".into());
            Ok((
                r.iter().zip(speed).map(|(r, v)| r * v).collect(),
                r.to_vec(),
            ))
        }
        (None, None) => Err(missing(
            path,
            "accel_lat or yaw_rate",
            &[Quantity::AccelLat, Quantity::YawRate],
            a,
        )),
    }
}

/// Quantity `q` of each wheel, which the log must have (`name` in the
/// error).
fn per_wheel<'a>(
    path: &Path,
    a: &'a Aligned,
    q: Quantity,
    name: &str,
) -> Result<Vec<&'a [f64]>, ImportError> {
    Wheel::ALL
        .iter()
        .map(|&w| {
            a.get(q, Some(w))
                .ok_or_else(|| missing(path, &format!("{name} {}", w.name()), &[q], a))
        })
        .collect()
}

/// Each wheel's pressure (Pa): TPMS, or without it car.toml's hot
/// pressure per axle (a constant).
fn pressures<'a>(
    path: &Path,
    a: &'a Aligned,
    car: &CarDescription,
    notes: &mut Vec<String>,
) -> Result<Vec<Cow<'a, [f64]>>, ImportError> {
    let tpms: Vec<Option<&[f64]>> = Wheel::ALL
        .iter()
        .map(|&w| a.get(Quantity::TpmsPressure, Some(w)))
        .collect();
    if tpms.iter().all(Option::is_some) {
        return Ok(tpms.into_iter().flatten().map(Cow::Borrowed).collect());
    }
    let Some(kpa) = car.tyres.pressure_kpa else {
        let w = Wheel::ALL
            .into_iter()
            .find(|&w| tpms[w.index()].is_none())
            .expect("one is missing");
        return Err(missing(
            path,
            &format!(
                "tpms_pressure {} (or car.toml [tyres] pressure_kpa)",
                w.name()
            ),
            &[Quantity::TpmsPressure],
            a,
        ));
    };
    notes.push("pressure_pa: car.toml [tyres] pressure_kpa (no TPMS)".into());
    Ok(Wheel::ALL
        .iter()
        .map(|&w| Cow::Owned(vec![kpa[CarDescription::axle_of(w)] * 1e3; a.len()]))
        .collect())
}

impl<'a> Loads<'a> {
    /// Logged loads; else the damper positions through car.toml's springs;
    /// else load transfer.
    fn choose(a: &'a Aligned, car: &'a CarDescription, notes: &mut Vec<String>) -> Loads<'a> {
        let of = |q: Quantity| -> Option<Vec<&'a [f64]>> {
            Wheel::ALL.iter().map(|&w| a.get(q, Some(w))).collect()
        };
        if let Some(loads) = of(Quantity::WheelLoad) {
            return Loads::Measured(loads);
        }
        match (of(Quantity::DamperPos), &car.suspension) {
            (Some(dampers), Some(suspension)) => {
                notes.push(
                    "fz_n: static load plus wheel rate times wheel travel from the damper positions (car.toml)"
                        .into(),
                );
                let static_load_n: [f64; 4] = std::array::from_fn(|k| {
                    let w = Wheel::ALL[k];
                    let wf = car.front_weight_fraction;
                    0.5 * car.mass_kg
                        * G
                        * if w.axle() == crate::Axle::Front {
                            wf
                        } else {
                            1.0 - wf
                        }
                });
                Loads::Springs {
                    dampers,
                    suspension,
                    static_load_n,
                }
            }
            _ => {
                notes.push("fz_n: static weight, downforce and load transfer (car.toml)".into());
                Loads::Transfer
            }
        }
    }

    /// The four wheel loads (N) of sample `i`, at speed `v` (m/s) and
    /// accelerations `ax`, `ay` (m/s²).
    fn at(&self, car: &CarDescription, i: usize, v: f64, ax: f64, ay: f64) -> [f64; 4] {
        match self {
            Loads::Measured(loads) => std::array::from_fn(|k| loads[k][i]),
            Loads::Springs {
                dampers,
                suspension: s,
                static_load_n,
            } => std::array::from_fn(|k| {
                let ax_i = CarDescription::axle_of(Wheel::ALL[k]);
                // Damper travel (mm, compression positive) over the motion
                // ratio is wheel travel; the wheel rate turns it into load.
                let damper_mm = dampers[k][i] * 1e3;
                let travel_mm = (damper_mm - s.static_damper_mm[ax_i]) / s.motion_ratio[ax_i];
                (static_load_n[k] + s.wheel_rate_n_per_mm[ax_i] * travel_mm).max(50.0)
            }),
            Loads::Transfer => load_transfer(car, v, ax, ay),
        }
    }
}

/// Quasi-static wheel loads (N): static weight and downforce per axle,
/// longitudinal and lateral load transfer (the latter shared by the axles'
/// roll stiffness); at least 50 N.
fn load_transfer(car: &CarDescription, v: f64, ax: f64, ay: f64) -> [f64; 4] {
    let m = car.mass_kg;
    let (h, l, wf) = (car.cg_height_m, car.wheelbase_m, car.front_weight_fraction);
    let rho = car.aero.air_density_kg_m3;
    let df = 0.5 * rho * car.aero.cl_a_m2 * v * v;
    let long = m * ax * h / l;
    let axle = [
        m * G * wf + df * car.aero.front_fraction - long,
        m * G * (1.0 - wf) + df * (1.0 - car.aero.front_fraction) + long,
    ];
    let lat_share = [
        car.roll_stiffness_front_fraction,
        1.0 - car.roll_stiffness_front_fraction,
    ];
    std::array::from_fn(|k| {
        let w = Wheel::ALL[k];
        let ax_i = CarDescription::axle_of(w);
        let lat = lat_share[ax_i] * m * ay * h / car.track_width(w);
        // A left turn (a_y > 0) moves load to the right wheels.
        (0.5 * axle[ax_i] - w.side_sign() * lat).max(50.0)
    })
}

/// Each axle's longitudinal and lateral force (N): the driving force (mass
/// times acceleration plus drag) on the driven axles, braking shared by the
/// brake balance; the lateral force by the steady-turn yaw balance.
fn axle_forces(car: &CarDescription, v: f64, ax: f64, ay: f64) -> ([f64; 2], [f64; 2]) {
    let (m, wf) = (car.mass_kg, car.front_weight_fraction);
    let drag = 0.5 * car.aero.air_density_kg_m3 * car.aero.cd_a_m2 * v * v;
    let fx_total = m * ax + drag;
    let axle_fx = if fx_total >= 0.0 {
        match car.driven_axle {
            DrivenAxle::Rear => [0.0, fx_total],
            DrivenAxle::Front => [fx_total, 0.0],
            DrivenAxle::All => [fx_total * wf, fx_total * (1.0 - wf)],
        }
    } else {
        [
            fx_total * car.brake_front_fraction,
            fx_total * (1.0 - car.brake_front_fraction),
        ]
    };
    // Steady-turn yaw balance: the front axle carries m·a_y·b/L.
    let axle_fy = [m * ay * wf, m * ay * (1.0 - wf)];
    (axle_fx, axle_fy)
}

impl<'a> Lateral<'a> {
    /// Kinematics when the log has body slip and a steer angle (or a
    /// steering wheel and car.toml's ratio); else car.toml's tyre model.
    fn choose(
        path: &Path,
        a: &'a Aligned,
        car: &CarDescription,
        notes: &mut Vec<String>,
    ) -> Result<Lateral<'a>, ImportError> {
        let steer: Option<Vec<f64>> = match (
            a.get(Quantity::SteerAngle, None),
            a.get(Quantity::SteeringWheel, None),
        ) {
            (Some(d), _) => Some(d.to_vec()),
            (None, Some(sw)) => car
                .steering_ratio
                .map(|r| sw.iter().map(|x| x / r).collect()),
            _ => None,
        };
        let lateral = match (
            a.get(Quantity::BodySlip, None),
            steer,
            car.tyres.cornering_stiffness_per_rad,
        ) {
            (Some(body_slip_deg), Some(steer_deg), _) => Lateral::Kinematic {
                body_slip_deg,
                steer_deg,
            },
            (_, _, Some(c)) => Lateral::TyreModel {
                cornering_stiffness_per_rad: c,
            },
            _ => {
                return Err(missing(
                    path,
                    "body_slip and steer_angle (or steering_wheel with car.toml steering_ratio), or car.toml [tyres] cornering_stiffness_per_rad",
                    &[
                        Quantity::BodySlip,
                        Quantity::SteerAngle,
                        Quantity::SteeringWheel,
                    ],
                    a,
                ));
            }
        };
        notes.push(match lateral {
            Lateral::Kinematic { .. } => {
                "vy_mps: body slip angle, yaw rate and steer angle (kinematics)".into()
            }
            Lateral::TyreModel { .. } => {
                "vy_mps: lateral force / cornering stiffness (car.toml)".into()
            }
        });
        Ok(lateral)
    }

    fn method(&self) -> LateralMethod {
        match self {
            Lateral::Kinematic { .. } => LateralMethod::Kinematic,
            Lateral::TyreModel { .. } => LateralMethod::TyreModel,
        }
    }
}

impl<'a> Temperature<'a> {
    /// The `which` ("air" or "track") temperature `q` as logged, else the
    /// event's (`event_c`).
    fn of(
        path: &Path,
        a: &'a Aligned,
        q: Quantity,
        which: &str,
        event_c: Option<f64>,
        notes: &mut Vec<String>,
    ) -> Result<Temperature<'a>, ImportError> {
        if let Some(t) = a.get(q, None) {
            return Ok(Temperature::Logged(t));
        }
        notes.push(format!("t_{which}_c: the event's {which} temperature"));
        let t = event_c.ok_or_else(|| {
            missing(
                path,
                &format!("{which}_temp (and no event to take it from)"),
                &[q],
                a,
            )
        })?;
        Ok(Temperature::Event(t))
    }

    fn at(&self, i: usize) -> f64 {
        match self {
            Temperature::Logged(t) => t[i],
            Temperature::Event(t) => *t,
        }
    }
}

/// Distance (m) from the log's start: as logged, else speed integrated
/// over time (trapezoids).
fn distance_m(a: &Aligned, speed: &[f64], notes: &mut Vec<String>) -> Vec<f64> {
    match a.get(Quantity::Distance, None) {
        Some(d) => d.iter().map(|x| x - d[0]).collect(),
        None => {
            notes.push("distance_m: speed integrated over time".into());
            let n = a.len();
            let mut d = vec![0.0; n];
            for i in 1..n {
                let dt = (a.index[i] - a.index[i - 1]) as f64 / a.rate_hz;
                d[i] = d[i - 1] + 0.5 * (speed[i] + speed[i - 1]) * dt;
            }
            d
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::import::car::CarDescription;

    fn car() -> CarDescription {
        toml::from_str(include_str!("../../datasets/import/car.toml")).unwrap()
    }

    /// One sample with the given car channels and wheel speeds (m/s at the logger radius).
    fn sample(
        v: f64,
        ax: f64,
        ay: f64,
        r: f64,
        beta_deg: f64,
        steer_deg: f64,
        ws: [f64; 4],
    ) -> Aligned {
        let mut a = Aligned {
            rate_hz: 10.0,
            index: vec![0],
            ..Aligned::default()
        };
        let mut put = |q: Quantity, c: Option<Wheel>, x: f64| {
            a.series.insert((q, c), vec![x]);
        };
        put(Quantity::GroundSpeed, None, v);
        put(Quantity::AccelLong, None, ax);
        put(Quantity::AccelLat, None, ay);
        put(Quantity::YawRate, None, r);
        put(Quantity::BodySlip, None, beta_deg);
        put(Quantity::SteerAngle, None, steer_deg);
        put(Quantity::AirTemp, None, 20.0);
        put(Quantity::TrackTemp, None, 30.0);
        put(Quantity::Distance, None, 0.0);
        for w in Wheel::ALL {
            put(Quantity::WheelSpeed, Some(w), ws[w.index()]);
            put(Quantity::TyreTemp, Some(w), 90.0);
            put(Quantity::TpmsPressure, Some(w), 1.8e5);
            put(Quantity::TpmsTemp, Some(w), 95.0);
        }
        a.wheel_speed_dimension = [Some(crate::import::units::Dimension::Speed); 4];
        a
    }

    #[test]
    fn steady_left_corner_by_hand() {
        let c = car();
        // 40 m/s, 2 g to the left on a 81.5 m radius: r = a_y / v.
        let (v, ay) = (40.0, 2.0 * G);
        let r = ay / v;
        let a = sample(v, 0.0, ay, r, 0.5, 3.0, [40.0; 4]);
        let e = estimate(Path::new("x"), &a, &c, EventConditions::default(), false).unwrap();
        let t = &e.tires[0];
        let (m, h) = (798.0, 0.30);
        // Downforce 0.5·1.2·3.2·40² = 3072 N, 42 % on the front.
        let df = 0.5 * 1.2 * 3.2 * 1600.0;
        let front_axle = m * G * 0.445 + df * 0.42;
        let d_front = 0.55 * m * ay * h / 1.60;
        let fz_fl = 0.5 * front_axle - d_front;
        let fz_fr = 0.5 * front_axle + d_front;
        assert!(
            (t[0].fz_n as f64 - fz_fl).abs() < 0.01,
            "{} vs {fz_fl}",
            t[0].fz_n
        );
        assert!((t[1].fz_n as f64 - fz_fr).abs() < 0.01);
        // Front axle lateral force m·a_y·(weight on front), split by load.
        let fy_front = m * ay * 0.445;
        assert!((t[0].fy_n as f64 - fy_front * fz_fl / (fz_fl + fz_fr)).abs() < 0.01);
        assert!(((t[0].fy_n + t[1].fy_n) as f64 - fy_front).abs() < 0.01);
        // No longitudinal acceleration: drag alone, on the rear axle.
        let drag = 0.5 * 1.2 * 1.05 * 1600.0;
        assert_eq!(t[0].fx_n, 0.0);
        assert!(((t[2].fx_n + t[3].fx_n) as f64 - drag).abs() < 0.01);
        // Wheel-centre speed: the left wheels are on the inside (y = +t/2).
        assert!((t[0].vx_mps as f64 - (v - r * 0.80)).abs() < 1e-4);
        assert!((t[1].vx_mps as f64 - (v + r * 0.80)).abs() < 1e-4);
        // Lateral slip: rear tan β − b·r/v, front tan β + a·r/v − tan δ.
        let (a_cg, b_cg) = (3.60 * 0.555, 3.60 * 0.445);
        let tb = 0.5f64.to_radians().tan();
        let s_rear = tb - b_cg * r / v;
        let s_front = tb + a_cg * r / v - 3.0f64.to_radians().tan();
        assert!((t[2].vy_mps as f64 - s_rear * t[2].vx_mps as f64).abs() < 1e-5);
        assert!((t[0].vy_mps as f64 - s_front * t[0].vx_mps as f64).abs() < 1e-5);
        // Camber: static −3.2° at the front; 2 g rolls the body 0.7°, the
        // outer (right) wheel gains 0.42° of positive camber.
        let roll = 0.35 * ay / G;
        assert!((t[1].camber_deg as f64 - (-3.2 + 0.6 * roll)).abs() < 1e-5);
        assert!((t[0].camber_deg as f64 - (-3.2 - 0.6 * roll)).abs() < 1e-5);
        // Wheel speeds at the logger radius: Ω = 40 / 0.330.
        assert!((t[0].omega_radps as f64 - 40.0 / 0.330).abs() < 1e-3);
        assert!((t[0].rolling_radius_m as f64 - (0.330 - fz_fl / 600_000.0)).abs() < 1e-6);
        assert_eq!(e.lateral, Some(LateralMethod::Kinematic));
    }

    #[test]
    fn straight_line_braking_by_hand() {
        let c = car();
        let (v, ax) = (60.0, -3.0 * G);
        let a = sample(v, ax, 0.0, 0.0, 0.0, 0.0, [60.0, 60.0, 59.0, 59.0]);
        let e = estimate(Path::new("x"), &a, &c, EventConditions::default(), false).unwrap();
        let t = &e.tires[0];
        let m = 798.0;
        let drag = 0.5 * 1.2 * 1.05 * v * v;
        let fx_total = m * ax + drag;
        // Brake bias 57 % front, equal left and right on a straight.
        assert!((t[0].fx_n as f64 - 0.5 * 0.57 * fx_total).abs() < 0.05);
        assert!((t[3].fx_n as f64 - 0.5 * 0.43 * fx_total).abs() < 0.05);
        // Longitudinal load transfer m·a_x·h/L moves 1.95 kN to the front.
        let df = 0.5 * 1.2 * 3.2 * v * v;
        let long = m * ax * 0.30 / 3.60;
        let fz_front = 0.5 * (m * G * 0.445 + df * 0.42 - long);
        assert!((t[0].fz_n as f64 - fz_front).abs() < 0.05);
        assert_eq!(t[0].fy_n, 0.0);
        assert_eq!(t[0].vy_mps, 0.0);
        // Rear wheels at 59 m/s at the logger radius: Ω = 59/0.335, and the
        // loaded radius follows the hand-computed load.
        let fz_rear = 0.5 * (m * G * 0.555 + df * 0.58 + long);
        assert!((t[2].fz_n as f64 - fz_rear).abs() < 0.05);
        let omega = 59.0 / 0.335;
        let r_loaded = 0.335 - fz_rear / 600_000.0;
        assert_eq!(t[2].vx_mps, 60.0);
        assert!((t[2].omega_radps as f64 - omega).abs() < 1e-3);
        assert!((t[2].rolling_radius_m as f64 - r_loaded).abs() < 1e-6);
    }

    #[test]
    fn loads_from_damper_positions_by_hand() {
        let mut c = car();
        c.suspension = Some(crate::import::car::Suspension {
            wheel_rate_n_per_mm: [180.0, 200.0],
            motion_ratio: [0.8, 0.9],
            static_damper_mm: [40.0, 45.0],
        });
        let mut a = sample(50.0, 0.0, 10.0, 0.2, 0.0, 1.0, [50.0; 4]);
        // Dampers in m (the archive unit of length): FL 10 mm compressed,
        // RR 9 mm extended.
        for (w, mm) in [
            (Wheel::FL, 50.0),
            (Wheel::FR, 40.0),
            (Wheel::RL, 45.0),
            (Wheel::RR, 36.0),
        ] {
            a.series
                .insert((Quantity::DamperPos, Some(w)), vec![mm * 1e-3]);
        }
        let e = estimate(Path::new("x"), &a, &c, EventConditions::default(), false).unwrap();
        let t = &e.tires[0];
        let m = 798.0;
        let static_front = 0.5 * m * G * 0.445;
        let static_rear = 0.5 * m * G * 0.555;
        // 10 mm of damper / 0.8 = 12.5 mm of wheel travel × 180 N/mm = 2250 N.
        assert!((t[0].fz_n as f64 - (static_front + 2250.0)).abs() < 0.01);
        assert!((t[1].fz_n as f64 - static_front).abs() < 0.01);
        // −9 mm / 0.9 = −10 mm × 200 N/mm = −2000 N.
        assert!((t[3].fz_n as f64 - (static_rear - 2000.0)).abs() < 0.01);
        assert!(e.estimated.iter().any(|n| n.contains("damper positions")));
    }

    #[test]
    fn without_body_slip_the_tyre_model_or_a_clear_error() {
        let mut c = car();
        let mut a = sample(40.0, 0.0, 10.0, 0.25, 0.0, 0.0, [40.0; 4]);
        a.series.remove(&(Quantity::BodySlip, None));
        let e = estimate(Path::new("x"), &a, &c, EventConditions::default(), false).unwrap();
        assert_eq!(e.lateral, Some(LateralMethod::TyreModel));
        let t = &e.tires[0][0];
        // v_y/v_x = −F_y/(C·F_z) with C = 48 /rad.
        assert!((t.vy_mps / t.vx_mps + t.fy_n / (48.0 * t.fz_n)).abs() < 1e-6);
        c.tyres.cornering_stiffness_per_rad = None;
        let err = estimate(
            Path::new("log.csv"),
            &a,
            &c,
            EventConditions::default(),
            false,
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("log.csv")
                && err.contains("body_slip")
                && err.contains("cornering_stiffness"),
            "{err}"
        );
    }
}
