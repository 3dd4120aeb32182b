//! Viscoelastic indices (paper table 5): the solicitation frequency of the
//! tread by the road texture, the shifted temperature T* (WLF, eqs. 30-31)
//! and the compound's E′ and tan δ there.

use crate::ingest::compound::Compound;

/// Table 5 indices of one tire and run.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct ViscoelasticIndices {
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

/// `sliding_speed_mps`: mean |v_s| of the run; `macro_wavelength_mm`: the
/// track's λ_Macro; `surface_c`: mean surface temperature.
pub fn viscoelastic_indices(
    compound: &Compound,
    sliding_speed_mps: f64,
    macro_wavelength_mm: f64,
    surface_c: f64,
) -> ViscoelasticIndices {
    let f = sliding_speed_mps / (macro_wavelength_mm / 1000.0);
    // Shifting frequency f to the reference is a shift of log10(f/f_ref) decades:
    // log a_T(T*) = log a_T(T) + log10(f/f_ref), then eq. 31.
    let x = compound.wlf.log10_shift(surface_c) + (f / compound.reference_frequency_hz).log10();
    let t_star = compound.wlf.temperature_for_shift(x);
    ViscoelasticIndices {
        solicitation_frequency_hz: f,
        shifted_temperature_c: t_star,
        storage_modulus_mpa: compound.storage_modulus_mpa(t_star),
        loss_factor: compound.loss_factor(t_star),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ingest::compound::{MasterCurve, Wlf};

    #[test]
    fn wlf_shift_by_hand() {
        let c = Compound {
            id: "c".into(),
            name: "c".into(),
            reference_frequency_hz: 10.0,
            wlf: Wlf {
                c1: 8.86,
                c2_k: 101.6,
                t_ref_c: 40.0,
            },
            master_curve: MasterCurve {
                temperature_c: vec![0.0, 40.0, 80.0],
                storage_modulus_mpa: vec![400.0, 100.0, 40.0],
                loss_factor: vec![0.6, 0.4, 0.25],
            },
        };
        // v_s = 2 m/s over λ = 4 mm: f = 500 Hz.
        // At T = 60 °C: log a_T = −8.86·20/121.6 = −1.457237; + log10(500/10) = 1.698970 -> x = 0.241733.
        // T* = 40 − 101.6·0.241733/(8.86 + 0.241733) = 37.30160 °C.
        let v = viscoelastic_indices(&c, 2.0, 4.0, 60.0);
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
}
