//! The reduction engines, tested once against the `ReduceEngine` trait and
//! run for the CPU engine and (when this machine has an adapter; always in
//! CI, on Mesa's lavapipe) the GPU engine:
//! - a constant-slip run and two-bin energy maps by hand;
//! - a full-length run (1 h at 1 kHz, 3.6 M samples) against the CPU's f64
//!   result within the stated tolerances (indices and energy maps);
//! - the multi-dispatch and 2-D grid paths, reached by lowering the limits;
//! - `extract --engine gpu` on the demo season equals `--engine cpu`.

mod common;

use tirewear::engine::{
    CONDITION_MAP_TOLERANCE, CpuEngine, ENERGY_MAP_TOLERANCE, PAIR_MAP_TOLERANCE,
    ROUGHNESS_TOLERANCE, ReduceEngine, TELEMETRY_TOLERANCE, compare_condition_maps,
    compare_energy_maps, compare_roughness, compare_telemetry, gpu_for_tests,
};
use tirewear::kpi::cpu::condition_map::{CONDITIONS, Component, ConditionMaps, N_PAIRS, pair_name};
use tirewear::kpi::cpu::telemetry_reduce::{ReduceBatch, ReduceSample, merge};
use tirewear::kpi::table::read_parquet;
use tirewear::kpi::telemetry::finish_wheel;
use tirewear::kpi::{Engine, ExtractOptions, KpiRow, extract};

/// Every engine this machine has, with the tolerance its results are held to
/// against exact values: the CPU works in f64, the GPU in f32.
fn engines(test: &str) -> Vec<(Box<dyn ReduceEngine>, f64)> {
    let mut v: Vec<(Box<dyn ReduceEngine>, f64)> = vec![(Box::new(CpuEngine), 1e-9)];
    if let Some(g) = gpu_for_tests(test) {
        v.push((Box::new(g), TELEMETRY_TOLERANCE));
    }
    v
}

fn sample(dt: f64) -> ReduceSample {
    let (dt, dt_lo) = ReduceSample::split_dt(dt);
    ReduceSample {
        dt,
        dt_lo,
        ..Default::default()
    }
}

#[test]
fn constant_slip_by_hand_on_every_engine() {
    // v_sx = 50.5 − 100·0.5 = 0.5 m/s, v_sy = 1 m/s, Fx = −2000 N, Fy = −3000 N:
    // P_x = 1000 W, P_y = 3000 W over 60 000 samples of 1 ms = 60 s.
    let s = ReduceSample {
        vx: 50.5,
        vy: 1.0,
        omega: 100.0,
        radius: 0.5,
        fx: -2000.0,
        fy: -3000.0,
        fz: 4000.0,
        t_surface: 85.0,
        t_inner: 110.0,
        pressure: 160_000.0,
        camber: -2.5,
        ..sample(0.001)
    };
    let mut batch = ReduceBatch::default();
    batch.push_wheel(&vec![s; 60_000]);
    for (e, tol) in engines("constant_slip_by_hand_on_every_engine") {
        let sums = merge(&batch, &e.telemetry_reduce(&batch).unwrap());
        let k = finish_wheel(&sums[0], &batch.refs[0]).unwrap();
        let close = |got: f64, want: f64, what: &str| {
            assert!(
                (got - want).abs() <= tol * want.abs().max(1.0),
                "{} engine, {what}: {got} vs {want} (tolerance {tol:e})",
                e.name()
            );
        };
        close(k.duration_s, 60.0, "duration");
        close(k.friction_energy_x_j, 60_000.0, "energy x");
        close(k.friction_energy_y_j, 180_000.0, "energy y");
        close(
            k.sliding_distance_m,
            1.25f64.sqrt() * 60.0,
            "sliding distance",
        );
        close(k.contact_patch_mm2, 20_000.0, "contact patch");
        close(k.t_surface_avg_c, 85.0, "surface temperature");
        close(k.camber_avg_deg, -2.5, "camber");
        assert_eq!(k.t_surface_std_c, 0.0, "{}", e.name());
    }
}

