//! The simulator's generated effects (`sim::generated`), checked against
//! the telemetry it wrote: the threshold is the drawn energy quantile, the
//! wear per tire is the magnitude times the base abrasion per joule times
//! the energy weighted by the onset (summed here sample by sample, in f64,
//! not from the simulator's histograms), and the magnitude gives the drawn
//! share of the wear's variance. And the condition maps' accelerations,
//! which the telemetry does not log, against the simulator's own.

use std::path::Path;
use tirewear::ingest::manifest::Season;
use tirewear::ingest::telemetry::{Encoding, read_telemetry};
use tirewear::sim::generated::{Component, Form, Onset, Quantity, Scope};
use tirewear::sim::{GeneratedEffect, Preset, SimOptions, simulate};
use tirewear::{Axle, Wheel};

#[derive(Debug, serde::Deserialize)]
struct TruthRow {
    run: String,
    wheel: Wheel,
    friction_energy_j: f64,
    weighted_energy_j: f64,
    wear_base_pct: f64,
    wear_generated_pct: f64,
    wear_total_pct: f64,
}

#[derive(serde::Deserialize)]
struct Settings {
    generated: GeneratedEffect,
}

fn simulate_with(out: &Path, g: GeneratedEffect) -> (Vec<TruthRow>, GeneratedEffect) {
    simulate(&SimOptions {
        preset: Preset::Tiny,
        scale: 1.0,
        tracks: None,
        seed: 5,
        effects: vec![],
        generated: Some(g),
        scatter: tirewear::sim::WearScatter::NONE,
        encoding: Encoding::Block,
        rate_hz: Some(20.0),
        out: out.to_path_buf(),
        sensor_noise: false,
        logger_export: None,
        progress: false,
    })
    .unwrap();
    let rows = csv::Reader::from_path(out.join("truth/wear_truth.csv"))
        .unwrap()
        .deserialize()
        .map(Result::unwrap)
        .collect();
    let text = std::fs::read_to_string(out.join("truth/settings.toml")).unwrap();
    let s: Settings = toml::from_str(&text).unwrap();
    (rows, s.generated)
}

/// One tire's run: (run, wheel, samples of (surface temperature °C, friction energy J)).
type TireSamples = (String, Wheel, Vec<(f64, f64)>);

/// Per tire of the season: (run, wheel, samples of (surface temperature
/// °C, friction energy J)), from the telemetry with time steps from the
/// timestamps: P = −F_x·v_sx − F_y·v_sy, v_sx = v_x − ω·r.
fn energy_by_temperature(dir: &Path) -> Vec<TireSamples> {
    let season = Season::open(dir).unwrap();
    let mut out = Vec::new();
    for run in &season.manifest.runs {
        let t = read_telemetry(&season.path(&run.telemetry)).unwrap();
        for (w, wheel) in t.wheels.iter().zip(Wheel::ALL) {
            let f = |x: f32| x as f64;
            let samples = (0..w.len().saturating_sub(1))
                .map(|i| {
                    let dt = (w.time_ns[i + 1] - w.time_ns[i]) as f64 * 1e-9;
                    let v_sx = f(w.vx_mps[i]) - f(w.omega_radps[i]) * f(w.rolling_radius_m[i]);
                    let p = -f(w.fx_n[i]) * v_sx - f(w.fy_n[i]) * f(w.vy_mps[i]);
                    (f(w.t_surface_c[i]), p * dt)
                })
                .collect();
            out.push((run.id.clone(), wheel, samples));
        }
    }
    out
}

/// An effect on the total energy as drawn, before the simulator resolves
/// its thresholds and magnitude on the season.
fn unresolved(form: Form, scope: Scope, variance_share: f64) -> GeneratedEffect {
    GeneratedEffect {
        seed: 0,
        form,
        component: Component::Total,
        scope,
        variance_share,
        magnitude: f64::NAN,
    }
}

