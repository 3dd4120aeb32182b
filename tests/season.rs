//! End-to-end tests of the season archive: the simulator writes it, the
//! readers read every file back, and the physics checks out by hand.

mod common;

use std::path::Path;
use tirewear::Wheel;
use tirewear::ingest::compound::Compound;
use tirewear::ingest::manifest::Season;
use tirewear::ingest::road::{read_profile_csv, read_profiles_parquet};
use tirewear::ingest::telemetry::{Encoding, read_telemetry, read_telemetry_linear};
use tirewear::ingest::wear::read_wear_csv;
use tirewear::sim::{Effect, Preset, SimOptions, simulate};

fn sim(out: &Path, seed: u64, encoding: Encoding, noise: bool, effects: Vec<Effect>) {
    let opts = SimOptions {
        preset: Preset::Tiny,
        scale: 1.0,
        tracks: None,
        seed,
        effects,
        generated: None,
        scatter: tirewear::sim::WearScatter::NONE,
        encoding,
        rate_hz: None,
        out: out.to_path_buf(),
        sensor_noise: noise,
        logger_export: None,
        progress: false,
    };
    let s = simulate(&opts).unwrap();
    assert_eq!(s.observations, 16);
}

#[derive(Debug, serde::Deserialize)]
struct TruthRow {
    run: String,
    wheel: Wheel,
    friction_energy_j: f64,
    wear_base_pct: f64,
    wear_irregular_pct: f64,
    wear_graining_pct: f64,
    wear_blistering_pct: f64,
    wear_total_pct: f64,
}

fn truth<T: serde::de::DeserializeOwned>(dir: &Path) -> Vec<T> {
    csv::Reader::from_path(dir.join("truth/wear_truth.csv"))
        .unwrap()
        .deserialize()
        .map(Result::unwrap)
        .collect()
}

#[test]
fn every_file_of_a_simulated_season_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    sim(dir.path(), 11, Encoding::Block, true, vec![]);
    let season = Season::open(dir.path()).unwrap();
    let m = &season.manifest;
    assert_eq!((m.tracks.len(), m.events.len(), m.runs.len()), (2, 2, 4));
    for c in &m.compounds {
        let comp = Compound::load(&season.path(&c.file)).unwrap();
        assert_eq!(comp.id, c.id);
    }
    let bulk = read_profiles_parquet(&season.path(m.road_profiles.as_ref().unwrap())).unwrap();
    assert_eq!(bulk.len(), 2); // one bulk location per track, the other as CSV
    for t in &m.tracks {
        assert_eq!(t.profiles.len(), 1);
        let p = read_profile_csv(
            &season.path(&t.profiles[0].file),
            &t.id,
            &t.profiles[0].location,
        )
        .unwrap();
        assert_eq!(p.z_mm.len(), 1 << 12);
        assert!((p.dx_mm - 0.01).abs() < 1e-9);
    }
    let wear = read_wear_csv(&season.path(&m.wear_readings[0])).unwrap();
    assert_eq!(wear.len(), 16 * 7 * 3); // 16 tires x 7 spots x 3 readings
    #[derive(serde::Deserialize)]
    struct RunRow {
        run: String,
        samples: u64,
        dropped_samples: u64,
    }
    let runs: Vec<RunRow> = csv::Reader::from_path(dir.path().join("truth/runs.csv"))
        .unwrap()
        .deserialize()
        .map(Result::unwrap)
        .collect();
    for r in &m.runs {
        let tel = read_telemetry(&season.path(&r.telemetry)).unwrap();
        let rt = runs.iter().find(|x| x.run == r.id).unwrap();
        for w in Wheel::ALL {
            assert_eq!(
                tel.wheels[w.index()].len() as u64,
                rt.samples - rt.dropped_samples
            );
        }
        assert_eq!(tel.vehicle.len() as u64, rt.samples - rt.dropped_samples);
        // Distance channel reaches the planned run distance.
        let last = *tel.vehicle.distance_m.last().unwrap();
        assert!(
            last > 0.99 * r.distance_m - 100.0 && last <= r.distance_m,
            "{last} vs {}",
            r.distance_m
        );
    }
}

