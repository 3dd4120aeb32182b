//! The vehicle description (`car.toml`) the virtual sensors need
//! (`docs/import.md`, "Vehicle description").

use super::error::ImportError;
use crate::{Axle, Wheel};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Which axle drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DrivenAxle {
    Front,
    Rear,
    /// Four-wheel drive: drive force split by the static weight distribution.
    All,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Aero {
    /// Downforce coefficient × frontal area, C_L·A (m²).
    pub cl_a_m2: f64,
    /// Drag coefficient × frontal area, C_D·A (m²).
    pub cd_a_m2: f64,
    /// Share of the downforce on the front axle.
    pub front_fraction: f64,
    #[serde(default = "default_air_density")]
    pub air_density_kg_m3: f64,
}

fn default_air_density() -> f64 {
    1.2
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tyres {
    /// Unloaded pure rolling radius, front and rear (m).
    pub rolling_radius_m: [f64; 2],
    /// Loaded radius `R = R0 − F_z/k` (N/m); absent: R = R0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radial_stiffness_n_per_m: Option<f64>,
    /// The radius the logger turns wheel revolutions into a wheel speed
    /// with, front and rear (m); absent: `rolling_radius_m`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wheel_speed_radius_m: Option<[f64; 2]>,
    /// Cornering stiffness per unit load, front and rear (1/rad): the
    /// lateral slip `v_y/v_x = −F_y/(C·F_z)` when the log has no body slip
    /// angle and steering angle.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cornering_stiffness_per_rad: Option<[f64; 2]>,
    /// Hot gauge pressure, front and rear (kPa), taken when the log has no
    /// TPMS pressure (marked as estimated).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pressure_kpa: Option<[f64; 2]>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camber {
    /// Static camber, front and rear (deg; negative: top of the wheel inwards).
    pub static_deg: [f64; 2],
    /// Body roll per g of lateral acceleration (deg/g).
    pub roll_gradient_deg_per_g: f64,
    /// Camber change of a wheel per degree of roll.
    pub change_per_roll: f64,
}

/// Springs, for loads from damper positions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Suspension {
    /// Wheel rate, front and rear (N/mm): vertical force at the tyre per mm
    /// of wheel travel (spring through its motion ratio, in series with
    /// nothing else).
    pub wheel_rate_n_per_mm: [f64; 2],
    /// Damper travel per wheel travel, front and rear.
    pub motion_ratio: [f64; 2],
    /// Damper position with the car at rest on the set-up pad (mm), front and rear.
    pub static_damper_mm: [f64; 2],
}

/// `car.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CarDescription {
    /// The car's id in the season manifest.
    pub id: String,
    #[serde(default)]
    pub name: String,
    /// Mass with driver (kg).
    pub mass_kg: f64,
    /// Static weight on the front axle (fraction).
    pub front_weight_fraction: f64,
    pub cg_height_m: f64,
    pub wheelbase_m: f64,
    pub front_track_m: f64,
    pub rear_track_m: f64,
    pub driven_axle: DrivenAxle,
    /// Share of the braking force on the front axle.
    pub brake_front_fraction: f64,
    /// Share of the roll stiffness on the front axle (splits lateral load transfer).
    pub roll_stiffness_front_fraction: f64,
    /// Steering-wheel angle per road-wheel angle.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub steering_ratio: Option<f64>,
    pub aero: Aero,
    pub tyres: Tyres,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camber: Option<Camber>,
    /// With damper-position channels, loads come from the springs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub suspension: Option<Suspension>,
}

impl CarDescription {
    pub fn read(path: &Path) -> Result<Self, ImportError> {
        let text = std::fs::read_to_string(path).map_err(|e| ImportError::io(path, e))?;
        let car: CarDescription = toml::from_str(&text).map_err(|e| ImportError::Car {
            path: path.to_path_buf(),
            what: e.to_string(),
        })?;
        car.check().map_err(|what| ImportError::Car {
            path: path.to_path_buf(),
            what,
        })?;
        Ok(car)
    }