#[test]
fn a_generated_onset_acts_where_and_as_much_as_it_was_drawn() {
    let dir = tempfile::tempdir().unwrap();
    let onset = Onset {
        quantity: Quantity::SurfaceTemperature,
        above: true,
        quantile: 0.7,
        width_fraction: 0.1,
        threshold: f64::NAN,
        width: f64::NAN,
    };
    let drawn = unresolved(
        Form::Onset { onset },
        Scope::Axle { axle: Axle::Front },
        0.2,
    );
    let (rows, g) = simulate_with(dir.path(), drawn);
    let Form::Onset { onset } = g.form else {
        panic!("{:?}", g.form)
    };

    // The threshold: the season's energy-weighted 0.7 quantile of the
    // surface temperature, over every tire (the simulator reads it off a
    // 512-bin histogram over 0-200 °C: within one bin, 0.39 K).
    let tires = energy_by_temperature(dir.path());
    let mut all: Vec<(f64, f64)> = tires.iter().flat_map(|t| t.2.iter().copied()).collect();
    all.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = all.iter().map(|s| s.1).sum();
    let mut acc = 0.0;
    let q70 = all
        .iter()
        .find(|s| {
            acc += s.1;
            acc >= 0.7 * total
        })
        .unwrap()
        .0;
    assert!(
        (onset.threshold - q70).abs() < 200.0 / 512.0,
        "{} vs {q70}",
        onset.threshold
    );

    // The wear per tire: magnitude × (base wear per J of the law's weighted
    // energy) × Σ P·w(T)·dt on the fronts, none on the rears. The simulator
    // weights by bin centres (bins of 0.39 K against an onset width of
    // several K) and integrates with its own time step: 1 %.
    for (run, wheel, samples) in &tires {
        let row = rows
            .iter()
            .find(|r| &r.run == run && r.wheel == *wheel)
            .unwrap();
        if wheel.axle() == Axle::Rear {
            assert_eq!(row.wear_generated_pct, 0.0);
            continue;
        }
        let energy: f64 = samples.iter().map(|(t, e)| e * onset.weight(*t)).sum();
        let expected = g.magnitude * row.wear_base_pct / row.weighted_energy_j * energy;
        assert!(
            (row.wear_generated_pct - expected).abs() <= 0.01 * expected,
            "{run} {wheel}: {} vs {expected}",
            row.wear_generated_pct
        );
    }

    // Its share of the wear's variance over the season's tires is the drawn one.
    let var = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        v.iter().map(|x| (x - m) * (x - m)).sum::<f64>()
    };
    let planted: Vec<f64> = rows.iter().map(|r| r.wear_generated_pct).collect();
    let total: Vec<f64> = rows.iter().map(|r| r.wear_total_pct).collect();
    let share = var(&planted) / var(&total);
    assert!((share - 0.2).abs() < 1e-9, "{share}");
}

#[test]
fn a_set_up_effect_scales_one_wheel_position() {
    let dir = tempfile::tempdir().unwrap();
    let drawn = unresolved(Form::SetUp, Scope::Wheel { wheel: Wheel::FR }, 0.1);
    let (rows, g) = simulate_with(dir.path(), drawn);
    // Weight 1 on every joule of the right-front tires: their extra wear is
    // the magnitude times the law's wear per joule times all their energy.
    for r in &rows {
        if r.wheel == Wheel::FR {
            let expected =
                g.magnitude * r.wear_base_pct / r.weighted_energy_j * r.friction_energy_j;
            assert!(
                (r.wear_generated_pct - expected).abs() <= 1e-9 * expected,
                "{r:?}: {expected}"
            );
        } else {
            assert_eq!(r.wear_generated_pct, 0.0, "{r:?}");
        }
    }
}