/// A deterministic full-length run: 1 h at 1 kHz of smooth signals with
/// sliding, load and temperature swings.
fn full_length_run() -> Vec<ReduceSample> {
    (0..3_600_000)
        .map(|i| {
            let t = i as f64 * 1e-3;
            let vx = 45.0 + 20.0 * (0.05 * t).sin();
            let slip = 0.03 * (1.3 * t).sin();
            let radius = 0.33 + 0.002 * (0.7 * t).cos();
            ReduceSample {
                vx: vx as f32,
                vy: (0.8 * (0.9 * t).sin()) as f32,
                omega: (vx * (1.0 - slip) / radius) as f32,
                radius: radius as f32,
                fx: (3000.0 * (1.3 * t).sin()) as f32,
                fy: (-4000.0 * (0.9 * t).sin()) as f32,
                fz: (4000.0 + 1000.0 * (0.3 * t).sin()) as f32,
                t_surface: (80.0 + 10.0 * (0.01 * t).sin()) as f32,
                t_inner: (110.0 + 5.0 * (0.004 * t).sin()) as f32,
                pressure: (160_000.0 + 5000.0 * (0.002 * t).sin()) as f32,
                camber: (-2.0 + 0.5 * (0.3 * t).sin()) as f32,
                t_surface_rate: (10.0 * 0.01 * (0.01 * t).cos()) as f32,
                t_inner_rate: (5.0 * 0.004 * (0.004 * t).cos()) as f32,
                load_rel: (1.0 + 0.25 * (0.3 * t).sin()) as f32,
                time_s: t as f32,
                distance_m: (45.0 * t) as f32,
                accel_x: (20.0 * 0.05 * (0.05 * t).cos()) as f32,
                accel_y: (15.0 * (0.9 * t).sin().abs()) as f32,
                ..sample(1e-3)
            }
        })
        .collect()
}

#[test]
fn full_length_run_matches_the_f64_reference() {
    let mut batch = ReduceBatch::default();
    batch.push_wheel(&full_length_run());
    batch.push_wheel(&full_length_run()[..20_000]);
    for (e, _) in engines("full_length_run_matches_the_f64_reference") {
        let c = compare_telemetry(&CpuEngine, e.as_ref(), &batch).unwrap();
        let (worst, err) = c.worst();
        eprintln!(
            "{} engine ({}): largest scaled difference {err:.2e} in {worst}",
            e.name(),
            e.device()
        );
        assert!(c.passes(), "{}: {:?}", e.name(), c.errors);
        assert_eq!(c.errors.len(), 22, "every index compared");
        let m = compare_energy_maps(&CpuEngine, e.as_ref(), &batch).unwrap();
        eprintln!(
            "{} engine: energy maps differ by {m:.2e} of the energy",
            e.name()
        );
        assert!(m <= ENERGY_MAP_TOLERANCE, "{}: {m}", e.name());
        let (c, p) = compare_condition_maps(&CpuEngine, e.as_ref(), &batch).unwrap();
        eprintln!(
            "{} engine: condition maps differ by {c:.2e} of the energy, pair maps by {p:.2e}",
            e.name()
        );
        assert!(c <= CONDITION_MAP_TOLERANCE, "{}: {c}", e.name());
        assert!(p <= PAIR_MAP_TOLERANCE, "{}: pair maps {p}", e.name());
    }
}

