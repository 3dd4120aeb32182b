//! Tire compound files: master curves of storage modulus E' and loss factor
//! tan δ versus temperature at a reference frequency, and the WLF constants
//! that move between frequency and temperature (paper eqs. 30-31).

use super::{IngestError, Result, positive, read_toml, write_toml};
use serde::{Deserialize, Serialize};
use std::path::Path;

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Compound {
    pub id: String,
    pub name: String,
    /// Frequency at which the master curve below was measured (Hz).
    pub reference_frequency_hz: f64,
    pub wlf: Wlf,
    pub master_curve: MasterCurve,
}

/// Williams-Landel-Ferry constants: `log10 a_T = -C1 (T - T_ref) / (C2 + T - T_ref)`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Wlf {
    /// C1 (dimensionless).
    pub c1: f64,
    /// C2 (K).
    pub c2_k: f64,
    /// Reference temperature T_ref (degC).
    pub t_ref_c: f64,
}

/// Master curve sampled on a strictly increasing temperature grid.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MasterCurve {
    pub temperature_c: Vec<f64>,
    pub storage_modulus_mpa: Vec<f64>,
    pub loss_factor: Vec<f64>,
}

/// Largest accepted WLF C1 (typical rubber: 8-20).
pub(crate) const MAX_WLF_C1: f64 = 1000.0;
/// Largest accepted WLF C2 in K (typical rubber: 50-200 K).
pub(crate) const MAX_WLF_C2_K: f64 = 10_000.0;
/// Accepted range of the WLF reference temperature (degC).
pub(crate) const T_REF_RANGE_C: (f64, f64) = (-150.0, 250.0);
/// Largest accepted master-curve reference frequency (Hz).
pub(crate) const MAX_REFERENCE_FREQUENCY_HZ: f64 = 1e12;

impl Wlf {
    /// log10 of the shift factor a_T at temperature `t_c` (paper eq. 30).
    pub(crate) fn log10_shift(&self, t_c: f64) -> f64 {
        let dt = t_c - self.t_ref_c;
        -self.c1 * dt / (self.c2_k + dt)
    }

    /// Temperature whose shift factor is `10^log10_at` (paper eq. 31, the
    /// inverse of eq. 30): `T = T_ref - C2 x / (C1 + x)` with `x = log10 a_T`.
    pub(crate) fn temperature_for_shift(&self, log10_at: f64) -> f64 {
        self.t_ref_c - self.c2_k * log10_at / (self.c1 + log10_at)
    }
}

impl Compound {
    /// A compound with the common WLF constants (C1 = 8.86, C2 = 101.6 K),
    /// 10 Hz reference frequency and the given master curve: for tests.
    #[cfg(test)]
    pub(crate) fn for_tests(t_ref_c: f64, curve: &[(f64, f64, f64)]) -> Compound {
        Compound {
            id: "c".into(),
            name: "c".into(),
            reference_frequency_hz: 10.0,
            wlf: Wlf {
                c1: 8.86,
                c2_k: 101.6,
                t_ref_c,
            },
            master_curve: MasterCurve {
                temperature_c: curve.iter().map(|p| p.0).collect(),
                storage_modulus_mpa: curve.iter().map(|p| p.1).collect(),
                loss_factor: curve.iter().map(|p| p.2).collect(),
            },
        }
    }

    pub fn load(path: &Path) -> Result<Compound> {
        let c: Compound = read_toml(path)?;
        c.validate(path)?;
        Ok(c)
    }

    /// The file must describe the compound the manifest names it for.
    pub(crate) fn check_id(&self, manifest_id: &str, path: &Path) -> Result<()> {
        if self.id != manifest_id {
            return Err(IngestError::invalid(
                path,
                "id",
                format!(
                    "is '{}' but the manifest lists this file as compound '{manifest_id}'",
                    self.id
                ),
            ));
        }
        Ok(())
    }

    pub fn write(&self, path: &Path) -> Result<()> {
        write_toml(path, self)
    }

