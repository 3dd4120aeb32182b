//! Viscoelastic indices (paper table 5): the solicitation frequency of the
//! tread by the road texture, the shifted temperature T* (WLF, eqs. 30-31)
//! and the compound's E′ and tan δ there.

use crate::ingest::compound::Compound;

/// Table 5 indices of one tire and run.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub(crate) struct ViscoelasticIndices {
    /// f = v_s / λ_Macro (Hz): mean sliding speed over the macro-texture wavelength.
    pub solicitation_frequency_hz: f64,
    /// T* (°C): the temperature at the master curve's reference frequency
    /// equivalent to (mean surface temperature, f).
    pub shifted_temperature_c: f64,
    /// E′(T*) (MPa).
    pub storage_modulus_mpa: f64,
    /// tan δ(T*).
    pub loss_factor: f64,
}

impl ViscoelasticIndices {
    /// Every index undefined (NaN), for a row whose inputs do not allow them.
    pub const UNDEFINED: ViscoelasticIndices = ViscoelasticIndices {
        solicitation_frequency_hz: f64::NAN,
        shifted_temperature_c: f64::NAN,
        storage_modulus_mpa: f64::NAN,
        loss_factor: f64::NAN,
    };
}

/// `sliding_speed_mps`: mean |v_s| of the run; `macro_wavelength_mm`: the
/// track's λ_Macro; `surface_c`: mean surface temperature. An error says why
/// the indices are undefined (no road wavelength, a temperature where the WLF
/// equation does not hold); the caller keeps the row with NaN and the reason.
pub(crate) fn viscoelastic_indices(
    compound: &Compound,
    sliding_speed_mps: f64,
    macro_wavelength_mm: f64,
    surface_c: f64,
) -> Result<ViscoelasticIndices, String> {
    let f = sliding_speed_mps / (macro_wavelength_mm / 1000.0);
    if !(f.is_finite() && f > 0.0) {
        return Err(format!(
            "solicitation frequency undefined (sliding speed {sliding_speed_mps} m/s, \
             macro wavelength {macro_wavelength_mm} mm)"
        ));
    }
    let w = &compound.wlf;
    let margin_k = w.c2_k + surface_c - w.t_ref_c;
    if margin_k.is_nan() || margin_k <= 0.0 {
        return Err(format!(
            "WLF undefined at the mean surface temperature {surface_c} degC \
             (C2 + T - T_ref = {margin_k} K <= 0)"
        ));
    }
    let x = w.log10_shift(surface_c) + (f / compound.reference_frequency_hz).log10();
    // Eq. 31 needs C1 + log10 a_T > 0: beyond it no temperature has that shift.
    if (w.c1 + x).is_nan() || w.c1 + x <= 0.0 {
        return Err(format!(
            "no WLF temperature has the shift log10 a_T = {x:.3} (C1 + log10 a_T <= 0)"
        ));
    }
    let t_star = w.temperature_for_shift(x);
    if !t_star.is_finite() {
        return Err(format!("shifted temperature is {t_star}"));
    }
    Ok(ViscoelasticIndices {
        solicitation_frequency_hz: f,
        shifted_temperature_c: t_star,
        storage_modulus_mpa: compound.storage_modulus_mpa(t_star),
        loss_factor: compound.loss_factor(t_star),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wlf_shift_by_hand() {
        let c = Compound::for_tests(
            40.0,
            &[(0.0, 400.0, 0.6), (40.0, 100.0, 0.4), (80.0, 40.0, 0.25)],
        );
        // v_s = 2 m/s over λ = 4 mm: f = 500 Hz.
        // At T = 60 °C: log a_T = −8.86·20/121.6 = −1.457237; + log10(500/10) = 1.698970 -> x = 0.241733.
        // T* = 40 − 101.6·0.241733/(8.86 + 0.241733) = 37.30160 °C.
        let v = viscoelastic_indices(&c, 2.0, 4.0, 60.0).unwrap();
        assert!((v.solicitation_frequency_hz - 500.0).abs() < 1e-9);
        let x = -8.86 * 20.0 / 121.6 + 50f64.log10();
        let t_star = 40.0 - 101.6 * x / (8.86 + x);
        assert!((v.shifted_temperature_c - t_star).abs() < 1e-9);
        assert!((t_star - 37.3016).abs() < 1e-4);
        // E' between 0 °C (400) and 40 °C (100), log-linear: 10^(log10 400 + (log10 100 − log10 400)·T*/40).
        let e = 10f64.powf(400f64.log10() + (100f64.log10() - 400f64.log10()) * t_star / 40.0);
        assert!((v.storage_modulus_mpa - e).abs() < 1e-9);
        assert!((v.loss_factor - (0.6 - 0.2 * t_star / 40.0)).abs() < 1e-12);
    }

    #[test]
    fn undefined_inputs_give_a_reason_not_a_panic() {
        let c = Compound::for_tests(40.0, &[(0.0, 400.0, 0.6), (80.0, 40.0, 0.25)]);
        // A track without road profiles: λ_Macro is NaN.
        let e = viscoelastic_indices(&c, 2.0, f64::NAN, 60.0).unwrap_err();
        assert!(e.contains("solicitation frequency"), "{e}");
        // 101.6 + (-70) - 40 < 0: below the WLF pole.
        let e = viscoelastic_indices(&c, 2.0, 4.0, -70.0).unwrap_err();
        assert!(e.contains("C2 + T - T_ref"), "{e}");
        // x = -8.86*100/201.6 + log10(1e-9/10) = -14.4 < -C1.
        let e = viscoelastic_indices(&c, 1e-9, 1000.0, 140.0).unwrap_err();
        assert!(e.contains("C1 + log10 a_T"), "{e}");
    }
}