#[test]
fn condition_maps_by_hand_on_every_engine() {
    // a: v_x 50.5, ω·r 50 → v_sx 0.5, κ = −0.5/50.5 = −0.0099 (bin 14), tan α
    // 0 (bin 15), F 2000 N on F_z 0 → utilisation 2000/100 = 20 (last bin), v_x
    // 50.5 m/s (bin 12), P_x = 1000 W. b: v_x 0 → slip speed floor 1 m/s,
    // κ 0 (bin 15), tan α = 12/1 (last bin), F_y −25 N → 0.25
    // (bin 2), speed 0 (bin 0), P_y = 300 W. 10 ms each.
    let a = ReduceSample {
        vx: 50.5,
        omega: 100.0,
        radius: 0.5,
        fx: -2000.0,
        t_surface: 82.0,
        t_inner: 101.0,
        ..sample(0.01)
    };
    let b = ReduceSample {
        vx: 0.0,
        omega: 0.0,
        fx: 0.0,
        vy: 12.0,
        fy: -25.0,
        t_surface: 19.0,
        t_inner: 170.0,
        ..a
    };
    let mut wheel = vec![a; 1500];
    wheel.extend(vec![b; 700]);
    let mut batch = ReduceBatch::default();
    batch.push_wheel(&wheel);
    let (ea, eb) = (1000.0 * 0.01 * 1500.0, 300.0 * 0.01 * 700.0);
    let at = |name: &str| ConditionMaps::condition_index(name).unwrap();
    for (e, tol) in engines("condition_maps_by_hand_on_every_engine") {
        let m = &e.condition_map(&batch).unwrap()[0];
        let close = |got: f64, want: f64| (got - want).abs() <= tol * want.abs() + 1e-6;
        let total = |c: &str| m.map(Component::Total, at(c));
        let n = e.name();
        assert!(close(total("slip_ratio")[14], ea), "{n}");
        assert!(close(total("slip_ratio")[15], eb), "{n}");
        assert!(close(total("lateral_slip")[15], ea), "{n}");
        assert!(close(total("lateral_slip")[29], eb), "{n}");
        assert!(close(total("friction_utilisation")[24], ea), "{n}");
        assert!(close(total("friction_utilisation")[2], eb), "{n}");
        assert!(close(total("speed_mps")[12], ea), "{n}");
        assert!(close(total("speed_mps")[0], eb), "{n}");
        assert!(close(total("t_inner_c")[23], eb), "{n}");
        // Components: a slides along, b sideways.
        let slip = at("slip_ratio");
        assert!(close(m.map(Component::Longitudinal, slip)[14], ea), "{n}");
        assert!(close(m.map(Component::Lateral, slip)[15], eb), "{n}");
        assert_eq!(m.map(Component::Longitudinal, slip)[15], 0.0, "{n}");
        assert_eq!(m.map(Component::Lateral, slip)[14], 0.0, "{n}");
        // Every condition's map holds the whole energy.
        for (c, cd) in CONDITIONS.iter().enumerate() {
            let sum: f64 = m.map(Component::Total, c).iter().sum();
            assert!(close(sum, ea + eb), "{n}: {} sums to {sum}", cd.name);
        }
        // Pairs, on the coarse bins: a's combined slip 0.0099 → below the
        // first edge (0.03) → 0, T_surface 82 °C → (82 − 45)/5 = 7.4 → 7: cell 7; b's
        // combined slip 12 → last (7), 19 °C → 0: cell 7·8 = 56. Speed: a
        // 50.5 m/s → (50.5 − 24)/8 = 3.3 → 3: cell 3; b 0 → cell 56.
        let pair = |name: &str| (0..N_PAIRS).find(|&p| pair_name(p) == name).unwrap();
        let slip_surface = m.pair_map(pair("combined_slip:t_surface_c"));
        assert!(
            close(slip_surface[7], ea) && close(slip_surface[56], eb),
            "{n}"
        );
        let slip_speed = m.pair_map(pair("combined_slip:speed_mps"));
        assert!(close(slip_speed[3], ea) && close(slip_speed[56], eb), "{n}");
        for p in 0..N_PAIRS {
            let sum: f64 = m.pair_map(p).iter().sum();
            assert!(close(sum, ea + eb), "{n}: {} sums to {sum}", pair_name(p));
        }
    }
}