#[test]
fn same_seed_same_season_and_both_encodings_carry_the_same_samples() {
    let (a, b, c) = (
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
    );
    sim(a.path(), 5, Encoding::Block, true, vec![]);
    sim(b.path(), 5, Encoding::Sample, true, vec![]);
    sim(c.path(), 6, Encoding::Block, true, vec![]);
    let read = |d: &Path, f: &str| std::fs::read(d.join(f)).unwrap();
    assert_eq!(
        read(a.path(), "wear/readings.csv"),
        read(b.path(), "wear/readings.csv")
    );
    assert_eq!(
        read(a.path(), "truth/wear_truth.csv"),
        read(b.path(), "truth/wear_truth.csv")
    );
    assert_ne!(
        read(a.path(), "wear/readings.csv"),
        read(c.path(), "wear/readings.csv")
    );
    let sa = Season::open(a.path()).unwrap();
    for r in &sa.manifest.runs {
        let ta = read_telemetry(&a.path().join(&r.telemetry)).unwrap();
        let tb = read_telemetry(&b.path().join(&r.telemetry)).unwrap();
        assert_eq!(ta.encoding, Some(Encoding::Block));
        assert_eq!(tb.encoding, Some(Encoding::Sample));
        assert_eq!(ta.wheels, tb.wheels);
        assert_eq!(ta.vehicle, tb.vehicle);
        // The parallel chunk reader and the linear reader return the same data.
        assert_eq!(
            read_telemetry_linear(&a.path().join(&r.telemetry)).unwrap(),
            ta
        );
        assert_eq!(
            read_telemetry_linear(&b.path().join(&r.telemetry)).unwrap(),
            tb
        );
    }
}

#[test]
fn friction_energy_recomputed_from_telemetry_equals_the_truth() {
    // Ideal sensors: the energy by paper eqs. 19-25 from the logged channels,
    // P = -(Fx (vx - Ω R) + Fy vy), summed with the sample period, equals the
    // simulator's internal f64 integral up to f32 storage of the channels.
    let dir = tempfile::tempdir().unwrap();
    sim(dir.path(), 9, Encoding::Block, false, vec![]);
    let season = Season::open(dir.path()).unwrap();
    let truth = truth::<TruthRow>(dir.path());
    for r in &season.manifest.runs {
        let tel = read_telemetry(&season.path(&r.telemetry)).unwrap();
        for w in Wheel::ALL {
            let s = &tel.wheels[w.index()];
            let dt = 1.0 / 20.0;
            let e: f64 = (0..s.len())
                .map(|i| {
                    let vsx =
                        s.vx_mps[i] as f64 - s.omega_radps[i] as f64 * s.rolling_radius_m[i] as f64;
                    -(s.fx_n[i] as f64 * vsx + s.fy_n[i] as f64 * s.vy_mps[i] as f64) * dt
                })
                .sum();
            let t = truth
                .iter()
                .find(|t| t.run == r.id && t.wheel == w)
                .unwrap();
            // f32 channels: v_sx = vx - ΩR loses ~1e-6 m/s against a few m/s of sliding.
            assert!(
                (e / t.friction_energy_j - 1.0).abs() < 2e-4,
                "{} {w}: {e} vs {}",
                r.id,
                t.friction_energy_j
            );
        }
    }
}

#[test]
fn planted_effect_adds_wear_only_where_it_acts() {
    let (clean, planted) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    sim(clean.path(), 4, Encoding::Block, true, vec![]);
    let graining: Effect = "graining=1.0,threshold=95".parse().unwrap();
    let blistering: Effect = "blistering=1.0".parse().unwrap();
    sim(
        planted.path(),
        4,
        Encoding::Block,
        true,
        vec![graining, blistering],
    );
    let (c, p) = (
        truth::<TruthRow>(clean.path()),
        truth::<TruthRow>(planted.path()),
    );
    let mut front = 0.0;
    let mut rear = 0.0;
    for (a, b) in c.iter().zip(&p) {
        // The effects change wear, not the physics: base wear and energy are identical.
        assert_eq!(a.friction_energy_j, b.friction_energy_j);
        assert_eq!(a.wear_base_pct, b.wear_base_pct);
        assert_eq!(a.wear_graining_pct, 0.0);
        assert_eq!(a.wear_blistering_pct, 0.0);
        let sum =
            b.wear_base_pct + b.wear_irregular_pct + b.wear_graining_pct + b.wear_blistering_pct;
        assert!((b.wear_total_pct - sum).abs() < 1e-9);
        match b.wheel.axle() {
            tirewear::Axle::Front => front += b.wear_graining_pct,
            tirewear::Axle::Rear => rear += b.wear_graining_pct,
        }
        assert!(b.wear_blistering_pct >= 0.0);
    }
    // Graining acts on the fronts (rears at a fifth of the rate per joule).
    assert!(front > 0.0 && front > rear, "front {front} rear {rear}");
    // Irregular wear only on the fronts.
    assert!(
        c.iter()
            .filter(|t| t.wheel.axle() == tirewear::Axle::Rear)
            .all(|t| t.wear_irregular_pct == 0.0)
    );
}

