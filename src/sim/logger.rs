//! The simulator's logger export (`simulate --logger-export`): each run as a
//! race logger would have recorded it, as a MoTeC CSV export or a MoTeC
//! `.ld` file, with only the channels real loggers have (speed,
//! accelerations, yaw rate, body slip angle from an optical sensor, steering,
//! wheel speeds, IR tyre temperatures in three zones, TPMS), plus a
//! `car.toml` per car. Importing it (`tirewear import`) and extracting it
//! checks the importer's virtual sensors against the full-channel archive
//! (`docs/import.md`, "Accuracy").
//!
//! Body slip and steering are what a rigid car would show for the wheels'
//! simulated lateral slips: with `a`, `b` the distances from the centre of
//! gravity to the axles and `r` the yaw rate, the axle-mean slips satisfy
//! `s_rear = tan β − b·r/v` and `s_front = tan β + a·r/v − tan δ`.

use super::run::Motion;
use super::vehicle::CarParams;
use crate::Wheel;
use crate::import::car::{Aero, Camber, CarDescription, DrivenAxle, Tyres};
use crate::import::ld::{LdChannel, LdHeader, write_ld};
use crate::import::units::STANDARD_GRAVITY;
use crate::ingest::telemetry::proto::{TireSample, VehicleSample};
use rand::Rng;
use rand_distr::{Distribution, Normal};
use std::io::Write;
use std::path::Path;

/// The file format of the export.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LoggerFormat {
    /// MoTeC CSV export (`logger/<run>.csv`), one rate, dropouts as gaps.
    MotecCsv,
    /// MoTeC `.ld` (`logger/<run>.ld`): tyre temperatures at half and TPMS
    /// at a quarter of the rate; dropouts bridged by interpolation.
    MotecLd,
}

/// Steering-wheel angle per road-wheel angle of the simulated cars.
pub const STEERING_RATIO: f64 = 12.0;

/// Zone temperature spread (K per degree of camber): the inner shoulder of a
/// wheel with negative camber runs hotter; the zones average to the surface
/// temperature.
const ZONE_SPREAD_K_PER_DEG: f64 = 1.5;

/// The simulated cars' springs, for the damper-position channels: wheel
/// rate (N/mm), motion ratio and static damper position (mm), front and rear.
pub const WHEEL_RATE_N_PER_MM: [f64; 2] = [180.0, 200.0];
pub const MOTION_RATIO: [f64; 2] = [0.8, 0.9];
pub const STATIC_DAMPER_MM: [f64; 2] = [40.0, 45.0];

