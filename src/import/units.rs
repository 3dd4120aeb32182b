//! Units a logger writes and their conversion to the SI units of the season
//! archive (`docs/import.md`, "Units"). A unit is matched without regard to
//! case, spaces and the degree sign (`°C`, `degC`, `C` are one unit).

use std::fmt;

/// What a channel measures; a unit converts only within its dimension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dimension {
    Time,
    Speed,
    Acceleration,
    AngularSpeed,
    Angle,
    Temperature,
    Pressure,
    Length,
    Force,
}

impl fmt::Display for Dimension {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = match self {
            Dimension::Time => "time",
            Dimension::Speed => "speed",
            Dimension::Acceleration => "acceleration",
            Dimension::AngularSpeed => "angular speed",
            Dimension::Angle => "angle",
            Dimension::Temperature => "temperature",
            Dimension::Pressure => "pressure",
            Dimension::Length => "length",
            Dimension::Force => "force",
        };
        f.write_str(s)
    }
}

/// A linear conversion `si = value · scale + offset` into the archive's unit
/// of its dimension: s, m/s, m/s², rad/s, deg, °C, Pa (gauge), m, N.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Conversion {
    pub dimension: Dimension,
    pub scale: f64,
    pub offset: f64,
}

impl Conversion {
    pub(crate) fn apply(&self, value: f64) -> f64 {
        value * self.scale + self.offset
    }
}

/// Standard gravity (m/s²): loggers' "g" is this one.
pub const STANDARD_GRAVITY: f64 = 9.806_65;

/// The conversion of `unit` (as written in a log or a channel map), or
/// `None` when the unit is unknown.
pub(crate) fn conversion(unit: &str) -> Option<Conversion> {
    use Dimension::*;
    let key: String = unit
        .chars()
        .filter(|c| !c.is_whitespace() && *c != '°' && *c != 'º')
        .collect::<String>()
        .to_ascii_lowercase();
    let deg = std::f64::consts::PI / 180.0;
    let (dimension, scale, offset) = match key.as_str() {
        "s" | "sec" | "secs" => (Time, 1.0, 0.0),
        "ms" => (Time, 1e-3, 0.0),
        "us" | "µs" => (Time, 1e-6, 0.0),
        "m/s" | "mps" => (Speed, 1.0, 0.0),
        "km/h" | "kph" | "kmh" | "km/hr" => (Speed, 1.0 / 3.6, 0.0),
        "mph" => (Speed, 0.447_04, 0.0),
        "m/s2" | "m/s^2" | "m/s²" | "mps2" => (Acceleration, 1.0, 0.0),
        "g" => (Acceleration, STANDARD_GRAVITY, 0.0),
        "rad/s" | "radps" => (AngularSpeed, 1.0, 0.0),
        "deg/s" | "degs" | "/s" => (AngularSpeed, deg, 0.0),
        "rpm" | "rev/min" => (AngularSpeed, std::f64::consts::TAU / 60.0, 0.0),
        "deg" | "degree" | "degrees" => (Angle, 1.0, 0.0),
        "rad" | "radian" | "radians" => (Angle, 1.0 / deg, 0.0),
        "c" | "degc" | "celsius" => (Temperature, 1.0, 0.0),
        "f" | "degf" | "fahrenheit" => (Temperature, 5.0 / 9.0, -32.0 * 5.0 / 9.0),
        "k" | "kelvin" => (Temperature, 1.0, -273.15),
        "pa" => (Pressure, 1.0, 0.0),
        "kpa" => (Pressure, 1e3, 0.0),
        "bar" => (Pressure, 1e5, 0.0),
        "mbar" => (Pressure, 100.0, 0.0),
        "psi" => (Pressure, 6_894.757_293_168, 0.0),
        "m" => (Length, 1.0, 0.0),
        "km" => (Length, 1e3, 0.0),
        "mm" => (Length, 1e-3, 0.0),
        "mi" | "mile" | "miles" => (Length, 1_609.344, 0.0),
        "n" => (Force, 1.0, 0.0),
        "kn" => (Force, 1e3, 0.0),
        "kgf" => (Force, STANDARD_GRAVITY, 0.0),
        "lbf" => (Force, 4.448_221_615_260_5, 0.0),
        _ => return None,
    };
    Some(Conversion {
        dimension,
        scale,
        offset,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn to_si(v: f64, unit: &str) -> f64 {
        conversion(unit).expect("known").apply(v)
    }

    #[test]
    fn conversions_by_hand() {
        // 180 km/h = 50 m/s; 100 mph = 44.704 m/s (1 mi = 1609.344 m exactly).
        assert!((to_si(180.0, "km/h") - 50.0).abs() < 1e-12);
        assert!((to_si(100.0, "mph") - 44.704).abs() < 1e-12);
        // 1.5 g = 14.709975 m/s².
        assert!((to_si(1.5, "G") - 14.709_975).abs() < 1e-12);
        // 600 rpm = 10 rev/s = 20π rad/s; 90 deg/s = π/2 rad/s.
        assert!((to_si(600.0, "rpm") - 20.0 * std::f64::consts::PI).abs() < 1e-12);
        assert!((to_si(90.0, "deg/s") - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        // π rad = 180 deg.
        assert!((to_si(std::f64::consts::PI, "rad") - 180.0).abs() < 1e-12);
        // 212 °F = 100 °C; 32 F = 0 °C; 373.15 K = 100 °C.
        assert!((to_si(212.0, "°F") - 100.0).abs() < 1e-12);
        assert!(to_si(32.0, "F").abs() < 1e-12);
        assert!((to_si(373.15, "K") - 100.0).abs() < 1e-9);
        assert_eq!(to_si(25.0, "degC"), 25.0);
        // 1.8 bar = 180 kPa; 26 psi = 179.263689 kPa (1 psi = 6894.757293168 Pa).
        assert!((to_si(1.8, "bar") - 180_000.0).abs() < 1e-9);
        assert!((to_si(26.0, "psi") - 179_263.689_622_368).abs() < 1e-6);
        assert!((to_si(180.0, "kPa") - 180_000.0).abs() < 1e-9);
        assert!((to_si(3.0, "km") - 3000.0).abs() < 1e-12);
        assert!((to_si(2.0, "kN") - 2000.0).abs() < 1e-12);
    }

    #[test]
    fn unknown_units_are_none_and_dimensions_are_kept() {
        assert!(conversion("furlong/fortnight").is_none());
        assert!(conversion("").is_none());
        assert_eq!(conversion("km/h").unwrap().dimension, Dimension::Speed);
        assert_eq!(conversion("° C").unwrap().dimension, Dimension::Temperature);
    }
}
