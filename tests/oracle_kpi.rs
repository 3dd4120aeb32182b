//! KPIs of the CPU engine against independent libraries (scripts in
//! tests/oracles/): table 4 against numpy on MCAP read by Python `mcap`;
//! road roughness against surfalize (moments, ISO 16610-21 Gaussian split)
//! and scipy (Welch PSD). Tolerances are relative, f64 on both sides; they
//! allow only for summation order (1e-9) and FFT rounding (1e-9).

use serde_json::Value;
use std::path::PathBuf;
use tirewear::Wheel;
use tirewear::ingest::road::read_profile_csv;
use tirewear::ingest::telemetry::read_telemetry;
use tirewear::kpi::road::{
    average_wavelength, gaussian_lowpass, hdc, height_moments, profile_indices, psd,
};
use tirewear::kpi::telemetry::wheel_indices;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn golden(name: &str) -> Value {
    serde_json::from_str(&std::fs::read_to_string(root().join("tests/golden").join(name)).unwrap())
        .unwrap()
}

fn close(what: &str, got: f64, want: f64, rtol: f64) {
    assert!(
        (got - want).abs() <= rtol * want.abs() + 1e-12,
        "{what}: {got} vs {want}"
    );
}

#[test]
fn table4_matches_numpy() {
    for fixture in ["tiny-sample", "tiny-block"] {
        let run = read_telemetry(&root().join(format!("tests/fixtures/{fixture}.mcap"))).unwrap();
        let g = golden(&format!("{fixture}.json"));
        for w in Wheel::ALL {
            let (k, _, _) = wheel_indices(&run.wheels[w.index()]).unwrap();
            let t = &g[w.topic()]["table4"];
            let f = |n: &str| t[n].as_f64().unwrap();
            let pairs = [
                ("t_surface_avg", k.t_surface_avg_c),
                ("t_surface_std", k.t_surface_std_c),
                ("t_inner_avg", k.t_inner_avg_c),
                ("t_inner_std", k.t_inner_std_c),
                ("fx_avg", k.fx_avg_n),
                ("fx_std", k.fx_std_n),
                ("fy_avg", k.fy_avg_n),
                ("fy_std", k.fy_std_n),
                ("fz_avg", k.fz_avg_n),
                ("fz_std", k.fz_std_n),
                ("vsx_avg", k.vsx_avg_mps),
                ("vsx_std", k.vsx_std_mps),
                ("vsy_avg", k.vsy_avg_mps),
                ("vsy_std", k.vsy_std_mps),
                ("friction_energy_x_j", k.friction_energy_x_j),
                ("friction_energy_y_j", k.friction_energy_y_j),
                ("sliding_distance_m", k.sliding_distance_m),
                ("duration_s", k.duration_s),
                ("camber_avg_deg", k.camber_avg_deg),
                ("pressure_avg_pa", k.pressure_avg_pa),
                ("contact_patch_mm2", k.contact_patch_mm2),
            ];
            for (name, got) in pairs {
                close(&format!("{fixture} {w} {name}"), got, f(name), 1e-9);
            }
        }
    }
}