    pub fn validate(&self, path: &Path) -> Result<()> {
        let bad = |rec: &str, what: String| IngestError::invalid(path, rec, what);
        let m = &self.master_curve;
        let n = m.temperature_c.len();
        if n < 2 {
            return Err(bad(
                "master_curve",
                format!("needs at least 2 temperatures, got {n}"),
            ));
        }
        if m.storage_modulus_mpa.len() != n || m.loss_factor.len() != n {
            return Err(bad(
                "master_curve",
                format!(
                    "temperature_c has {n} values but storage_modulus_mpa has {} and loss_factor {}",
                    m.storage_modulus_mpa.len(),
                    m.loss_factor.len()
                ),
            ));
        }
        for i in 0..n {
            let (t, e, d) = (
                m.temperature_c[i],
                m.storage_modulus_mpa[i],
                m.loss_factor[i],
            );
            let rec = format!("master_curve point {i} (T = {t} degC)");
            if !t.is_finite() || (i > 0 && t <= m.temperature_c[i - 1]) {
                return Err(bad(
                    &rec,
                    "temperatures must be finite and strictly increasing".into(),
                ));
            }
            if !positive(e) {
                return Err(bad(
                    &rec,
                    format!("storage modulus must be > 0 MPa, got {e}"),
                ));
            }
            if !positive(d) {
                return Err(bad(&rec, format!("loss factor must be > 0, got {d}")));
            }
        }
        if !positive(self.reference_frequency_hz) {
            return Err(bad(
                "reference_frequency_hz",
                format!("must be > 0, got {}", self.reference_frequency_hz),
            ));
        }
        if self.reference_frequency_hz > MAX_REFERENCE_FREQUENCY_HZ {
            return Err(bad(
                "reference_frequency_hz",
                format!(
                    "{:?} Hz is above {MAX_REFERENCE_FREQUENCY_HZ:e} Hz",
                    self.reference_frequency_hz
                ),
            ));
        }
        self.validate_wlf(path)
    }

    /// WLF constants in physical ranges, and the equation defined (C2 + T −
    /// T_ref > 0) over the whole master curve: a NaN or absurd constant would
    /// otherwise reach the master-curve lookups as a NaN temperature.
    fn validate_wlf(&self, path: &Path) -> Result<()> {
        let w = &self.wlf;
        let bad = |what: String| IngestError::invalid(path, "wlf", what);
        if !(positive(w.c1) && w.c1 <= MAX_WLF_C1) {
            return Err(bad(format!(
                "c1 must be in (0, {MAX_WLF_C1}], got {:?}",
                w.c1
            )));
        }
        if !(positive(w.c2_k) && w.c2_k <= MAX_WLF_C2_K) {
            return Err(bad(format!(
                "c2_k must be in (0, {MAX_WLF_C2_K}] K, got {:?}",
                w.c2_k
            )));
        }
        if !(T_REF_RANGE_C.0..=T_REF_RANGE_C.1).contains(&w.t_ref_c) {
            return Err(bad(format!(
                "t_ref_c must be a temperature in {}..{} degC, got {:?}",
                T_REF_RANGE_C.0, T_REF_RANGE_C.1, w.t_ref_c
            )));
        }
        let t_min = self.master_curve.temperature_c[0];
        if w.c2_k + t_min - w.t_ref_c <= 0.0 {
            return Err(bad(format!(
                "C2 + T - T_ref = {} K at the master curve's lowest temperature {t_min} degC: \
                 the WLF equation is undefined there (it needs C2 + T - T_ref > 0)",
                w.c2_k + t_min - w.t_ref_c
            )));
        }
        Ok(())
    }

    /// E' (MPa) at temperature `t_c` on the reference-frequency master curve,
    /// linear in log10 E' between grid points, clamped at the grid ends.
    pub fn storage_modulus_mpa(&self, t_c: f64) -> f64 {
        let m = &self.master_curve;
        10f64.powf(interp(
            &m.temperature_c,
            &m.storage_modulus_mpa,
            t_c,
            f64::log10,
        ))
    }

    /// tan δ at temperature `t_c` on the reference-frequency master curve,
    /// linear between grid points, clamped at the grid ends.
    pub fn loss_factor(&self, t_c: f64) -> f64 {
        let m = &self.master_curve;
        interp(&m.temperature_c, &m.loss_factor, t_c, |v| v)
    }
}