#[test]
fn energy_maps_by_hand_on_every_engine() {
    // 1500 samples at T_s 82 °C, T_i 101 °C, v_s 0.5 m/s, P = 1000 W;
    // 700 at T_s 19 (first bin), T_i 170 (last), v_s 12 m/s (last), P = 300 W
    // all lateral; 300 at T_s 52, T_i 61, v_s 2 m/s with the force along the
    // slip, P = −400 W (a negative sum: the maps keep signed energy);
    // 10 ms each. Each sum passes 2^32 quanta (256 J), so the carry between
    // the shader's lo and hi words is exercised in workgroup and global sums.
    let a = ReduceSample {
        vx: 50.5,
        omega: 100.0,
        radius: 0.5,
        fx: -2000.0,
        t_surface: 82.0,
        t_inner: 101.0,
        ..sample(0.01)
    };
    let b = ReduceSample {
        vx: 0.0,
        omega: 0.0,
        fx: 0.0,
        vy: 12.0,
        fy: -25.0,
        t_surface: 19.0,
        t_inner: 170.0,
        ..a
    };
    let c = ReduceSample {
        vx: 52.0,
        fx: 200.0,
        t_surface: 52.0,
        t_inner: 61.0,
        ..a
    };
    let mut wheel = vec![a; 1500];
    wheel.extend(vec![b; 700]);
    wheel.extend(vec![c; 300]);
    let mut batch = ReduceBatch::default();
    batch.push_wheel(&wheel);
    let (ea, eb, ec) = (
        1000.0 * 0.01 * 1500.0,
        300.0 * 0.01 * 700.0,
        -400.0 * 0.01 * 300.0,
    );
    for (e, tol) in engines("energy_maps_by_hand_on_every_engine") {
        let m = &e.energy_map(&batch).unwrap()[0];
        let close = |got: f64, want: f64| (got - want).abs() <= tol * want.abs();
        assert!(close(m.surface_inner[12 * 24 + 12], ea), "{}", e.name());
        assert!(close(m.speed_surface[24 + 12], ea), "{}", e.name());
        assert!(close(m.surface_inner[23], eb), "{}", e.name());
        assert!(close(m.speed_surface[19 * 24], eb), "{}", e.name());
        // c: T_s bin 6, T_i bin 4, v_s bin 4.
        assert!(close(m.surface_inner[6 * 24 + 4], ec), "{}", e.name());
        assert!(close(m.speed_surface[4 * 24 + 6], ec), "{}", e.name());
        assert!(close(m.total(), ea + eb + ec), "{}", e.name());
        // Lateral map: only b slides sideways (−F_y·v_sy = 300 W).
        assert!(close(m.lateral_surface_inner[23], eb), "{}", e.name());
        let lateral: f64 = m.lateral_surface_inner.iter().sum();
        assert!(close(lateral, eb), "{}", e.name());
    }
}

#[test]
fn energy_maps_do_not_depend_on_the_order_of_additions() {
    // Integer sums are exact: the CPU engine gives the same bits on one
    // thread or many and with its chunks reversed; the GPU engine gives the
    // same bits on every call and however the batch is cut into dispatches.
    let run = full_length_run();
    let mut batch = ReduceBatch::default();
    batch.push_wheel(&run[..40_000]);
    batch.push_wheel(&run[150_000..190_000]);
    let cpu = CpuEngine.energy_map(&batch).unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    assert_eq!(cpu, pool.install(|| CpuEngine.energy_map(&batch).unwrap()));
    let mut reversed = batch.clone();
    reversed.chunks.reverse();
    assert_eq!(cpu, CpuEngine.energy_map(&reversed).unwrap());
    let Some(mut g) = gpu_for_tests("energy_maps_do_not_depend_on_the_order_of_additions") else {
        return;
    };
    let gpu = g.energy_map(&batch).unwrap();
    assert_eq!(gpu, g.energy_map(&batch).unwrap());
    g.ctx.set_test_limits(5 * 1024, 3);
    assert_eq!(gpu, g.energy_map(&batch).unwrap());
}