#[test]
fn road_indices_match_surfalize_and_scipy() {
    let g = golden("road.json");
    for (path, want) in g.as_object().unwrap() {
        let p = read_profile_csv(&root().join(path), "t", "l").unwrap();
        let f = |n: &str| want[n].as_f64().unwrap();
        let list = |n: &str| {
            want[n]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect::<Vec<_>>()
        };
        let (ra, rq, sk, ku) = height_moments(&p.z_mm);
        close(&format!("{path} Ra"), ra, f("ra_mm"), 1e-9);
        close(&format!("{path} Rq"), rq, f("rq_mm"), 1e-9);
        close(&format!("{path} Sk"), sk, f("skewness"), 1e-9);
        close(&format!("{path} Ku"), ku, f("kurtosis"), 1e-9);
        // ISO 16610-21 split: surfalize uses scipy.ndimage.gaussian_filter (reflect ends).
        let low = gaussian_lowpass(&p.z_mm, p.dx_mm, 0.5);
        for (i, want) in list("lowpass_first").iter().enumerate() {
            close(&format!("{path} lowpass[{i}]"), low[i], *want, 1e-9);
        }
        close(
            &format!("{path} lowpass mid"),
            low[low.len() / 2],
            f("lowpass_mid"),
            1e-9,
        );
        let (idx, _) = profile_indices(&p);
        close(
            &format!("{path} Ra macro"),
            idx.ra_macro_mm,
            f("ra_macro_mm"),
            1e-9,
        );
        close(
            &format!("{path} Ra micro"),
            idx.ra_micro_mm,
            f("ra_micro_mm"),
            1e-8,
        );
        close(
            &format!("{path} λa macro"),
            idx.macro_wavelength_mm,
            f("macro_wavelength_mm"),
            1e-9,
        );
        close(
            &format!("{path} λa micro"),
            idx.micro_wavelength_mm,
            f("micro_wavelength_mm"),
            1e-8,
        );
        close(
            &format!("{path} ζ⊥"),
            idx.peakyness_mm,
            f("peakyness_mm"),
            1e-9,
        );
        assert!((average_wavelength(&low, p.dx_mm) - idx.macro_wavelength_mm).abs() < 1e-12);
        // Welch PSD, every 37th bin, against scipy.signal.welch / 2.
        let (q, c) = psd(&p.z_mm, p.dx_mm);
        for (k, (wq, wc)) in list("psd_q").iter().zip(list("psd_c")).enumerate() {
            close(&format!("{path} q[{}]", 37 * k), q[37 * k], *wq, 1e-12);
            close(&format!("{path} C[{}]", 37 * k), c[37 * k], wc, 1e-9);
        }
        let (lag, h) = hdc(&p.z_mm, p.dx_mm);
        for (i, (wl, wh)) in list("hdc_lag_mm").iter().zip(list("hdc")).enumerate() {
            close(&format!("{path} lag[{i}]"), lag[i], *wl, 1e-12);
            close(&format!("{path} HDC[{i}]"), h[i], wh, 1e-9);
        }
        // H is a property of self-affine profiles; on the 64-sample sine most PSD bins are
        // rounding-level leakage (~1e-30) whose logs differ between FFT libraries.
        if p.z_mm.len() < 1024 {
            continue;
        }
        assert!(
            (idx.hurst - f("hurst")).abs() < 1e-9,
            "{path} H {} vs {}",
            idx.hurst,
            f("hurst")
        );
        assert!(
            (idx.hurst_hdc - f("hurst_hdc")).abs() < 1e-9,
            "{path} H_hdc {} vs {}",
            idx.hurst_hdc,
            f("hurst_hdc")
        );
    }
}

/// The pair maps (docs/kpis.md, "Pair maps") against numpy: each wheel's
/// energy binned by two conditions at once, computed by
/// tests/oracles/read_our_mcap.py from the MCAP as Python `mcap` reads it,
/// with the conditions' formulas and coarse bins transcribed from the docs.
/// Both bin in f32 from the same f64 values, so every sample lands in the
/// same cell; the tolerance (1e-9 of the wheel's |energy|, per cell) allows
/// only for summation order.
#[test]
fn pair_maps_match_numpy() {
    use tirewear::kpi::cpu::condition_map::{N_PAIRS, pair_name};
    use tirewear::kpi::telemetry::wheel_condition_maps;
    for fixture in ["tiny-sample", "tiny-block"] {
        let run = read_telemetry(&root().join(format!("tests/fixtures/{fixture}.mcap"))).unwrap();
        let g = golden(&format!("{fixture}.json"));
        for w in Wheel::ALL {
            let maps = wheel_condition_maps(&run.wheels[w.index()]).unwrap();
            let want_maps = &g[w.topic()]["table4"]["pair_maps"];
            for p in 0..N_PAIRS {
                let name = pair_name(p);
                let want: Vec<f64> = want_maps[&name]
                    .as_array()
                    .unwrap_or_else(|| panic!("{fixture} {w}: no '{name}' in the golden file"))
                    .iter()
                    .map(|v| v.as_f64().unwrap())
                    .collect();
                let got = maps.pair_map(p);
                assert_eq!(got.len(), want.len(), "{name}");
                let scale: f64 = want.iter().map(|e| e.abs()).sum();
                assert!(scale > 0.0, "{fixture} {w} {name}: empty");
                for (cell, (g_, w_)) in got.iter().zip(&want).enumerate() {
                    assert!(
                        (g_ - w_).abs() <= 1e-9 * scale,
                        "{fixture} {w} {name} cell {cell}: {g_} vs {w_}"
                    );
                }
            }
        }
    }
}
