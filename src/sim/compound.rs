//! Compound models: a viscoelastic master curve built on WLF-reduced
//! frequency (so the tables written to the compound files are WLF-consistent
//! by construction), grip, and the abrasion coefficient of the wear law.

use super::tire::GripParams;
use crate::ingest::compound::{Compound, MasterCurve, Wlf};

/// Surface temperature at which the wear law's temperature factor is 1 (°C).
pub const WEAR_REFERENCE_C: f64 = 60.0;

#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CompoundModel {
    pub id: String,
    pub name: String,
    /// Glass-transition temperature at the reference frequency (°C).
    pub tg_c: f64,
    pub wlf: Wlf,
    pub reference_frequency_hz: f64,
    /// Glassy and rubbery storage moduli (MPa).
    pub e_glassy_mpa: f64,
    pub e_rubbery_mpa: f64,
    /// Width of the modulus transition (decades of reduced frequency).
    pub transition_decades: f64,
    /// tan δ: base value, peak value and log-Gaussian width (decades).
    pub tan_delta: [f64; 3],
    pub grip: GripParams,
    /// Base abrasion: tread depth lost per MJ of friction energy at
    /// [`WEAR_REFERENCE_C`] on a neutral road (mm/MJ).
    pub wear_mm_per_mj: f64,
    /// Exponent γ of the viscoelastic temperature factor `(a_T(T_opt)/a_T(T))^γ`.
    pub wear_shift_exponent: f64,
}

impl CompoundModel {
    /// log10 of the reduced frequency f·a_T at the glass transition.
    fn x_transition(&self) -> f64 {
        (self.reference_frequency_hz).log10() + self.wlf.log10_shift(self.tg_c)
    }

    /// E' (MPa) and tan δ at temperature `t_c` and frequency `f_hz`.
    pub fn viscoelastic(&self, t_c: f64, f_hz: f64) -> (f64, f64) {
        let x = f_hz.log10() + self.wlf.log10_shift(t_c) - self.x_transition();
        let s = 1.0 / (1.0 + (-x / (self.transition_decades / 4.0)).exp());
        let log_e =
            self.e_rubbery_mpa.log10() + (self.e_glassy_mpa / self.e_rubbery_mpa).log10() * s;
        let [base, peak, width] = self.tan_delta;
        let td = base + (peak - base) * (-((x - 0.5) / width).powi(2)).exp();
        (10f64.powf(log_e), td)
    }

    /// The temperature factor of the wear law at surface temperature `t_c`,
    /// through the compound's WLF shift (Grosch: abrasion follows the
    /// rubber's reduced viscoelastic state): each decade that heating moves
    /// the rubber toward its rubbery state multiplies abrasion by 10^γ.
    /// It is 1 at [`WEAR_REFERENCE_C`] for every compound, so compounds differ
    /// in abradability only through `wear_mm_per_mj`.
    pub(crate) fn wear_temperature_factor(&self, t_c: f64) -> f64 {
        let decades = self.wlf.log10_shift(WEAR_REFERENCE_C) - self.wlf.log10_shift(t_c);
        10f64.powf(self.wear_shift_exponent * decades)
    }

    /// The compound file: master curves tabulated from −50 to 150 °C every 5 K.
    pub(crate) fn to_file(&self) -> Compound {
        let temperature_c: Vec<f64> = (0..=40).map(|i| -50.0 + 5.0 * i as f64).collect();
        let (storage_modulus_mpa, loss_factor) = temperature_c
            .iter()
            .map(|&t| {
                let (e, d) = self.viscoelastic(t, self.reference_frequency_hz);
                (round_sig(e, 6), round_sig(d, 6))
            })
            .unzip();
        Compound {
            id: self.id.clone(),
            name: self.name.clone(),
            reference_frequency_hz: self.reference_frequency_hz,
            wlf: self.wlf,
            master_curve: MasterCurve {
                temperature_c,
                storage_modulus_mpa,
                loss_factor,
            },
        }
    }
}

fn round_sig(v: f64, digits: i32) -> f64 {
    let scale = 10f64.powi(digits - 1 - v.abs().log10().floor() as i32);
    (v * scale).round() / scale
}

/// The three compounds of the presets.
pub(crate) fn catalogue() -> Vec<CompoundModel> {
    let make =
        |id: &str, name: &str, tg: f64, e_r: f64, mu: f64, t_opt: f64, wear: f64, td_peak: f64| {
            CompoundModel {
                id: id.into(),
                name: name.into(),
                tg_c: tg,
                wlf: Wlf {
                    c1: 8.86,
                    c2_k: 101.6,
                    t_ref_c: tg + 50.0,
                },
                reference_frequency_hz: 10.0,
                e_glassy_mpa: 2500.0,
                e_rubbery_mpa: e_r,
                transition_decades: 10.0,
                tan_delta: [0.10, td_peak, 5.0],
                grip: GripParams {
                    mu_peak: mu,
                    t_opt_c: t_opt,
                    window_c: 45.0,
                },
                wear_mm_per_mj: wear,
                wear_shift_exponent: 0.17,
            }
        };
    vec![
        make("soft", "C-Soft", 0.0, 15.0, 1.92, 65.0, 0.12, 1.15),
        make("medium", "C-Medium", -8.0, 24.0, 1.84, 72.0, 0.11, 1.05),
        make("hard", "C-Hard", -15.0, 34.0, 1.76, 80.0, 0.10, 0.95),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn written_master_curve_is_wlf_consistent() {
        // E' at (T, f) must equal the tabulated E' at the temperature T' whose shift
        // moves f to the reference frequency: log a_T(T') = log a_T(T) + log10(f/f_ref).
        for c in catalogue() {
            let file = c.to_file();
            for (t, f) in [(60.0, 1000.0), (80.0, 10_000.0), (40.0, 100.0)] {
                let (e, _) = c.viscoelastic(t, f);
                let t_star = c
                    .wlf
                    .temperature_for_shift(c.wlf.log10_shift(t) + (f / 10.0f64).log10());
                let (e_ref, _) = c.viscoelastic(t_star, 10.0);
                assert!((e / e_ref - 1.0).abs() < 1e-9);
                // and the tabulated curve interpolates it within 1 %
                assert!((file.storage_modulus_mpa(t_star) / e_ref - 1.0).abs() < 0.01);
            }
            // Moduli never rise with temperature, from glassy to rubbery.
            let m = &file.master_curve.storage_modulus_mpa;
            assert!(m.windows(2).all(|w| w[1] <= w[0]));
            assert!(m[0] > 10.0 * m[m.len() - 1]);
        }
    }
}
