//! Planted effects: wear mechanisms the plain frictional-energy law does not
//! contain, each with a magnitude and smooth-onset thresholds. The extra
//! wear of an effect is `magnitude × k × road × ∫ P·w dt` with the
//! compound's base abrasion `k` and the effect's weight `w` (0..1): so a
//! magnitude of 1 means "as abrasive per joule as base wear, where it acts".

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EffectKind {
    /// Fronts: lateral sliding energy while the tread bulk is cold.
    Graining,
    /// Friction energy while the inner liner is above a temperature.
    Blistering,
    /// Friction energy while the surface is above a critical temperature.
    Thermal,
    /// Extra abrasion growing with the micro-texture of the road.
    RoadAbrasion,
}

impl EffectKind {
    pub const ALL: [EffectKind; 4] = [
        EffectKind::Graining,
        EffectKind::Blistering,
        EffectKind::Thermal,
        EffectKind::RoadAbrasion,
    ];

    pub fn name(self) -> &'static str {
        match self {
            EffectKind::Graining => "graining",
            EffectKind::Blistering => "blistering",
            EffectKind::Thermal => "thermal",
            EffectKind::RoadAbrasion => "road-abrasion",
        }
    }
}

/// Largest magnitude of a planted effect: 100 times the base wear where
/// it acts (the validation plants 0.5 to 4).
pub const MAX_MAGNITUDE: f64 = 100.0;

/// One planted effect with its settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Effect {
    pub kind: EffectKind,
    pub magnitude: f64,
    /// Threshold (°C for the thermal effects, mm rms for road abrasion).
    pub threshold: f64,
    /// Width of the smooth onset (same unit as the threshold).
    pub width: f64,
}

impl Effect {
    pub fn with_defaults(kind: EffectKind, magnitude: f64) -> Effect {
        let (threshold, width) = match kind {
            // Bulk temperature (mean of surface and inner liner) below which graining starts.
            EffectKind::Graining => (84.0, 3.0),
            EffectKind::Blistering => (122.0, 2.5),
            EffectKind::Thermal => (86.0, 2.0),
            // Micro-texture rms (mm) above which abrasion grows.
            EffectKind::RoadAbrasion => (0.03, 0.01),
        };
        Effect {
            kind,
            magnitude,
            threshold,
            width,
        }
    }

    /// Refuses settings that cannot describe an effect: a magnitude outside
    /// 0..[`MAX_MAGNITUDE`] (1e308 made the wear infinite), a threshold
    /// that is not a number (NaN silently planted nothing), a width that
    /// is not positive.
    pub fn check(&self) -> Result<(), String> {
        if !(0.0..=MAX_MAGNITUDE).contains(&self.magnitude) {
            return Err(format!(
                "magnitude must be within 0..{MAX_MAGNITUDE} (abrasion per joule relative to base wear where it acts), got {:?}",
                self.magnitude
            ));
        }
        if !self.threshold.is_finite() {
            return Err(format!(
                "threshold must be a number, got {}",
                self.threshold
            ));
        }
        if !(self.width > 0.0 && self.width.is_finite()) {
            return Err(format!("width must be > 0, got {:?}", self.width));
        }
        Ok(())
    }

    /// Weight 0..1 of a sample. Temperatures in °C.
    pub fn weight(&self, t_surface: f64, t_inner: f64) -> f64 {
        let logistic = |x: f64| 1.0 / (1.0 + (-x).exp());
        match self.kind {
            EffectKind::Graining => {
                logistic((self.threshold - 0.5 * (t_surface + t_inner)) / self.width)
            }
            EffectKind::Blistering => logistic((t_inner - self.threshold) / self.width),
            EffectKind::Thermal => logistic((t_surface - self.threshold) / self.width),
            EffectKind::RoadAbrasion => 1.0,
        }
    }

    /// Road factor of road abrasion: softplus growth above the threshold, in units of the width.
    pub(crate) fn road_weight(&self, micro_rms_mm: f64) -> f64 {
        let x = (micro_rms_mm - self.threshold) / self.width;
        (1.0 + x.exp()).ln()
    }
}

impl FromStr for Effect {
    type Err = String;
    /// `NAME[=MAGNITUDE][,threshold=T][,width=W]`, e.g. `graining=0.4,threshold=80`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let mut parts = s.split(',');
        let head = parts.next().unwrap_or_default();
        let (name, mag) = match head.split_once('=') {
            Some((n, m)) => (
                n,
                m.parse::<f64>()
                    .map_err(|_| format!("bad magnitude '{m}' in '{s}'"))?,
            ),
            None => (head, 0.5),
        };
        let kind = EffectKind::ALL
            .into_iter()
            .find(|k| k.name() == name)
            .ok_or_else(|| {
                format!(
                    "unknown effect '{name}' (graining, blistering, thermal, road-abrasion, none)"
                )
            })?;
        let mut e = Effect::with_defaults(kind, mag);
        for kv in parts {
            let (k, v) = kv
                .split_once('=')
                .ok_or_else(|| format!("expected key=value, got '{kv}'"))?;
            let v: f64 = v.parse().map_err(|_| format!("bad number '{v}' for {k}"))?;
            match k {
                "threshold" => e.threshold = v,
                "width" => e.width = v,
                _ => return Err(format!("unknown setting '{kv}' (threshold, width)")),
            }
        }
        e.check()?;
        Ok(e)
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}={},threshold={},width={}",
            self.kind.name(),
            self.magnitude,
            self.threshold,
            self.width
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_effect_specs() {
        let e: Effect = "graining=0.4,threshold=80".parse().unwrap();
        assert_eq!(e.kind, EffectKind::Graining);
        assert_eq!((e.magnitude, e.threshold, e.width), (0.4, 80.0, 3.0));
        assert!("wobble=1".parse::<Effect>().is_err());
        assert!("thermal=-1".parse::<Effect>().is_err());
        // Settings that cannot describe an effect, each refused with its reason.
        for (spec, reason) in [
            ("graining=1e308", "magnitude must be within 0..100"),
            ("graining=nan", "magnitude must be within 0..100"),
            ("graining=1,threshold=nan", "threshold must be a number"),
            ("graining=1,threshold=inf", "threshold must be a number"),
            ("graining=1,width=-3", "width must be > 0"),
            ("graining=1,width=0", "width must be > 0"),
            ("graining=1,depth=3", "unknown setting 'depth=3'"),
        ] {
            let e = spec.parse::<Effect>().unwrap_err();
            assert!(e.contains(reason), "{spec}: {e}");
        }
        assert!("graining=100,threshold=1e3".parse::<Effect>().is_ok());
        // Smooth onset: half weight at the threshold.
        let b = Effect::with_defaults(EffectKind::Blistering, 1.0);
        assert!((b.weight(80.0, 122.0) - 0.5).abs() < 1e-12);
    }
}