#[test]
fn damaged_telemetry_is_an_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    sim(dir.path(), 2, Encoding::Block, true, vec![]);
    let season = Season::open(dir.path()).unwrap();
    let path = season.path(&season.manifest.runs[0].telemetry);
    let bytes = std::fs::read(&path).unwrap();
    // Truncated in the middle of the data section.
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let Err(err) = read_telemetry(&cut) else {
        panic!("a truncated file must fail")
    };
    let err = err.to_string();
    assert!(err.contains("cut.mcap"), "{err}");
    // A record length field overwritten with a huge value: an error, not an abort.
    let mut bad = bytes.clone();
    let pos = 8 + 1; // first record after the magic: its u64 length
    bad[pos..pos + 8].copy_from_slice(&u64::MAX.to_le_bytes());
    let badp = dir.path().join("bad-length.mcap");
    std::fs::write(&badp, &bad).unwrap();
    let Err(err) = read_telemetry(&badp) else {
        panic!("a corrupt header must fail")
    };
    let err = err.to_string();
    assert!(err.contains("bad-length.mcap"), "{err}");
    // Flipped bytes inside compressed chunks: every outcome is an error or a clean read, never a panic.
    for k in 1..20 {
        let mut flipped = bytes.clone();
        let i = bytes.len() * k / 21;
        flipped[i] ^= 0x5a;
        let p = dir.path().join(format!("flip{k}.mcap"));
        std::fs::write(&p, &flipped).unwrap();
        if let Err(e) = read_telemetry(&p) {
            assert!(e.to_string().contains(&format!("flip{k}.mcap")));
        }
    }
}

#[test]
fn manifest_errors_name_the_record() {
    let dir = tempfile::tempdir().unwrap();
    sim(dir.path(), 2, Encoding::Block, true, vec![]);
    let p = dir.path().join("season.toml");
    let text = std::fs::read_to_string(&p).unwrap();
    let first_event = Season::open(dir.path()).unwrap().manifest.runs[0]
        .event
        .clone();
    std::fs::write(
        &p,
        text.replacen(
            &format!("event = \"{first_event}\""),
            "event = \"E99-nowhere\"",
            1,
        ),
    )
    .unwrap();
    let err = Season::open(dir.path()).unwrap_err().to_string();
    assert!(
        err.contains("season.toml") && err.contains("runs[0]") && err.contains("E99-nowhere"),
        "{err}"
    );
}

