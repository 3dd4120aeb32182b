//! The channel map (`channels.toml`): which of a log's channels is which
//! tirewear quantity, and in which unit (`docs/import.md`, "Channel map").

use super::error::ImportError;
use super::units::{Conversion, Dimension, conversion};
use crate::Wheel;
use regex::Regex;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

/// The shipped default map (`datasets/import/channels.toml`).
pub const DEFAULT_CHANNEL_MAP: &str = include_str!("../../datasets/import/channels.toml");

/// A quantity the importer reads from a log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Quantity {
    Time,
    GroundSpeed,
    AccelLong,
    AccelLat,
    YawRate,
    BodySlip,
    SteerAngle,
    SteeringWheel,
    Distance,
    AirTemp,
    TrackTemp,
    WheelSpeed,
    WheelLoad,
    DamperPos,
    TyreTemp,
    TpmsPressure,
    TpmsTemp,
}

impl Quantity {
    pub const ALL: [Quantity; 17] = [
        Quantity::Time,
        Quantity::GroundSpeed,
        Quantity::AccelLong,
        Quantity::AccelLat,
        Quantity::YawRate,
        Quantity::BodySlip,
        Quantity::SteerAngle,
        Quantity::SteeringWheel,
        Quantity::Distance,
        Quantity::AirTemp,
        Quantity::TrackTemp,
        Quantity::WheelSpeed,
        Quantity::WheelLoad,
        Quantity::DamperPos,
        Quantity::TyreTemp,
        Quantity::TpmsPressure,
        Quantity::TpmsTemp,
    ];

