//! Wheel positions and axles.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// A wheel position on a four-wheeled car. (The default, FL, is only there
/// so that rows can be built field by field.)
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize,
)]
pub enum Wheel {
    #[default]
    FL,
    FR,
    RL,
    RR,
}

/// Front or rear axle: "front" and "rear" in every file tirewear writes
/// (season archives' truth files before 2026-11-24 spelled them "Front" and
/// "Rear", which still read). The default, front, is only there so that
/// rows can be built field by field.
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize,
)]
pub enum Axle {
    #[default]
    #[serde(rename = "front", alias = "Front")]
    Front,
    #[serde(rename = "rear", alias = "Rear")]
    Rear,
}

impl Axle {
    pub const ALL: [Axle; 2] = [Axle::Front, Axle::Rear];

    /// "front" or "rear", as the KPI table's `axle` column spells it.
    pub fn name(self) -> &'static str {
        match self {
            Axle::Front => "front",
            Axle::Rear => "rear",
        }
    }
}

impl FromStr for Axle {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Axle::ALL
            .into_iter()
            .find(|a| a.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| format!("unknown axle '{s}' (expected front or rear)"))
    }
}

impl Wheel {
    pub const ALL: [Wheel; 4] = [Wheel::FL, Wheel::FR, Wheel::RL, Wheel::RR];

    pub fn index(self) -> usize {
        self as usize
    }

    pub fn name(self) -> &'static str {
        match self {
            Wheel::FL => "FL",
            Wheel::FR => "FR",
            Wheel::RL => "RL",
            Wheel::RR => "RR",
        }
    }

    /// MCAP topic carrying this wheel's channels.
    pub fn topic(self) -> &'static str {
        match self {
            Wheel::FL => "/tire/FL",
            Wheel::FR => "/tire/FR",
            Wheel::RL => "/tire/RL",
            Wheel::RR => "/tire/RR",
        }
    }

    pub(crate) fn from_topic(topic: &str) -> Option<Wheel> {
        Wheel::ALL.into_iter().find(|w| w.topic() == topic)
    }

    pub fn axle(self) -> Axle {
        match self {
            Wheel::FL | Wheel::FR => Axle::Front,
            Wheel::RL | Wheel::RR => Axle::Rear,
        }
    }

    /// +1 for left wheels, -1 for right (the sign of the wheel's y in ISO 8855 axes).
    pub(crate) fn side_sign(self) -> f64 {
        match self {
            Wheel::FL | Wheel::RL => 1.0,
            Wheel::FR | Wheel::RR => -1.0,
        }
    }
}

impl fmt::Display for Wheel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Wheel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Wheel::ALL
            .into_iter()
            .find(|w| w.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| format!("unknown wheel position '{s}' (expected FL, FR, RL or RR)"))
    }
}

impl fmt::Display for Axle {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axles_are_written_lowercase_and_older_capitalised_files_still_read() {
        assert_eq!(serde_json::to_string(&Axle::Rear).unwrap(), "\"rear\"");
        for (text, axle) in [
            ("\"front\"", Axle::Front),
            ("\"Front\"", Axle::Front),
            ("\"Rear\"", Axle::Rear),
        ] {
            assert_eq!(serde_json::from_str::<Axle>(text).unwrap(), axle);
        }
        assert_eq!("REAR".parse::<Axle>(), Ok(Axle::Rear));
        assert!("middle".parse::<Axle>().unwrap_err().contains("'middle'"));
        for w in Wheel::ALL {
            assert_eq!(w.name().parse::<Wheel>(), Ok(w));
        }
    }
}
