//! The single-seater: mass, geometry, aerodynamics, power; wheel loads from
//! static weight, downforce and longitudinal/lateral load transfer; wheel
//! forces from the vehicle's accelerations. Axes are ISO 8855 (x forward,
//! y left, z up); a positive lateral acceleration is a left turn.

use crate::Wheel;

pub(crate) const G: f64 = 9.81;
pub(crate) const AIR_DENSITY: f64 = 1.2;

#[derive(Debug, Clone, PartialEq)]
pub struct CarParams {
    pub id: String,
    pub name: String,
    /// Mass with driver (kg).
    pub mass_kg: f64,
    /// Static weight on the front axle (fraction).
    pub front_weight_fraction: f64,
    pub cg_height_m: f64,
    pub wheelbase_m: f64,
    pub front_track_m: f64,
    pub rear_track_m: f64,
    /// Downforce coefficient times area, C_L·A (m²).
    pub cl_a_m2: f64,
    /// Drag coefficient times area, C_D·A (m²).
    pub cd_a_m2: f64,
    /// Share of downforce on the front axle.
    pub aero_front_fraction: f64,
    pub power_w: f64,
    /// Share of braking force on the front axle.
    pub brake_front_fraction: f64,
    /// Share of roll stiffness on the front axle (splits lateral load transfer).
    pub roll_stiffness_front_fraction: f64,
    /// Body roll per g of lateral acceleration (deg/g).
    pub roll_gradient_deg_per_g: f64,
    /// Static camber, front and rear (deg, negative = top leaning inwards).
    pub static_camber_deg: [f64; 2],
    /// Camber change of a wheel per degree of body roll.
    pub camber_per_roll: f64,
    /// Pure rolling radius, front and rear (m).
    pub rolling_radius_m: [f64; 2],
    /// Tread width, front and rear (mm).
    pub tread_width_mm: [f64; 2],
}

/// Forces on one tire from the road (N), ISO axes.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct WheelForces {
    pub fx: f64,
    pub fy: f64,
    pub fz: f64,
}

impl CarParams {
    /// The reference single-seater; `variant` gives the cars of a team small differences.
    pub(crate) fn single_seater(id: &str, name: &str, variant: f64) -> Self {
        CarParams {
            id: id.into(),
            name: name.into(),
            mass_kg: 798.0 + 12.0 * variant,
            front_weight_fraction: 0.445 + 0.01 * variant,
            cg_height_m: 0.30,
            wheelbase_m: 3.60,
            front_track_m: 1.60,
            rear_track_m: 1.55,
            cl_a_m2: 3.2 + 0.2 * variant,
            cd_a_m2: 1.05,
            aero_front_fraction: 0.42,
            power_w: 620e3,
            brake_front_fraction: 0.57,
            roll_stiffness_front_fraction: 0.55,
            roll_gradient_deg_per_g: 0.35,
            static_camber_deg: [-3.2, -1.9],
            camber_per_roll: 0.6,
            rolling_radius_m: [0.330, 0.335],
            tread_width_mm: [300.0, 380.0],
        }
    }

    fn axle(w: Wheel) -> usize {
        match w.axle() {
            crate::Axle::Front => 0,
            crate::Axle::Rear => 1,
        }
    }

    pub(crate) fn rolling_radius(&self, w: Wheel) -> f64 {
        self.rolling_radius_m[Self::axle(w)]
    }

    pub(crate) fn tread_width(&self, w: Wheel) -> f64 {
        self.tread_width_mm[Self::axle(w)]
    }

    pub(crate) fn track_width(&self, w: Wheel) -> f64 {
        [self.front_track_m, self.rear_track_m][Self::axle(w)]
    }

    pub(crate) fn downforce(&self, v: f64) -> f64 {
        0.5 * AIR_DENSITY * self.cl_a_m2 * v * v
    }

    pub(crate) fn drag(&self, v: f64) -> f64 {
        0.5 * AIR_DENSITY * self.cd_a_m2 * v * v
    }

    /// Vertical loads (N) at speed `v` with accelerations `ax`, `ay` (m/s²):
    /// static weight and downforce split by axle, longitudinal transfer
    /// `m·ax·h/L` and lateral transfer `m·ay·h/t` split by roll stiffness.
    pub(crate) fn wheel_loads(&self, v: f64, ax: f64, ay: f64) -> [f64; 4] {
        let m = self.mass_kg;
        let df = self.downforce(v);
        let axle_static = [
            m * G * self.front_weight_fraction + df * self.aero_front_fraction,
            m * G * (1.0 - self.front_weight_fraction) + df * (1.0 - self.aero_front_fraction),
        ];
        let long = m * ax * self.cg_height_m / self.wheelbase_m;
        let axle = [axle_static[0] - long, axle_static[1] + long];
        let lat_share = [
            self.roll_stiffness_front_fraction,
            1.0 - self.roll_stiffness_front_fraction,
        ];
        let mut fz = [0.0; 4];
        for w in Wheel::ALL {
            let a = Self::axle(w);
            let lat = lat_share[a] * m * ay * self.cg_height_m / self.track_width(w);
            // Left turn (ay > 0): load moves to the right wheels.
            fz[w.index()] = (0.5 * axle[a] - w.side_sign() * lat).max(50.0);
        }
        fz
    }