/// One acceleration's check: per tire, the friction energy weighted by a
/// smooth onset on it, Σ P·w(a)·dt, three ways. `simulated`: as the
/// simulator summed it from its own state (the lap's accelerations, not the
/// logged forces or speeds). `logged`: sample by sample from the telemetry,
/// with the acceleration computed here by docs/kpis.md's formula, unbinned.
/// `binned`: the same samples with the onset taken at the mid-point of the
/// condition's bin each value falls in — and the map, weighted the same
/// way, must equal it (the map bins that quantity). Returns the largest
/// relative difference of `logged` from `simulated` over the tires.
fn acceleration_against_simulator(
    quantity: Quantity,
    condition: &str,
    accel: impl Fn(&tirewear::ingest::telemetry::RunTelemetry, usize, f64) -> Vec<f64>,
) -> f64 {
    use tirewear::kpi::cpu::condition_map::{CONDITIONS, Component, read_condition_maps};
    let dir = tempfile::tempdir().unwrap();
    let onset = Onset {
        quantity,
        above: true,
        quantile: 0.5,
        width_fraction: 0.15,
        threshold: f64::NAN,
        width: f64::NAN,
    };
    let (rows, g) = simulate_with(
        dir.path(),
        unresolved(Form::Onset { onset }, Scope::All, 0.2),
    );
    let Form::Onset { onset } = g.form else {
        panic!("{:?}", g.form)
    };
    tirewear::kpi::extract(&tirewear::kpi::ExtractOptions {
        engine: tirewear::kpi::Engine::Cpu,
        ..tirewear::kpi::ExtractOptions::new(dir.path(), dir.path().join("kpis.parquet"))
    })
    .unwrap();
    let maps = read_condition_maps(&dir.path().join("kpis.condition_maps.parquet")).unwrap();
    let c = CONDITIONS.iter().position(|c| c.name == condition).unwrap();
    let bins = CONDITIONS[c].bins;
    let season = Season::open(dir.path()).unwrap();
    let mut worst = 0.0f64;
    for r in &rows {
        let run = season.manifest.runs.iter().find(|x| x.id == r.run).unwrap();
        let car = season
            .manifest
            .cars
            .iter()
            .find(|c| c.id == run.car)
            .unwrap();
        let t = read_telemetry(&season.path(&run.telemetry)).unwrap();
        let a = accel(&t, r.wheel.index(), car.mass_kg);
        let w = &t.wheels[r.wheel.index()];
        let f = |x: f32| x as f64;
        let (mut logged, mut binned) = (0.0, 0.0);
        for (i, &a_i) in a.iter().enumerate() {
            // The cleaning rule's step: to the next sample, the last one period.
            let dt = match i + 1 < w.len() {
                true => (w.time_ns[i + 1] - w.time_ns[i]) as f64 * 1e-9,
                false => (w.time_ns[1] - w.time_ns[0]) as f64 * 1e-9,
            };
            let v_sx = f(w.vx_mps[i]) - f(w.omega_radps[i]) * f(w.rolling_radius_m[i]);
            let e = (-f(w.fx_n[i]) * v_sx - f(w.fy_n[i]) * f(w.vy_mps[i])) * dt;
            logged += e * onset.weight(a_i);
            let b = ((a_i - bins.lo) / bins.width)
                .floor()
                .clamp(0.0, (bins.n - 1) as f64);
            binned += e * onset.weight(bins.mid(b as usize));
        }
        let from_map: f64 = maps[&(r.run.clone(), r.wheel)]
            .map(Component::Total, c)
            .iter()
            .enumerate()
            .map(|(b, e)| e * onset.weight(bins.mid(b)))
            .sum();
        // The map bins in f32 (the value rounded to f32, as both engines
        // do), this in f64: a sample within rounding of an edge may land
        // in the bin beside (2e-5 of a tire's weighted energy seen).
        assert!(
            (from_map - binned).abs() <= 1e-4 * binned.abs(),
            "{} {}: map {from_map} vs {binned}",
            r.run,
            r.wheel
        );
        let simulated =
            r.wear_generated_pct / (g.magnitude * r.wear_base_pct / r.weighted_energy_j);
        assert!(simulated > 0.0, "{} {}: no weighted energy", r.run, r.wheel);
        worst = worst.max((logged - simulated).abs() / simulated);
    }
    worst
}

/// The car's lateral acceleration, |Σ F_y| / m from the four tires' logged
/// forces, is the lap's: tire by tire within 0.5 % (0.18 % seen; the
/// simulator weights by its histogram's 0.1 m/s² bins; f32 forces).
#[test]
fn the_lateral_acceleration_map_holds_the_cars_lateral_acceleration() {
    let worst = acceleration_against_simulator(
        Quantity::LateralAcceleration,
        "accel_y_mps2",
        |t, _, mass| {
            (0..t.wheels[0].len())
                .map(|i| t.wheels.iter().map(|w| w.fy_n[i] as f64).sum::<f64>().abs() / mass)
                .collect()
        },
    );
    assert!(worst < 0.005, "{worst}");
}

/// The wheel centre's dv_x/dt over ±0.5 s follows the lap's longitudinal
/// acceleration less closely: the window smooths the steps between braking
/// and driving, and a wheel's v_x carries the yaw rate's part (the energy
/// weighted by an onset at the median differs by up to 10 %; 8.3 % seen).
#[test]
fn the_longitudinal_acceleration_map_holds_the_wheels_acceleration() {
    let worst = acceleration_against_simulator(
        Quantity::LongitudinalAcceleration,
        "accel_x_mps2",
        |t, wheel, _| {
            let w = &t.wheels[wheel];
            let half = 500_000_000;
            (0..w.len())
                .map(|i| {
                    let ti = w.time_ns[i];
                    let j0 = (0..=i).find(|&j| ti - w.time_ns[j] <= half).unwrap();
                    let j1 = (i..w.len())
                        .rev()
                        .find(|&j| w.time_ns[j] - ti <= half)
                        .unwrap();
                    if j0 == j1 {
                        return 0.0;
                    }
                    let span = (w.time_ns[j1] - w.time_ns[j0]) as f64 * 1e-9;
                    (w.vx_mps[j1] as f64 - w.vx_mps[j0] as f64) / span
                })
                .collect()
        },
    );
    assert!(worst < 0.10, "{worst}");
}