    /// Ranges a real car is in; a typo (a track width in mm) is refused.
    pub fn check(&self) -> Result<(), String> {
        let range = |name: &str, v: f64, lo: f64, hi: f64| {
            if v.is_finite() && v >= lo && v <= hi {
                Ok(())
            } else {
                Err(format!(
                    "{name} = {} is outside [{lo}, {hi}]",
                    super::shown(v)
                ))
            }
        };
        if self.id.trim().is_empty() {
            return Err("id is empty".into());
        }
        range("mass_kg", self.mass_kg, 50.0, 10_000.0)?;
        range(
            "front_weight_fraction",
            self.front_weight_fraction,
            0.05,
            0.95,
        )?;
        range("cg_height_m", self.cg_height_m, 0.05, 3.0)?;
        range("wheelbase_m", self.wheelbase_m, 0.5, 10.0)?;
        range("front_track_m", self.front_track_m, 0.3, 5.0)?;
        range("rear_track_m", self.rear_track_m, 0.3, 5.0)?;
        range("brake_front_fraction", self.brake_front_fraction, 0.0, 1.0)?;
        range(
            "roll_stiffness_front_fraction",
            self.roll_stiffness_front_fraction,
            0.0,
            1.0,
        )?;
        if let Some(r) = self.steering_ratio {
            range("steering_ratio", r, 1.0, 50.0)?;
        }
        range("aero.cl_a_m2", self.aero.cl_a_m2, -2.0, 20.0)?;
        range("aero.cd_a_m2", self.aero.cd_a_m2, 0.0, 10.0)?;
        range("aero.front_fraction", self.aero.front_fraction, 0.0, 1.0)?;
        range(
            "aero.air_density_kg_m3",
            self.aero.air_density_kg_m3,
            0.5,
            2.0,
        )?;
        for r in self.tyres.rolling_radius_m {
            range("tyres.rolling_radius_m", r, 0.1, 1.5)?;
        }
        if let Some(k) = self.tyres.radial_stiffness_n_per_m {
            range("tyres.radial_stiffness_n_per_m", k, 1e4, 1e8)?;
        }
        if let Some(rs) = self.tyres.wheel_speed_radius_m {
            for r in rs {
                range("tyres.wheel_speed_radius_m", r, 0.1, 1.5)?;
            }
        }
        if let Some(cs) = self.tyres.cornering_stiffness_per_rad {
            for c in cs {
                range("tyres.cornering_stiffness_per_rad", c, 1.0, 500.0)?;
            }
        }
        if let Some(ps) = self.tyres.pressure_kpa {
            for p in ps {
                range("tyres.pressure_kpa", p, 20.0, 1000.0)?;
            }
        }
        if let Some(c) = &self.camber {
            for s in c.static_deg {
                range("camber.static_deg", s, -15.0, 15.0)?;
            }
            range(
                "camber.roll_gradient_deg_per_g",
                c.roll_gradient_deg_per_g,
                0.0,
                10.0,
            )?;
            range("camber.change_per_roll", c.change_per_roll, -5.0, 5.0)?;
        }
        if let Some(s) = &self.suspension {
            for k in s.wheel_rate_n_per_mm {
                range("suspension.wheel_rate_n_per_mm", k, 1.0, 10_000.0)?;
            }
            for m in s.motion_ratio {
                range("suspension.motion_ratio", m, 0.1, 5.0)?;
            }
            for x in s.static_damper_mm {
                range("suspension.static_damper_mm", x, -1000.0, 1000.0)?;
            }
        }
        Ok(())
    }

    fn axle_index(w: Wheel) -> usize {
        match w.axle() {
            Axle::Front => 0,
            Axle::Rear => 1,
        }
    }

    pub(crate) fn track_width(&self, w: Wheel) -> f64 {
        [self.front_track_m, self.rear_track_m][Self::axle_index(w)]
    }

    pub(crate) fn rolling_radius(&self, w: Wheel) -> f64 {
        self.tyres.rolling_radius_m[Self::axle_index(w)]
    }

    pub(crate) fn wheel_speed_radius(&self, w: Wheel) -> f64 {
        self.tyres
            .wheel_speed_radius_m
            .unwrap_or(self.tyres.rolling_radius_m)[Self::axle_index(w)]
    }

    /// Loaded rolling radius (m) under `fz` (N).
    pub(crate) fn loaded_radius(&self, w: Wheel, fz: f64) -> f64 {
        let r0 = self.rolling_radius(w);
        match self.tyres.radial_stiffness_n_per_m {
            Some(k) => r0 - fz / k,
            None => r0,
        }
    }

    /// Distance from the centre of gravity to the front axle, `a` (m).
    pub(crate) fn cg_to_front_m(&self) -> f64 {
        self.wheelbase_m * (1.0 - self.front_weight_fraction)
    }

    /// Distance from the centre of gravity to the rear axle, `b` (m).
    pub(crate) fn cg_to_rear_m(&self) -> f64 {
        self.wheelbase_m * self.front_weight_fraction
    }

    pub(crate) fn axle_of(w: Wheel) -> usize {
        Self::axle_index(w)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn example() -> CarDescription {
        toml::from_str(include_str!("../../datasets/import/car.toml")).expect("valid example")
    }

    #[test]
    fn the_shipped_example_is_valid_and_a_typo_is_refused() {
        let car = example();
        car.check().unwrap();
        assert!((car.cg_to_front_m() + car.cg_to_rear_m() - car.wheelbase_m).abs() < 1e-12);
        let mut bad = car.clone();
        bad.front_track_m = 1600.0;
        assert!(bad.check().unwrap_err().contains("front_track_m"));
        let e = toml::from_str::<CarDescription>("id = \"x\"\nmass = 3").unwrap_err();
        assert!(e.to_string().contains("mass"), "{e}");
    }
}