    /// Its key in `channels.toml`.
    pub fn key(self) -> &'static str {
        match self {
            Quantity::Time => "time",
            Quantity::GroundSpeed => "ground_speed",
            Quantity::AccelLong => "accel_long",
            Quantity::AccelLat => "accel_lat",
            Quantity::YawRate => "yaw_rate",
            Quantity::BodySlip => "body_slip",
            Quantity::SteerAngle => "steer_angle",
            Quantity::SteeringWheel => "steering_wheel",
            Quantity::Distance => "distance",
            Quantity::AirTemp => "air_temp",
            Quantity::TrackTemp => "track_temp",
            Quantity::WheelSpeed => "wheel_speed",
            Quantity::WheelLoad => "wheel_load",
            Quantity::DamperPos => "damper_pos",
            Quantity::TyreTemp => "tyre_temp",
            Quantity::TpmsPressure => "tpms_pressure",
            Quantity::TpmsTemp => "tpms_temp",
        }
    }

    /// The dimensions a source channel may have (wheel speed: a linear speed
    /// at the logger's radius, or an angular speed).
    pub(crate) fn dimensions(self) -> &'static [Dimension] {
        use Dimension::*;
        match self {
            Quantity::Time => &[Time],
            Quantity::GroundSpeed => &[Speed],
            Quantity::AccelLong | Quantity::AccelLat => &[Acceleration],
            Quantity::YawRate => &[AngularSpeed],
            Quantity::BodySlip | Quantity::SteerAngle | Quantity::SteeringWheel => &[Angle],
            Quantity::Distance | Quantity::DamperPos => &[Length],
            Quantity::AirTemp | Quantity::TrackTemp | Quantity::TyreTemp | Quantity::TpmsTemp => {
                &[Temperature]
            }
            Quantity::WheelSpeed => &[Speed, AngularSpeed],
            Quantity::WheelLoad => &[Force],
            Quantity::TpmsPressure => &[Pressure],
        }
    }

    pub(crate) fn per_corner(self) -> bool {
        matches!(
            self,
            Quantity::WheelSpeed
                | Quantity::WheelLoad
                | Quantity::DamperPos
                | Quantity::TyreTemp
                | Quantity::TpmsPressure
                | Quantity::TpmsTemp
        )
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MapFile {
    format_version: u32,
    corners: BTreeMap<String, Vec<String>>,
    channels: BTreeMap<String, ChannelEntry>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ChannelEntry {
    names: Vec<String>,
    #[serde(default)]
    unit: Option<String>,
    #[serde(default)]
    corner: bool,
    #[serde(default)]
    zones: Option<String>,
}

/// One quantity's rule: name patterns in order (compiled per corner).
#[derive(Debug, Clone)]
struct Rule {
    quantity: Quantity,
    /// Per corner (index by `Wheel::index`), or one entry for a car channel.
    patterns: Vec<Vec<(String, Regex)>>,
    unit: Option<String>,
    mean_of_zones: bool,
}

/// A checked channel map.
#[derive(Debug, Clone)]
pub struct ChannelMap {
    rules: Vec<Rule>,
}

/// Where a quantity (of one corner, or of the car) comes from.
#[derive(Debug, Clone, PartialEq)]
pub struct Mapped {
    pub quantity: Quantity,
    pub corner: Option<Wheel>,
    /// Indices of the source channels (several: zones to average).
    pub sources: Vec<usize>,
    pub conversion: Conversion,
    /// The unit the conversion came from (the log's, or the map's).
    pub unit: String,
}

/// What a log's channels map to.
#[derive(Debug, Clone, Default)]
pub struct Mapping {
    pub mapped: Vec<Mapped>,
    /// Channels no rule matched, by name.
    pub unmapped: Vec<String>,
    /// Every channel of the log, by name (for errors that list them).
    pub source_names: Vec<String>,
    /// The names the map tries for each quantity (for errors).
    pub tried: BTreeMap<Quantity, Vec<String>>,
}

impl Mapping {
    pub fn get(&self, q: Quantity, corner: Option<Wheel>) -> Option<&Mapped> {
        self.mapped
            .iter()
            .find(|m| m.quantity == q && m.corner == corner)
    }
}

/// Lower case without spaces, underscores, dots, hyphens and brackets.
pub(crate) fn normalise(name: &str) -> String {
    name.chars()
        .filter(|c| !matches!(c, ' ' | '_' | '.' | '-' | '(' | ')' | '[' | ']' | '\t'))
        .flat_map(char::to_lowercase)
        .collect()
}

fn compile(pattern: &str, corner: Option<&[String]>) -> Result<Regex, String> {
    let norm = normalise(pattern);
    let mut re = String::from("^");
    let mut rest = norm.as_str();
    while !rest.is_empty() {
        if let Some(r) = rest.strip_prefix("{corner}") {
            let spellings = corner.ok_or("'{corner}' in a channel without `corner = true`")?;
            let alts: Vec<String> = spellings
                .iter()
                .map(|s| regex::escape(&normalise(s)))
                .collect();
            re.push_str(&format!("(?:{})", alts.join("|")));
            rest = r;
        } else if let Some(r) = rest.strip_prefix('*') {
            re.push_str(".*");
            rest = r;
        } else {
            let c = rest.chars().next().expect("non-empty");
            re.push_str(&regex::escape(&c.to_string()));
            rest = &rest[c.len_utf8()..];
        }
    }
    re.push('$');
    Regex::new(&re).map_err(|e| e.to_string())
}

impl ChannelMap {
    /// The shipped default map.
    pub fn default_map() -> Self {
        Self::parse(DEFAULT_CHANNEL_MAP, Path::new("<default channels.toml>"))
            .expect("the shipped channel map is valid (tested)")
    }

    pub fn read(path: &Path) -> Result<Self, ImportError> {
        let text = std::fs::read_to_string(path).map_err(|e| ImportError::io(path, e))?;
        Self::parse(&text, path)
    }

    pub fn parse(text: &str, path: &Path) -> Result<Self, ImportError> {
        let bad = |what: String| ImportError::Map {
            path: path.to_path_buf(),
            what,
        };
        let file: MapFile = toml::from_str(text).map_err(|e| bad(e.to_string()))?;
        if file.format_version != 1 {
            return Err(bad(format!(
                "format_version {} (this build reads 1)",
                file.format_version
            )));
        }
        let mut corners: Vec<Vec<String>> = Vec::new();
        for w in Wheel::ALL {
            let s = file
                .corners
                .get(w.name())
                .ok_or_else(|| bad(format!("[corners] has no {}", w.name())))?;
            if s.is_empty() {
                return Err(bad(format!("[corners] {} lists no spelling", w.name())));
            }
            corners.push(s.clone());
        }
        if let Some(k) = file
            .corners
            .keys()
            .find(|k| Wheel::ALL.iter().all(|w| w.name() != *k))
        {
            return Err(bad(format!(
                "[corners] has an unknown corner '{k}' (FL, FR, RL, RR)"
            )));
        }
        let mut rules = Vec::new();
        for (key, entry) in &file.channels {
            let quantity = Quantity::ALL
                .into_iter()
                .find(|q| q.key() == key)
                .ok_or_else(|| {
                    bad(format!(
                        "unknown channel '{key}' (known: {})",
                        Quantity::ALL.map(Quantity::key).join(", ")
                    ))
                })?;
            let ctx = |what: String| bad(format!("[channels.{key}]: {what}"));
            if entry.corner != quantity.per_corner() {
                return Err(ctx(format!(
                    "`corner` must be {} for this channel",
                    quantity.per_corner()
                )));
            }
            let mean_of_zones = match entry.zones.as_deref() {
                None => false,
                Some("mean") => true,
                Some(z) => return Err(ctx(format!("zones = \"{z}\" (only \"mean\" is known)"))),
            };
            if entry.names.is_empty() {
                return Err(ctx("`names` is empty".into()));
            }
            if let Some(u) = &entry.unit {
                let c = conversion(u).ok_or_else(|| ctx(format!("unknown unit '{u}'")))?;
                if !quantity.dimensions().contains(&c.dimension) {
                    return Err(ctx(format!("unit '{u}' is a {}", c.dimension)));
                }
            }
            let targets: Vec<Option<&[String]>> = if entry.corner {
                corners.iter().map(|c| Some(c.as_slice())).collect()
            } else {
                vec![None]
            };
            let mut patterns = Vec::new();
            for t in targets {
                let mut list = Vec::new();
                for n in &entry.names {
                    let re = compile(n, t).map_err(|e| ctx(format!("name '{n}': {e}")))?;
                    list.push((n.clone(), re));
                }
                patterns.push(list);
            }
            rules.push(Rule {
                quantity,
                patterns,
                unit: entry.unit.clone(),
                mean_of_zones,
            });
        }
        Ok(ChannelMap { rules })
    }

    /// Maps a log's channels (`names[i]`, with `units[i]` as the log gives
    /// them, "" when it gives none). Errors name the file and channel: an
    /// unknown unit, a unit of the wrong kind, two channels for one quantity.
    pub fn map(
        &self,
        file: &Path,
        names: &[String],
        units: &[String],
    ) -> Result<Mapping, ImportError> {
        let norm: Vec<String> = names.iter().map(|n| normalise(n)).collect();
        let mut used = vec![false; names.len()];
        let mut mapping = Mapping {
            source_names: names.to_vec(),
            ..Mapping::default()
        };
        for rule in &self.rules {
            mapping.tried.insert(
                rule.quantity,
                rule.patterns[0].iter().map(|(p, _)| p.clone()).collect(),
            );
            for (ci, patterns) in rule.patterns.iter().enumerate() {
                let corner = rule.quantity.per_corner().then(|| Wheel::ALL[ci]);
                let Some((pattern, hits)) = patterns.iter().find_map(|(p, re)| {
                    let hits: Vec<usize> = (0..names.len())
                        .filter(|&i| re.is_match(&norm[i]))
                        .collect();
                    (!hits.is_empty()).then_some((p, hits))
                }) else {
                    continue;
                };
                if hits.len() > 1 && !rule.mean_of_zones {
                    return Err(ImportError::Channel {
                        path: file.to_path_buf(),
                        channel: names[hits[0]].clone(),
                        what: format!(
                            "ambiguous: '{pattern}' ({}{}) matches {}",
                            rule.quantity.key(),
                            corner.map(|w| format!(" {}", w.name())).unwrap_or_default(),
                            hits.iter()
                                .map(|&i| format!("'{}'", names[i]))
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    });
                }
                let mut conv: Option<(Conversion, String)> = None;
                for &i in &hits {
                    let unit = if units[i].trim().is_empty() {
                        rule.unit.clone().ok_or_else(|| ImportError::Channel {
                            path: file.to_path_buf(),
                            channel: names[i].clone(),
                            what: format!(
                                "has no unit and the map gives none for {}",
                                rule.quantity.key()
                            ),
                        })?
                    } else {
                        units[i].trim().to_string()
                    };
                    let c = conversion(&unit).ok_or_else(|| ImportError::Channel {
                        path: file.to_path_buf(),
                        channel: names[i].clone(),
                        what: format!(
                            "unknown unit '{unit}' (docs/import.md lists the known units)"
                        ),
                    })?;
                    if !rule.quantity.dimensions().contains(&c.dimension) {
                        return Err(ImportError::Channel {
                            path: file.to_path_buf(),
                            channel: names[i].clone(),
                            what: format!(
                                "unit '{unit}' is a {}, but {} is a {}",
                                c.dimension,
                                rule.quantity.key(),
                                rule.quantity
                                    .dimensions()
                                    .iter()
                                    .map(|d| d.to_string())
                                    .collect::<Vec<_>>()
                                    .join(" or ")
                            ),
                        });
                    }
                    if let Some((prev, pu)) = &conv
                        && prev != &c
                    {
                        return Err(ImportError::Channel {
                            path: file.to_path_buf(),
                            channel: names[i].clone(),
                            what: format!(
                                "zones of one tyre in different units ('{pu}' and '{unit}')"
                            ),
                        });
                    }
                    conv = Some((c, unit));
                }
                let (conversion, unit) = conv.expect("at least one hit");
                for &i in &hits {
                    used[i] = true;
                }
                mapping.mapped.push(Mapped {
                    quantity: rule.quantity,
                    corner,
                    sources: hits,
                    conversion,
                    unit,
                });
            }
        }
        mapping.unmapped = names
            .iter()
            .zip(&used)
            .filter(|(_, u)| !**u)
            .map(|(n, _)| n.clone())
            .collect();
        Ok(mapping)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(v: &[&str]) -> Vec<String> {
        v.iter().map(|x| x.to_string()).collect()
    }

    #[test]
    fn default_map_parses_and_knows_mixed_spellings() {
        let map = ChannelMap::default_map();
        let names = s(&[
            "Time",
            "Tyre Temp FL Centre",
            "Tyre Temp FL Inner",
            "Tyre Temp FL Outer",
            "Tyre Temp FR Center",
            "wheel_speed_lf",
            "LFtempCM",
            "Engine RPM",
        ]);
        let units = s(&["s", "C", "C", "C", "°F", "km/h", "C", "rpm"]);
        let m = map.map(Path::new("x.csv"), &names, &units).unwrap();
        let fl = m.get(Quantity::TyreTemp, Some(Wheel::FL)).unwrap();
        assert_eq!(fl.sources, vec![1, 2, 3], "the FL zones are averaged");
        let fr = m.get(Quantity::TyreTemp, Some(Wheel::FR)).unwrap();
        assert_eq!(fr.sources, vec![4]);
        assert!((fr.conversion.apply(212.0) - 100.0).abs() < 1e-12);
        let ws = m.get(Quantity::WheelSpeed, Some(Wheel::FL)).unwrap();
        assert_eq!(ws.sources, vec![5]);
        // LFtempCM is FL's tyre temperature only by the third name, which
        // never comes up because the first already matched.
        assert_eq!(m.unmapped, s(&["LFtempCM", "Engine RPM"]));
        assert_eq!(m.get(Quantity::Time, None).unwrap().sources, vec![0]);
    }

    #[test]
    fn errors_name_the_channel() {
        let map = ChannelMap::default_map();
        let err = |names: &[&str], units: &[&str]| {
            map.map(Path::new("log.csv"), &s(names), &s(units))
                .unwrap_err()
                .to_string()
        };
        let e = err(&["Ground Speed"], &["furlong/h"]);
        assert!(
            e.contains("log.csv") && e.contains("Ground Speed") && e.contains("furlong/h"),
            "{e}"
        );
        let e = err(&["Ground Speed"], &["bar"]);
        assert!(
            e.contains("is a pressure") && e.contains("ground_speed"),
            "{e}"
        );
        let e = err(&["Wheel Speed FL", "Wheel Speed LF"], &["km/h", "km/h"]);
        assert!(e.contains("ambiguous"), "{e}");
        let e = err(&["Tyre Temp FL In", "Tyre Temp FL Out"], &["C", "F"]);
        assert!(e.contains("different units"), "{e}");
    }

    #[test]
    fn a_bad_map_is_refused_with_its_key() {
        let bad = |t: &str| {
            ChannelMap::parse(t, Path::new("m.toml"))
                .unwrap_err()
                .to_string()
        };
        let corners = "[corners]\nFL=[\"FL\"]\nFR=[\"FR\"]\nRL=[\"RL\"]\nRR=[\"RR\"]\n";
        let e = bad(&format!(
            "format_version = 1\n{corners}[channels.speed]\nnames=[\"x\"]\n"
        ));
        assert!(e.contains("unknown channel 'speed'"), "{e}");
        let e = bad(&format!(
            "format_version = 1\n{corners}[channels.wheel_speed]\nnames=[\"x\"]\n"
        ));
        assert!(e.contains("corner"), "{e}");
        let e = bad(&format!(
            "format_version = 1\n{corners}[channels.ground_speed]\nnames=[\"x\"]\nunit=\"bar\"\n"
        ));
        assert!(e.contains("pressure"), "{e}");
        let e = bad("format_version = 2\n[corners]\n[channels]\n");
        assert!(e.contains("format_version 2"), "{e}");
    }
}