#[test]
fn gpu_splits_batches_and_spreads_grids_in_2d() {
    let Some(mut g) = gpu_for_tests("gpu_splits_batches_and_spreads_grids_in_2d") else {
        return;
    };
    // 3 wheels, 38 chunks; at most 5 chunks per dispatch and 3 workgroups per grid row.
    let run = full_length_run();
    let mut batch = ReduceBatch::default();
    batch.push_wheel(&run[..15_000]);
    batch.push_wheel(&run[100_000..111_000]);
    batch.push_wheel(&run[200_000..212_000]);
    assert_eq!(batch.chunks.len(), 15 + 11 + 12);
    let unsplit = g.condition_map(&batch).unwrap();
    g.ctx.set_test_limits(5 * 1024, 3);
    let c = compare_telemetry(&CpuEngine, &g as &dyn ReduceEngine, &batch).unwrap();
    assert!(c.passes(), "{:?}", c.errors);
    let m = compare_energy_maps(&CpuEngine, &g as &dyn ReduceEngine, &batch).unwrap();
    assert!(m <= ENERGY_MAP_TOLERANCE, "{m}");
    // Exact sums: the split changes no bit of the condition maps.
    assert_eq!(g.condition_map(&batch).unwrap(), unsplit);
    // One upload for the three kernels gives what three calls give, bit for bit.
    let all = g.reductions(&batch).unwrap();
    assert_eq!(all.partials, g.telemetry_reduce(&batch).unwrap());
    assert_eq!(all.energy_maps, g.energy_map(&batch).unwrap());
    assert_eq!(all.condition_maps, g.condition_map(&batch).unwrap());
}

/// The pipelined extraction blocks rayon's threads while they hand decoded
/// runs to the thread that feeds the GPU, so the GPU engine may not wait for
/// them: it once copied its uploads on the rayon pool and hung on the first
/// season with more runs than threads (H200, 2026-11-26). Here every rayon
/// thread is held while the GPU reduces a batch large enough to be copied
/// by several threads (16 MB), which must still come back, and right.
#[test]
fn gpu_uploads_while_every_rayon_thread_is_blocked() {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::{Arc, RwLock};
    let Some(g) = gpu_for_tests("gpu_uploads_while_every_rayon_thread_is_blocked") else {
        return;
    };
    let mut batch = ReduceBatch::default();
    batch.push_wheel(&full_length_run()[..200_000]);
    // The CPU engine runs on the rayon pool: compared before the pool is held.
    let c = compare_telemetry(&CpuEngine, &g as &dyn ReduceEngine, &batch).unwrap();
    assert!(c.passes(), "{:?}", c.errors);
    let want = g.telemetry_reduce(&batch).unwrap();
    let gate = Arc::new(RwLock::new(()));
    let closed = gate.write().unwrap();
    let held = Arc::new(AtomicUsize::new(0));
    let threads = rayon::current_num_threads();
    for _ in 0..threads {
        let (gate, held) = (gate.clone(), held.clone());
        rayon::spawn(move || {
            held.fetch_add(1, Ordering::SeqCst);
            drop(gate.read().unwrap());
        });
    }
    while held.load(Ordering::SeqCst) < threads {
        std::thread::yield_now();
    }
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(g.telemetry_reduce(&batch).map_err(|e| e.to_string()));
    });
    // Minutes on lavapipe would mean a hang: the reduction takes a second.
    let got = rx.recv_timeout(std::time::Duration::from_secs(120));
    drop(closed);
    let got = got.expect("the GPU engine waited for the blocked rayon threads");
    assert_eq!(got.unwrap(), want);
}

