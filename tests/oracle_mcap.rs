//! MCAP interoperability with independent tools (scripts in tests/oracles/):
//! files we wrote, read by Python `mcap` + protobuf (goldens), and files
//! Python `mcap-protobuf-support` wrote, read by our reader.

use serde_json::Value;
use std::path::PathBuf;
use tirewear::Wheel;
use tirewear::ingest::telemetry::{Encoding, RunTelemetry, read_telemetry};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn golden(name: &str) -> Value {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/golden")
        .join(name);
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// Statistics of one channel, as the oracle computes them.
fn check_channel(topic: &str, name: &str, v: &[f64], g: &Value) {
    let g = &g[name];
    let sum: f64 = v.iter().sum();
    // Values are f32 widened to f64 on both sides: extremes and ends are exact;
    // sums differ only by summation order (numpy is pairwise): 1e-9 relative.
    assert_eq!(v[0], g["first"].as_f64().unwrap(), "{topic} {name} first");
    assert_eq!(
        *v.last().unwrap(),
        g["last"].as_f64().unwrap(),
        "{topic} {name} last"
    );
    assert_eq!(
        v.iter().cloned().fold(f64::INFINITY, f64::min),
        g["min"].as_f64().unwrap(),
        "{topic} {name} min"
    );
    assert_eq!(
        v.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
        g["max"].as_f64().unwrap(),
        "{topic} {name} max"
    );
    let gs = g["sum"].as_f64().unwrap();
    assert!(
        (sum - gs).abs() <= 1e-9 * gs.abs().max(1.0),
        "{topic} {name} sum {sum} vs {gs}"
    );
}

fn widen(v: &[f32]) -> Vec<f64> {
    v.iter().map(|&x| x as f64).collect()
}

fn compare_with_golden(run: &RunTelemetry, g: &Value) {
    for w in Wheel::ALL {
        let s = &run.wheels[w.index()];
        let gt = &g[w.topic()];
        assert_eq!(s.len() as u64, gt["count"].as_u64().unwrap(), "{w} count");
        assert_eq!(s.time_ns[0], gt["first_time_ns"].as_u64().unwrap());
        assert_eq!(
            *s.time_ns.last().unwrap(),
            gt["last_time_ns"].as_u64().unwrap()
        );
        for (name, v) in [
            ("vx_mps", &s.vx_mps),
            ("vy_mps", &s.vy_mps),
            ("omega_radps", &s.omega_radps),
            ("rolling_radius_m", &s.rolling_radius_m),
            ("fx_n", &s.fx_n),
            ("fy_n", &s.fy_n),
            ("fz_n", &s.fz_n),
            ("t_surface_c", &s.t_surface_c),
            ("t_inner_c", &s.t_inner_c),
            ("pressure_pa", &s.pressure_pa),
            ("camber_deg", &s.camber_deg),
        ] {
            check_channel(w.topic(), name, &widen(v), gt);
        }
        // Friction energy, paper eqs. 19-25: same definition as the oracle, computed here
        // independently of any tirewear KPI code.
        let period = 200_000_000u64; // 5 Hz fixture
        let mut e = 0.0;
        for i in 0..s.len() - 1 {
            let dt = s.time_ns[i + 1] - s.time_ns[i];
            if dt != period {
                continue;
            }
            let vsx = s.vx_mps[i] as f64 - s.omega_radps[i] as f64 * s.rolling_radius_m[i] as f64;
            let p = -(s.fx_n[i] as f64 * vsx + s.fy_n[i] as f64 * s.vy_mps[i] as f64);
            e += p * dt as f64 / 1e9;
        }
        let ge = gt["friction_energy_j"].as_f64().unwrap();
        assert!(
            (e - ge).abs() <= 1e-9 * ge.abs(),
            "{w} friction energy {e} vs {ge}"
        );
        assert!(e > 0.0);
    }
    let v = &run.vehicle;
    let gv = &g["/vehicle"];
    assert_eq!(v.len() as u64, gv["count"].as_u64().unwrap());
    check_channel("/vehicle", "speed_mps", &widen(&v.speed_mps), gv);
    check_channel("/vehicle", "t_track_c", &widen(&v.t_track_c), gv);
    check_channel("/vehicle", "t_air_c", &widen(&v.t_air_c), gv);
    check_channel("/vehicle", "distance_m", &v.distance_m, gv);
}

#[test]
fn our_sample_messages_match_python_reader() {
    let run = read_telemetry(&fixture("tiny-sample.mcap")).unwrap();
    assert_eq!(run.encoding, Some(Encoding::Sample));
    compare_with_golden(&run, &golden("tiny-sample.json"));
}

#[test]
fn our_block_messages_match_python_reader() {
    let run = read_telemetry(&fixture("tiny-block.mcap")).unwrap();
    assert_eq!(run.encoding, Some(Encoding::Block));
    compare_with_golden(&run, &golden("tiny-block.json"));
}

/// Closed form of the Python writer's samples (keep in sync with write_python_mcap.py).
fn tire_values(w: usize, i: u64) -> [f32; 11] {
    let (w, i) = (w as f64, i as f64);
    [
        50.0 + 0.25 * i + w,
        -0.5 + 0.01 * i,
        150.0 + 0.5 * i,
        0.33,
        1000.0 - 25.0 * i,
        2000.0 + 10.0 * w,
        4000.0 + 100.0 * w,
        60.0 + 0.125 * i,
        100.0 + 0.5 * w,
        130000.0 + i,
        -3.0 + 0.25 * w,
    ]
    .map(|v| v as f32)
}

fn check_python_file(name: &str, encoding: Encoding) {
    const T0: u64 = 1_772_000_000_000_000_000;
    const PERIOD: u64 = 10_000_000;
    let run = read_telemetry(&fixture(name)).unwrap();
    assert_eq!(run.encoding, Some(encoding));
    let kept: Vec<u64> = (0..40).filter(|i| !(20..25).contains(i)).collect();
    for w in Wheel::ALL {
        let s = &run.wheels[w.index()];
        assert_eq!(s.len(), kept.len(), "{name} {w}");
        for (k, &i) in kept.iter().enumerate() {
            assert_eq!(s.time_ns[k], T0 + i * PERIOD);
            let got = [
                s.vx_mps[k],
                s.vy_mps[k],
                s.omega_radps[k],
                s.rolling_radius_m[k],
                s.fx_n[k],
                s.fy_n[k],
                s.fz_n[k],
                s.t_surface_c[k],
                s.t_inner_c[k],
                s.pressure_pa[k],
                s.camber_deg[k],
            ];
            assert_eq!(got, tire_values(w.index(), i), "{name} {w} sample {i}");
        }
    }
    let v = &run.vehicle;
    assert_eq!(v.len(), kept.len());
    for (k, &i) in kept.iter().enumerate() {
        assert_eq!(v.speed_mps[k], (50.0 + 0.25 * i as f64) as f32);
        assert_eq!(v.distance_m[k], 0.5 * i as f64);
        assert_eq!((v.t_track_c[k], v.t_air_c[k]), (35.5, 22.25));
    }
}

#[test]
fn reads_python_written_sample_messages() {
    check_python_file("python-sample.mcap", Encoding::Sample);
}

#[test]
fn reads_python_written_blocks() {
    check_python_file("python-block.mcap", Encoding::Block);
}