/// Channel: name, short name, unit, decimals, rate divisor (`.ld`).
struct Spec(&'static str, &'static str, &'static str, i16, u16);

/// The export's channels, in column order. Spellings differ between corners
/// on purpose (`Centre`/`Center`), as they do in real logs.
fn specs() -> Vec<Spec> {
    let mut v = vec![
        Spec("Ground Speed", "GndSpd", "km/h", 3, 1),
        Spec("G Force Long", "GLong", "G", 4, 1),
        Spec("G Force Lat", "GLat", "G", 4, 1),
        Spec("Yaw Rate", "Yaw", "deg/s", 3, 1),
        Spec("Body Slip Angle", "Slip", "deg", 4, 1),
        Spec("Steering Angle", "Steer", "deg", 3, 1),
        Spec("Distance", "Dist", "m", 2, 1),
        Spec("Air Temp", "AirT", "C", 2, 1),
        Spec("Track Temp", "TrkT", "C", 2, 1),
    ];
    for (w, centre) in [
        ("FL", "Centre"),
        ("FR", "Center"),
        ("RL", "Centre"),
        ("RR", "Center"),
    ] {
        let s = |x: String| -> &'static str { Box::leak(x.into_boxed_str()) };
        v.push(Spec(
            s(format!("Wheel Speed {w}")),
            s(format!("WSpd{w}")),
            "km/h",
            3,
            1,
        ));
        for zone in ["Inner", centre, "Outer"] {
            v.push(Spec(
                s(format!("Tyre Temp {w} {zone}")),
                s(format!("TT{w}{}", &zone[..1])),
                "C",
                2,
                2,
            ));
        }
        v.push(Spec(
            s(format!("TPMS Pressure {w}")),
            s(format!("TPP{w}")),
            "bar",
            4,
            4,
        ));
        v.push(Spec(
            s(format!("TPMS Temp {w}")),
            s(format!("TPT{w}")),
            "C",
            2,
            4,
        ));
        v.push(Spec(
            s(format!("Damper Pos {w}")),
            s(format!("Dmp{w}")),
            "mm",
            3,
            1,
        ));
    }
    v
}

/// Sensor noise of the logger-only channels (standard deviations).
struct Noise {
    accel_g: Normal<f64>,
    yaw_degps: Normal<f64>,
    slip_deg: Normal<f64>,
    steer_deg: Normal<f64>,
}

/// One run's logger channels, recorded sample by sample.
pub(crate) struct Recorder {
    car: CarParams,
    noise: Noise,
    times_ns: Vec<u64>,
    rows: Vec<f64>,
    width: usize,
    /// Each wheel's load at rest (N): the springs' zero.
    static_load: [f64; 4],
}

impl Recorder {
    pub fn new(car: &CarParams, sensor_noise: bool) -> Self {
        let k = if sensor_noise { 1.0 } else { 0.0 };
        let n = |sd: f64| Normal::new(0.0, sd * k).expect("non-negative sd");
        Recorder {
            car: car.clone(),
            noise: Noise {
                accel_g: n(0.01),
                yaw_degps: n(0.1),
                slip_deg: n(0.05),
                steer_deg: n(0.2),
            },
            times_ns: Vec::new(),
            rows: Vec::new(),
            width: specs().len(),
            static_load: std::array::from_fn(|k| {
                let front = car.front_weight_fraction;
                let share = if k < 2 { front } else { 1.0 - front };
                0.5 * car.mass_kg * STANDARD_GRAVITY * share
            }),
        }
    }

    /// Records one sample from the archive's (noisy) channels and the
    /// noise-free motion; `rng` is the export's own (the archive does not
    /// change when an export is asked for).
    pub fn push(
        &mut self,
        t_ns: u64,
        tires: &[TireSample; 4],
        veh: &VehicleSample,
        m: &Motion,
        rng: &mut impl Rng,
    ) {
        let car = &self.car;
        let v = (veh.speed_mps as f64).max(1.0);
        let a = car.wheelbase_m * (1.0 - car.front_weight_fraction);
        let b = car.wheelbase_m * car.front_weight_fraction;
        let r = m.yaw_rate_radps;
        let s_front = 0.5 * (m.slip_y[0] + m.slip_y[1]);
        let s_rear = 0.5 * (m.slip_y[2] + m.slip_y[3]);
        let tan_beta = s_rear + b * r / v;
        let tan_delta = tan_beta + a * r / v - s_front;
        let mut row = vec![
            veh.speed_mps as f64 * 3.6,
            m.ax_mps2 / STANDARD_GRAVITY + self.noise.accel_g.sample(rng),
            m.ay_mps2 / STANDARD_GRAVITY + self.noise.accel_g.sample(rng),
            r.to_degrees() + self.noise.yaw_degps.sample(rng),
            tan_beta.atan().to_degrees() + self.noise.slip_deg.sample(rng),
            STEERING_RATIO * tan_delta.atan().to_degrees() + self.noise.steer_deg.sample(rng),
            veh.distance_m,
            veh.t_air_c as f64,
            veh.t_track_c as f64,
        ];
        for w in Wheel::ALL {
            let t = &tires[w.index()];
            let spread = ZONE_SPREAD_K_PER_DEG * (t.camber_deg as f64).abs();
            let ts = t.t_surface_c as f64;
            row.push(t.omega_radps as f64 * car.rolling_radius(w) * 3.6);
            row.extend([ts + spread, ts, ts - spread]);
            row.push(t.pressure_pa as f64 / 1e5);
            row.push(t.t_inner_c as f64);
            // The spring's compression for the (noisy) load above its static value.
            let a = match w.axle() {
                crate::Axle::Front => 0,
                crate::Axle::Rear => 1,
            };
            let travel_mm = (t.fz_n as f64 - self.static_load[w.index()]) / WHEEL_RATE_N_PER_MM[a];
            row.push(STATIC_DAMPER_MM[a] + MOTION_RATIO[a] * travel_mm);
        }
        debug_assert_eq!(row.len(), self.width);
        self.times_ns.push(t_ns);
        self.rows.extend(row);
    }

    /// Writes the export of the run.
    pub fn write(
        &self,
        path: &Path,
        format: LoggerFormat,
        info: &ExportInfo,
    ) -> std::io::Result<()> {
        match format {
            LoggerFormat::MotecCsv => self.write_csv(path, info),
            LoggerFormat::MotecLd => self.write_ld(path, info),
        }
    }

    fn write_csv(&self, path: &Path, info: &ExportInfo) -> std::io::Result<()> {
        let specs = specs();
        let mut out = crate::atomic::AtomicFile::create(path)?;
        let mut f = std::io::BufWriter::with_capacity(1 << 20, out.file().try_clone()?);
        let start = self.times_ns.first().copied().unwrap_or(0);
        let end_s = self
            .times_ns
            .last()
            .map_or(0.0, |t| (t - start) as f64 / 1e9);
        let date = info.dmy();
        let hdr = [
            (
                "Format",
                "MoTeC CSV File".to_string(),
                "Workbook",
                "tirewear simulate".to_string(),
            ),
            (
                "Venue",
                info.venue.clone(),
                "Worksheet",
                "logger export".to_string(),
            ),
            (
                "Vehicle",
                info.vehicle.clone(),
                "Vehicle Desc",
                info.vehicle_desc.clone(),
            ),
            (
                "Driver",
                "Sim Driver".to_string(),
                "Engine ID",
                String::new(),
            ),
            ("Device", "tirewear".to_string(), "Date", date.clone()),
            ("Comment", info.run.clone(), "Time", "12:00:00".to_string()),
            ("Log Date", date, "Origin Time", "0.000".to_string()),
            (
                "Log Time",
                "12:00:00".to_string(),
                "Start Time",
                "0.000".to_string(),
            ),
            (
                "Sample Rate",
                format!("{:.3}", info.rate_hz),
                "End Time",
                format!("{end_s:.3}"),
            ),
            (
                "Session",
                info.run.clone(),
                "Duration",
                format!("{end_s:.3}"),
            ),
        ];
        for (k1, v1, k2, v2) in hdr {
            writeln!(f, "\"{k1}\",\"{v1}\",\"\",\"\",\"{k2}\",\"{v2}\"")?;
        }
        writeln!(f)?;
        writeln!(f)?;
        let names: Vec<String> = specs.iter().map(|s| format!("\"{}\"", s.0)).collect();
        let units: Vec<String> = specs.iter().map(|s| format!("\"{}\"", s.2)).collect();
        writeln!(f, "\"Time\",{}", names.join(","))?;
        writeln!(f, "\"s\",{}", units.join(","))?;
        writeln!(f)?;
        writeln!(f)?;
        for (i, t) in self.times_ns.iter().enumerate() {
            write!(f, "\"{:.3}\"", (t - start) as f64 / 1e9)?;
            for (s, v) in specs
                .iter()
                .zip(&self.rows[i * self.width..(i + 1) * self.width])
            {
                write!(f, ",\"{:.*}\"", s.3 as usize, v)?;
            }
            writeln!(f)?;
        }
        f.flush()?;
        drop(f);
        out.commit()
    }

    fn write_ld(&self, path: &Path, info: &ExportInfo) -> std::io::Result<()> {
        let specs = specs();
        let start = self.times_ns.first().copied().unwrap_or(0);
        let period = 1e9 / info.rate_hz;
        // Every grid point from the first to the last sample; a dropout is
        // bridged linearly (an .ld channel has no gaps).
        let n = self
            .times_ns
            .last()
            .map_or(0, |t| ((t - start) as f64 / period).round() as usize + 1);
        let mut grid = vec![vec![0.0; n]; self.width];
        let k_of = |i: usize| ((self.times_ns[i] - start) as f64 / period).round() as usize;
        for i in 0..self.times_ns.len() {
            let (k0, row0) = (k_of(i), &self.rows[i * self.width..(i + 1) * self.width]);
            let (k1, row1) = match i + 1 < self.times_ns.len() {
                true => (
                    k_of(i + 1),
                    &self.rows[(i + 1) * self.width..(i + 2) * self.width],
                ),
                false => (k0 + 1, row0),
            };
            for k in k0..k1.min(n) {
                let w = (k - k0) as f64 / (k1 - k0) as f64;
                for (c, g) in grid.iter_mut().enumerate() {
                    g[k] = row0[c] * (1.0 - w) + row1[c] * w;
                }
            }
        }
        let rate = info.rate_hz.round() as u16;
        let decimated: Vec<Vec<f64>> = specs
            .iter()
            .zip(&grid)
            .map(|(s, g)| g.iter().step_by(s.4 as usize).copied().collect())
            .collect();
        let channels: Vec<LdChannel> = specs
            .iter()
            .zip(&decimated)
            .map(|(s, values)| LdChannel {
                name: s.0,
                short_name: s.1,
                unit: s.2,
                rate_hz: (rate / s.4).max(1),
                dec_places: s.3,
                values,
            })
            .collect();
        let date = info.dmy();
        let header = LdHeader {
            date: &date,
            time: "12:00:00",
            driver: "Sim Driver",
            vehicle: &info.vehicle,
            venue: &info.venue,
            session: &info.run,
            comment: "tirewear simulate logger export",
        };
        write_ld(path, &header, &channels).map_err(std::io::Error::other)
    }
}

/// Header facts of one run's export.
pub(crate) struct ExportInfo {
    pub run: String,
    pub venue: String,
    pub vehicle: String,
    pub vehicle_desc: String,
    /// `YYYY-MM-DD`.
    pub date: String,
    pub rate_hz: f64,
}

impl ExportInfo {
    fn dmy(&self) -> String {
        let p: Vec<&str> = self.date.split('-').collect();
        match p.as_slice() {
            [y, m, d] => format!("{d}/{m}/{y}"),
            _ => self.date.clone(),
        }
    }
}

/// The `car.toml` of a simulated car: its exact parameters (the importer's
/// loads and forces follow the same quasi-static model as the simulator's).
pub(crate) fn car_description(car: &CarParams) -> CarDescription {
    CarDescription {
        id: car.id.clone(),
        name: car.name.clone(),
        mass_kg: car.mass_kg,
        front_weight_fraction: car.front_weight_fraction,
        cg_height_m: car.cg_height_m,
        wheelbase_m: car.wheelbase_m,
        front_track_m: car.front_track_m,
        rear_track_m: car.rear_track_m,
        driven_axle: DrivenAxle::Rear,
        brake_front_fraction: car.brake_front_fraction,
        roll_stiffness_front_fraction: car.roll_stiffness_front_fraction,
        steering_ratio: Some(STEERING_RATIO),
        aero: Aero {
            cl_a_m2: car.cl_a_m2,
            cd_a_m2: car.cd_a_m2,
            front_fraction: car.aero_front_fraction,
            air_density_kg_m3: super::vehicle::AIR_DENSITY,
        },
        tyres: Tyres {
            rolling_radius_m: car.rolling_radius_m,
            radial_stiffness_n_per_m: Some(super::run::RADIAL_STIFFNESS_N_PER_M),
            wheel_speed_radius_m: Some(car.rolling_radius_m),
            // Slope of the simulator's normalised Magic Formula at zero
            // slip (B·C = 27.2) times a typical peak friction of 1.8.
            cornering_stiffness_per_rad: Some([49.0, 49.0]),
            pressure_kpa: None,
        },
        camber: Some(Camber {
            static_deg: car.static_camber_deg,
            roll_gradient_deg_per_g: car.roll_gradient_deg_per_g,
            change_per_roll: car.camber_per_roll,
        }),
        suspension: Some(crate::import::car::Suspension {
            wheel_rate_n_per_mm: WHEEL_RATE_N_PER_MM,
            motion_ratio: MOTION_RATIO,
            static_damper_mm: STATIC_DAMPER_MM,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// The CSV export reads back to the precision it stores (its decimals).
    #[test]
    fn csv_export_round_trips_to_its_decimals() {
        let car = CarParams::single_seater("car1", "Car #1", 0.0);
        let mut rec = Recorder::new(&car, true);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        for i in 0..30u64 {
            let x = i as f32;
            let tire = TireSample {
                vx_mps: 50.0 + x,
                vy_mps: -0.3,
                omega_radps: 150.0 + 0.37 * x,
                rolling_radius_m: 0.32,
                fx_n: 0.0,
                fy_n: 0.0,
                fz_n: 4000.0,
                t_surface_c: 90.0 + 0.123 * x,
                t_inner_c: 95.0,
                pressure_pa: 180_000.0 + 17.0 * x,
                camber_deg: -3.0,
            };
            let veh = VehicleSample {
                speed_mps: 50.0 + x,
                t_track_c: 30.0,
                t_air_c: 20.0,
                distance_m: 50.0 * i as f64,
            };
            let m = Motion {
                ax_mps2: 1.0,
                ay_mps2: 5.0,
                yaw_rate_radps: 0.1,
                slip_y: [-0.02, -0.021, -0.015, -0.016],
            };
            // Two dropped samples (10 and 11): a gap in the time column.
            if i != 10 && i != 11 {
                rec.push(
                    1_000_000_000 + i * 50_000_000,
                    &[tire; 4],
                    &veh,
                    &m,
                    &mut rng,
                );
            }
        }
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.csv");
        let info = ExportInfo {
            run: "r".into(),
            venue: "V".into(),
            vehicle: "car1".into(),
            vehicle_desc: "Car #1".into(),
            date: "2026-03-02".into(),
            rate_hz: 20.0,
        };
        rec.write(&p, LoggerFormat::MotecCsv, &info).unwrap();
        let log = crate::import::log::read_csv(&p).unwrap();
        assert_eq!(log.meta.format, "MoTeC CSV");
        assert_eq!(log.meta.date.as_deref(), Some("2026-03-02"));
        let time = &log.channels[0].values;
        assert_eq!(time.len(), 28);
        assert!(
            (time[10] - 0.6).abs() < 1e-12,
            "the gap is kept: {}",
            time[10]
        );
        for (c, spec) in log.channels[1..].iter().zip(specs()) {
            assert_eq!(c.name, spec.0);
            assert_eq!(c.unit, spec.2);
            let half = 0.5 * 10f64.powi(-(spec.3 as i32)) + 1e-9;
            let col = specs().iter().position(|s| s.0 == spec.0).unwrap();
            for (k, v) in c.values.iter().enumerate() {
                let want = rec.rows[k * rec.width + col];
                assert!((v - want).abs() <= half, "{}: {v} vs {want}", spec.0);
            }
        }
    }
}