/// `wear_scatter_factor` in the truth is the factor that multiplied the
/// tire's wear: the same season without scatter has every factor 1 and
/// each tire's wear equal to the scattered one over its factor.
#[test]
fn the_truth_s_scatter_factor_is_what_multiplied_the_wear() {
    #[derive(serde::Deserialize)]
    struct Row {
        run: String,
        wheel: Wheel,
        wear_base_pct: f64,
        wear_total_pct: f64,
        wear_scatter_factor: f64,
    }
    let season = |scatter| {
        let dir = tempfile::tempdir().unwrap();
        simulate(&SimOptions {
            preset: Preset::Tiny,
            scale: 1.0,
            tracks: None,
            seed: 11,
            effects: vec![],
            generated: None,
            scatter,
            encoding: Encoding::Block,
            rate_hz: None,
            out: dir.path().to_path_buf(),
            sensor_noise: true,
            logger_export: None,
            progress: false,
        })
        .unwrap();
        truth::<Row>(dir.path())
    };
    let plain = season(tirewear::sim::WearScatter::NONE);
    let scattered = season(tirewear::sim::WearScatter::REALISTIC);
    assert_eq!(plain.len(), 16);
    assert_eq!(plain.len(), scattered.len());
    for (p, s) in plain.iter().zip(&scattered) {
        assert_eq!((&p.run, p.wheel), (&s.run, s.wheel));
        assert_eq!(p.wear_scatter_factor, 1.0);
        for (a, b) in [
            (p.wear_base_pct, s.wear_base_pct),
            (p.wear_total_pct, s.wear_total_pct),
        ] {
            let back = b / s.wear_scatter_factor;
            assert!(
                (back - a).abs() <= 1e-9 * a.abs(),
                "{} {:?}: {a} vs {back}",
                p.run,
                p.wheel
            );
        }
    }
    // The realistic factors vary from tire to tire (σ ≈ 0.25 in the log).
    let logs: Vec<f64> = scattered
        .iter()
        .map(|s| s.wear_scatter_factor.ln())
        .collect();
    let mean = logs.iter().sum::<f64>() / logs.len() as f64;
    let sd =
        (logs.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / (logs.len() - 1) as f64).sqrt();
    assert!((0.1..0.5).contains(&sd), "{sd}");
}

/// Simulating into a folder that holds an earlier season: one simulated
/// by tirewear is replaced, its files the new season does not write are
/// removed and the outputs derived from it are reported as stale; a season
/// archive tirewear did not simulate (a team's own) is refused untouched,
/// and so is a file in the folder's place. Before, the team's manifest,
/// compounds and wear readings were overwritten without a word, and the
/// earlier season's telemetry stayed beside the new one.
#[test]
fn an_earlier_season_is_replaced_only_when_tirewear_simulated_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("season");
    let opts = |tracks| SimOptions {
        preset: Preset::Tiny,
        scale: 1.0,
        tracks,
        seed: 7,
        effects: vec![],
        generated: None,
        scatter: tirewear::sim::WearScatter::NONE,
        encoding: Encoding::Block,
        rate_hz: Some(5.0),
        out: out.clone(),
        sensor_noise: false,
        logger_export: None,
        progress: false,
    };
    let first = simulate(&opts(Some(3))).unwrap();
    assert!(first.stale_outputs.is_empty() && first.removed_files == 0);
    let listed = |dir: &Path| -> std::collections::BTreeSet<std::path::PathBuf> {
        Season::open(dir)
            .unwrap()
            .input_files()
            .into_iter()
            .map(|(_, p)| p)
            .collect()
    };
    let earlier = listed(&out);
    std::fs::write(out.join("kpis.parquet"), b"from the earlier season").unwrap();
    let second = simulate(&opts(None)).unwrap();
    let now = listed(&out);
    let gone: Vec<_> = earlier.difference(&now).collect();
    assert!(!gone.is_empty(), "three tracks, then the preset's two");
    assert_eq!(second.removed_files, gone.len());
    assert!(gone.iter().all(|p| !p.exists()), "{gone:?}");
    assert!(now.iter().all(|p| p.exists()));
    assert_eq!(second.stale_outputs, [out.join("kpis.parquet")]);
    // The same season again: nothing removed, nothing stale.
    let again = simulate(&opts(None)).unwrap();
    assert!(again.stale_outputs.is_empty() && again.removed_files == 0);

    let man = out.join("season.toml");
    let text = std::fs::read_to_string(&man).unwrap();
    let team = common::with_line(&text, "description", "description = \"Team data 2026\"");
    std::fs::write(&man, &team).unwrap();
    std::fs::remove_dir_all(out.join("truth")).unwrap();
    let wear = std::fs::read(out.join("wear/readings.csv")).unwrap();
    let e = simulate(&opts(None)).unwrap_err().to_string();
    assert!(
        e.contains("tirewear did not simulate") && e.contains("give a new folder"),
        "{e}"
    );
    assert_eq!(std::fs::read_to_string(&man).unwrap(), team);
    assert_eq!(std::fs::read(out.join("wear/readings.csv")).unwrap(), wear);

    let file = dir.path().join("file");
    std::fs::write(&file, b"x").unwrap();
    let mut o = opts(None);
    o.out = file;
    let e = simulate(&o).unwrap_err().to_string();
    assert!(e.contains("is a file, not a folder"), "{e}");
}