#[test]
fn extract_on_gpu_equals_extract_on_cpu() {
    if gpu_for_tests("extract_on_gpu_equals_extract_on_cpu").is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    common::simulate_demo(dir.path());
    let tables: Vec<Vec<KpiRow>> = [Engine::Cpu, Engine::Gpu]
        .into_iter()
        .map(|engine| {
            let out = dir.path().join(format!("{engine:?}.parquet"));
            let s = extract(&ExtractOptions {
                engine,
                ..ExtractOptions::new(dir.path(), &out)
            })
            .unwrap();
            assert_eq!(s.engine, engine);
            read_parquet(&out).unwrap()
        })
        .collect();
    let (cpu, gpu) = (&tables[0], &tables[1]);
    assert_eq!(cpu.len(), gpu.len());
    assert!(cpu.len() >= 280);
    let mut worst = (String::new(), 0.0f64);
    for (c, g) in cpu.iter().zip(gpu) {
        assert_eq!((&c.run, &c.wheel), (&g.run, &g.wheel));
        for name in KpiRow::NUMBER_COLUMNS {
            let (x, y) = (c.number(name).unwrap(), g.number(name).unwrap());
            if x.is_nan() {
                assert!(y.is_nan(), "{name}");
                continue;
            }
            let spread = c
                .number(&name.replace("_avg_", "_std_"))
                .filter(|_| name.contains("_avg_"));
            let e = (x - y).abs() / (x.abs() + spread.unwrap_or(0.0)).max(1e-12);
            if e > worst.1 {
                worst = (format!("{name} ({} {})", c.run, c.wheel), e);
            }
        }
    }
    eprintln!(
        "GPU vs CPU on the demo season: largest scaled difference {:.2e} in {}",
        worst.1, worst.0
    );
    assert!(worst.1 <= TELEMETRY_TOLERANCE, "{worst:?}");

    // The GPU's pipelined route (the default: runs decoded while the device
    // reduces others) gives what reducing each run in turn gives, bit for
    // bit: the same kernels on the same batches.
    let gpu_bits = |rows: &[KpiRow]| -> Vec<Vec<u64>> {
        rows.iter()
            .map(|r| {
                KpiRow::NUMBER_COLUMNS
                    .iter()
                    .map(|n| r.number(n).unwrap().to_bits())
                    .collect()
            })
            .collect()
    };
    let serial_out = dir.path().join("serial.parquet");
    extract(&ExtractOptions {
        engine: Engine::Gpu,
        pipeline: false,
        ..ExtractOptions::new(dir.path(), &serial_out)
    })
    .unwrap();
    let serial = read_parquet(&serial_out).unwrap();
    assert_eq!(gpu_bits(gpu), gpu_bits(&serial));
    let maps = |p: &std::path::Path| tirewear::kpi::energy_maps::read_tire_maps(p).unwrap();
    assert_eq!(
        maps(&dir.path().join("Gpu.parquet")),
        maps(&serial_out),
        "energy maps"
    );

    // A run whose telemetry is cut short is skipped on the pipelined route
    // too, naming its file, and the other runs' rows are unchanged.
    let manifest = tirewear::ingest::manifest::Season::open(dir.path()).unwrap();
    let victim = &manifest.manifest.runs[3];
    let file = manifest.path(&victim.telemetry);
    let bytes = std::fs::read(&file).unwrap();
    std::fs::write(&file, &bytes[..bytes.len() / 2]).unwrap();
    let cut_out = dir.path().join("cut.parquet");
    let s = extract(&ExtractOptions {
        engine: Engine::Gpu,
        ..ExtractOptions::new(dir.path(), &cut_out)
    })
    .unwrap();
    assert_eq!(s.skipped.len(), 1, "{:?}", s.skipped);
    assert_eq!(s.skipped[0].run, victim.id);
    assert!(
        s.skipped[0].reason.contains(&victim.telemetry),
        "{}",
        s.skipped[0].reason
    );
    let kept: Vec<KpiRow> = gpu.iter().filter(|r| r.run != victim.id).cloned().collect();
    assert_eq!(gpu_bits(&kept), gpu_bits(&read_parquet(&cut_out).unwrap()));
}

/// Simulated road profiles as the simulator writes them (self-affine,
/// skewed), rounded to f32 so both routes see the same heights.
fn road_profiles() -> Vec<Vec<f64>> {
    use rand::SeedableRng;
    use tirewear::sim::road::{Amplitudes, gaussian_profile, shape_heights};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let tracks = tirewear::sim::preset::track_catalogue();
    [(0usize, 1usize << 14), (3, 20_000), (5, 1 << 17)]
        .iter()
        .map(|&(t, n)| {
            let road = &tracks[t].road;
            let mut z = gaussian_profile(road, n, 0.01, Amplitudes::Random, &mut rng);
            shape_heights(&mut z, road);
            z.iter().map(|&v| v as f32 as f64).collect()
        })
        .collect()
}