/// Piecewise-linear interpolation of `map(ys)` at `x`, clamped to the ends;
/// NaN for a NaN `x` (no grid point to clamp to).
fn interp(xs: &[f64], ys: &[f64], x: f64, map: impl Fn(f64) -> f64) -> f64 {
    let n = xs.len();
    if x.is_nan() {
        return f64::NAN;
    }
    if x <= xs[0] {
        return map(ys[0]);
    }
    if x >= xs[n - 1] {
        return map(ys[n - 1]);
    }
    let i = xs.partition_point(|&v| v <= x) - 1;
    let w = (x - xs[i]) / (xs[i + 1] - xs[i]);
    map(ys[i]) * (1.0 - w) + map(ys[i + 1]) * w
}

/// Every `*.toml` compound file in `dir`, in file-name order.
pub(crate) fn read_compounds(dir: &Path) -> Result<Vec<Compound>> {
    compound_files(dir)?
        .iter()
        .map(|f| Compound::load(f))
        .collect()
}

/// The `*.toml` files of a compounds folder, in name order.
pub(crate) fn compound_files(dir: &Path) -> Result<Vec<std::path::PathBuf>> {
    let mut files: Vec<std::path::PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| IngestError::io(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    Ok(files)
}

/// WLF constants of every `*.toml` compound file in `dir`, by compound id
/// (the physics baseline's temperature factor per compound).
pub fn read_wlf(dir: &Path) -> Result<std::collections::BTreeMap<String, Wlf>> {
    Ok(read_compounds(dir)?
        .into_iter()
        .map(|c| (c.id, c.wlf))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wlf_equations_30_and_31_are_inverse() {
        let w = Wlf {
            c1: 8.86,
            c2_k: 101.6,
            t_ref_c: 30.0,
        };
        // By hand: T - T_ref = 20 K -> log10 a_T = -8.86*20/121.6 = -1.457237 (3 d.p.)
        assert!((w.log10_shift(50.0) + 8.86 * 20.0 / 121.6).abs() < 1e-12);
        for t in [-20.0, 0.0, 30.0, 75.0, 140.0] {
            assert!((w.temperature_for_shift(w.log10_shift(t)) - t).abs() < 1e-9);
        }
    }

    #[test]
    fn interpolation_is_log_linear_for_modulus() {
        let c = Compound::for_tests(30.0, &[(0.0, 100.0, 0.2), (10.0, 10.0, 0.4)]);
        assert!((c.storage_modulus_mpa(5.0) - 10f64.powf(1.5)).abs() < 1e-9);
        assert!((c.loss_factor(2.5) - 0.25).abs() < 1e-12);
        assert_eq!(c.storage_modulus_mpa(-50.0), 100.0);
        assert!(c.storage_modulus_mpa(f64::NAN).is_nan());
        assert!(c.loss_factor(f64::NAN).is_nan());
    }

    #[test]
    fn absurd_wlf_constants_are_refused_by_name() {
        let good = Compound::for_tests(30.0, &[(-20.0, 100.0, 0.2), (140.0, 10.0, 0.4)]);
        let p = Path::new("c.toml");
        good.validate(p).unwrap();
        type Change = fn(&mut Wlf);
        let cases: [(Change, &str); 6] = [
            (|w| w.t_ref_c = f64::NAN, "t_ref_c"),
            (|w| w.t_ref_c = f64::INFINITY, "t_ref_c"),
            (|w| w.t_ref_c = -500.0, "t_ref_c"),
            (|w| w.c1 = 1e308, "c1"),
            (|w| w.c2_k = f64::NAN, "c2_k"),
            // 101.6 - 20 - 90 < 0: the equation flips sign inside the curve.
            (|w| w.t_ref_c = 90.0, "C2 + T - T_ref"),
        ];
        for (change, says) in cases {
            let mut c = good.clone();
            change(&mut c.wlf);
            let err = c.validate(p).unwrap_err().to_string();
            assert!(
                err.starts_with("c.toml: wlf: ") && err.contains(says),
                "{err}"
            );
        }
    }
}