    /// Tire forces needed for the accelerations: total longitudinal force
    /// `m·ax + drag` to the rear axle when driving and by brake balance when
    /// braking; lateral force per axle from the yaw-moment balance of a
    /// steady turn (`m·ay·b/L` front). On each axle both forces are split
    /// between the wheels by load (limited-slip differential, brakes that
    /// the driver modulates to the available grip).
    pub(crate) fn wheel_forces(&self, v: f64, ax: f64, ay: f64) -> [WheelForces; 4] {
        let m = self.mass_kg;
        let fz = self.wheel_loads(v, ax, ay);
        let fx_total = m * ax + self.drag(v);
        let axle_fx = if fx_total >= 0.0 {
            [0.0, fx_total]
        } else {
            [
                fx_total * self.brake_front_fraction,
                fx_total * (1.0 - self.brake_front_fraction),
            ]
        };
        let axle_fy = [
            m * ay * self.front_weight_fraction,
            m * ay * (1.0 - self.front_weight_fraction),
        ];
        let mut out = [WheelForces::default(); 4];
        for w in Wheel::ALL {
            let a = Self::axle(w);
            let (l, r) = match a {
                0 => (fz[Wheel::FL.index()], fz[Wheel::FR.index()]),
                _ => (fz[Wheel::RL.index()], fz[Wheel::RR.index()]),
            };
            let share = fz[w.index()] / (l + r);
            out[w.index()] = WheelForces {
                fx: axle_fx[a] * share,
                fy: axle_fy[a] * share,
                fz: fz[w.index()],
            };
        }
        out
    }

    /// Body roll (deg) at lateral acceleration `ay`; positive rolls to the right (outward in a left turn).
    pub(crate) fn roll_deg(&self, ay: f64) -> f64 {
        self.roll_gradient_deg_per_g * ay / G
    }

    /// Dynamic camber (deg): static camber plus the roll-induced change; in a
    /// left turn the outer (right) wheels lose negative camber.
    pub fn camber_deg(&self, w: Wheel, ay: f64) -> f64 {
        self.static_camber_deg[Self::axle(w)]
            - w.side_sign() * self.camber_per_roll * self.roll_deg(ay)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steady_corner_lateral_load_transfer_by_hand() {
        let car = CarParams::single_seater("c", "c", 0.0);
        // Steady left turn at 2 g, v = 0 (no aero) for a clean hand calculation.
        let ay = 2.0 * G;
        let fz = car.wheel_loads(0.0, 0.0, ay);
        let m = car.mass_kg;
        // Front: rsf * m * ay * h / t_f = 0.55 * 798 * 19.62 * 0.30 / 1.60 = 1614.6 N
        let d_front = 0.55 * m * ay * 0.30 / 1.60;
        assert!((d_front - 1614.6).abs() < 0.1);
        let static_front_wheel = 0.5 * m * G * 0.445;
        assert!((fz[Wheel::FR.index()] - (static_front_wheel + d_front)).abs() < 1e-9);
        assert!((fz[Wheel::FL.index()] - (static_front_wheel - d_front)).abs() < 1e-9);
        // Total lateral moment balance: sum of transfers times track = m*ay*h.
        let d_rear = fz[Wheel::RR.index()] - 0.5 * m * G * (1.0 - 0.445);
        assert!((d_front * 1.60 + d_rear * 1.55 - m * ay * 0.30).abs() < 1e-6);
        // Loads still add up to the weight.
        assert!((fz.iter().sum::<f64>() - m * G).abs() < 1e-9);
    }

    #[test]
    fn forces_balance_the_accelerations() {
        let car = CarParams::single_seater("c", "c", 0.0);
        let (v, ax, ay) = (55.0, -12.0, 15.0);
        let f = car.wheel_forces(v, ax, ay);
        let fx: f64 = f.iter().map(|w| w.fx).sum();
        let fy: f64 = f.iter().map(|w| w.fy).sum();
        let fz: f64 = f.iter().map(|w| w.fz).sum();
        assert!((fx - (car.mass_kg * ax + car.drag(v))).abs() < 1e-9);
        assert!((fy - car.mass_kg * ay).abs() < 1e-9);
        assert!((fz - (car.mass_kg * G + car.downforce(v))).abs() < 1e-6);
        // Yaw moment of the lateral forces about the centre of gravity is zero.
        let a = car.wheelbase_m * (1.0 - car.front_weight_fraction);
        let b = car.wheelbase_m * car.front_weight_fraction;
        let front = f[0].fy + f[1].fy;
        let rear = f[2].fy + f[3].fy;
        assert!((front * a - rear * b).abs() < 1e-6);
    }
}