#[test]
fn roughness_on_every_engine_matches_the_f64_road_functions() {
    use tirewear::kpi::road::{HURST_BAND_MM, hdc, height_moments, hurst_from_psd, log_bin, psd};
    let profiles = road_profiles();
    let mut batch = tirewear::kpi::roughness_batch::RoughnessBatch::default();
    for z in &profiles {
        batch.push(z, 0.01);
    }
    let band = (
        std::f64::consts::TAU / HURST_BAND_MM.1,
        std::f64::consts::TAU / HURST_BAND_MM.0,
    );
    for (e, tol) in engines("roughness_on_every_engine_matches_the_f64_road_functions") {
        let (tol_sums, tol_psd) = if e.name() == "cpu" {
            (tol, tol)
        } else {
            ROUGHNESS_TOLERANCE
        };
        let out = e.roughness(&batch).unwrap();
        let (mut worst_m, mut worst_h, mut worst_p, mut worst_hurst) =
            (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for (o, z) in out.iter().zip(&profiles) {
            let m = height_moments(z);
            worst_m = worst_m
                .max((o.moments.0 - m.0).abs() / m.0)
                .max((o.moments.1 - m.1).abs() / m.1)
                .max((o.moments.2 - m.2).abs())
                .max((o.moments.3 - m.3).abs() / m.3);
            let (_, h) = hdc(z, 0.01);
            assert_eq!(o.hdc_c.len(), h.len());
            for (a, b) in o.hdc_c.iter().zip(&h) {
                worst_h = worst_h.max((a - b).abs() / b);
            }
            let (q, c) = psd(z, 0.01);
            let (bq, want) = log_bin(&q, &c, 48);
            let (_, got) = log_bin(&o.psd_q, &o.psd_c, 48);
            for ((qb, a), b) in bq.iter().zip(&got).zip(&want) {
                if *qb >= band.0 && *qb <= band.1 {
                    worst_p = worst_p.max((a - b).abs() / b);
                }
            }
            worst_hurst = worst_hurst
                .max((hurst_from_psd(&o.psd_q, &o.psd_c) - hurst_from_psd(&q, &c)).abs());
        }
        eprintln!(
            "{} engine: moments {worst_m:.2e}, HDC {worst_h:.2e}, PSD per log band {worst_p:.2e}, Hurst {worst_hurst:.1e}",
            e.name()
        );
        // The CPU twins see f32-rounded means for Ra (≤ 1e-6, see roughness_batch).
        assert!(
            worst_m <= tol_sums.max(1e-6) && worst_h <= tol_sums,
            "{}",
            e.name()
        );
        assert!(worst_p <= tol_psd.max(1e-6), "{}", e.name());
        assert!(worst_hurst <= 1e-4, "{}", e.name());
    }
}

#[test]
fn gpu_roughness_within_tolerance_of_the_cpu_twins() {
    let Some(g) = gpu_for_tests("gpu_roughness_within_tolerance_of_the_cpu_twins") else {
        return;
    };
    let profiles = road_profiles();
    let refs: Vec<(&[f64], f64)> = profiles.iter().map(|z| (z.as_slice(), 0.01)).collect();
    let groups = tirewear::kpi::roughness_batch::batches(&refs);
    assert_eq!(groups.len(), 1);
    let (m, h, p) = compare_roughness(&CpuEngine, &g, &groups[0].1).unwrap();
    eprintln!("GPU vs CPU twins: moments {m:.2e}, HDC {h:.2e}, PSD per band {p:.2e}");
    let (tol_sums, tol_psd) = ROUGHNESS_TOLERANCE;
    assert!(
        m <= tol_sums && h <= tol_sums && p <= tol_psd,
        "{m} {h} {p}"
    );
}

#[test]
fn road_indices_on_every_engine_match_the_cpu_route() {
    use tirewear::ingest::road::Profile;
    use tirewear::kpi::road::profile_indices;
    let mut profiles: Vec<Profile> = road_profiles()
        .into_iter()
        .enumerate()
        .map(|(i, z)| Profile {
            track: format!("t{}", i % 3),
            location: format!("L{i}"),
            x0_mm: 0.0,
            dx_mm: 0.01,
            z_mm: z,
        })
        .collect();
    // One profile shorter than a Welch segment takes the CPU route on every engine.
    let mut short = profiles[0].clone();
    short.z_mm.truncate(3000);
    short.location = "short".into();
    profiles.push(short);
    // The CPU route's indices are checked against SurfaceTopography and numpy
    // in tests/oracle_kpi.rs; here the engines' `road_indices` must give
    // them back per profile, in order, with their labels (on the CPU engine
    // that is the plumbing; on the GPU engine, the kernels within `tol`).
    let want: Vec<_> = profiles.iter().map(|p| profile_indices(p).0).collect();
    for (e, tol) in engines("road_indices_on_every_engine_match_the_cpu_route") {
        let got = e.road_indices(profiles.clone()).unwrap();
        assert_eq!(got.len(), profiles.len());
        let mut worst = 0.0f64;
        for (((p, g, _), w), q) in got.iter().zip(&want).zip(&profiles) {
            assert_eq!((&p.track, &p.location), (&q.track, &q.location));
            let pairs = [
                (g.macro_wavelength_mm, w.macro_wavelength_mm),
                (g.micro_wavelength_mm, w.micro_wavelength_mm),
                (g.hurst, w.hurst),
                (g.hurst_hdc, w.hurst_hdc),
                (g.ra_macro_mm, w.ra_macro_mm),
                (g.ra_micro_mm, w.ra_micro_mm),
                (g.peakyness_mm, w.peakyness_mm),
                (g.skewness, w.skewness),
                (g.kurtosis, w.kurtosis),
                (g.rq_mm, w.rq_mm),
                (g.ra_mm, w.ra_mm),
            ];
            for (a, b) in pairs {
                assert_eq!(a.is_nan(), b.is_nan(), "{} {}", e.name(), p.location);
                if !b.is_nan() {
                    // Dimensionless indices near 0 (skewness) on an absolute scale.
                    worst = worst.max((a - b).abs() / b.abs().max(1.0));
                }
            }
        }
        eprintln!("{} engine: road indices within {worst:.2e}", e.name());
        // The CPU engine takes this very route; the GPU's f32 kernels are
        // held to the telemetry tolerance, as in extract_on_gpu_equals_extract_on_cpu.
        let limit = if e.name() == "cpu" {
            0.0
        } else {
            TELEMETRY_TOLERANCE.max(tol)
        };
        assert!(worst <= limit, "{} engine: {worst:e}", e.name());
    }
}

/// `--engine auto` decides on the adapter before building its device and
/// kernels: `new_hardware` opens the adapter `GpuEngine::new` opens when it
/// is a hardware one and only describes it when it is a software one
/// (lavapipe in CI: `Err` with the same adapter).
#[test]
fn new_hardware_refuses_exactly_the_software_adapter_new_opens() {
    use tirewear::engine::GpuEngine;
    let Some(full) = gpu_for_tests("new_hardware_refuses_exactly_the_software_adapter_new_opens")
    else {
        return;
    };
    let software = full.ctx.adapter.device_type == wgpu::DeviceType::Cpu;
    match GpuEngine::new_hardware().unwrap() {
        Ok(hardware) => {
            assert!(!software, "{}", full.device());
            assert_eq!(hardware.device(), full.device());
        }
        Err(info) => {
            assert!(
                software,
                "{info:?} refused but {} is hardware",
                full.device()
            );
            assert_eq!(info.name, full.ctx.adapter.name);
            assert_eq!(info.backend, full.ctx.adapter.backend);
        }
    }
}
