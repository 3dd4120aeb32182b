//! `tirewear extract` end to end: the demo season gives at least 280 complete
//! rows; a damaged telemetry file fails only its own run, named; outputs and
//! side tables are written.

use std::path::Path;
use tirewear::ingest::manifest::Season;
use tirewear::ingest::telemetry::Encoding;
use tirewear::kpi::table::read_parquet;
use tirewear::kpi::{Engine, ExtractOptions, KpiRow, extract};
use tirewear::sim::{Preset, SimOptions, simulate};

mod common;

fn sim(out: &Path, preset: Preset, rate: f64) {
    simulate(&SimOptions {
        preset,
        scale: 1.0,
        tracks: None,
        seed: 7,
        effects: vec![],
        generated: None,
        scatter: tirewear::sim::WearScatter::NONE,
        encoding: Encoding::Block,
        rate_hz: Some(rate),
        out: out.to_path_buf(),
        sensor_noise: true,
        logger_export: None,
        progress: false,
    })
    .unwrap();
}

fn opts(season: &Path, out: &Path) -> ExtractOptions {
    ExtractOptions {
        csv: Some(out.join("kpis.csv")),
        engine: Engine::Auto,
        ..ExtractOptions::new(season, out.join("kpis.parquet"))
    }
}

#[test]
fn demo_season_extracts_to_complete_rows() {
    let dir = tempfile::tempdir().unwrap();
    sim(dir.path(), Preset::Demo, 5.0);
    let s = extract(&opts(dir.path(), dir.path())).unwrap();
    assert!(
        s.skipped.is_empty() && s.warnings.is_empty(),
        "{:?} {:?}",
        s.skipped,
        s.warnings
    );
    let rows = read_parquet(&dir.path().join("kpis.parquet")).unwrap();
    assert!(rows.len() >= 280);
    assert_eq!(rows.len(), s.rows);
    for r in &rows {
        for c in KpiRow::NUMBER_COLUMNS {
            assert!(
                r.number(c).unwrap().is_finite(),
                "run {} {}: {c} missing",
                r.run,
                r.wheel
            );
        }
    }
    // CSV has the same rows; side tables exist.
    let csv_rows = csv::Reader::from_path(dir.path().join("kpis.csv"))
        .unwrap()
        .records()
        .count();
    assert_eq!(csv_rows, rows.len());
    for side in [
        "kpis.road.parquet",
        "kpis.energy_maps.parquet",
        "kpis.condition_maps.parquet",
        "kpis.report.json",
    ] {
        assert!(dir.path().join(side).exists(), "{side}");
    }
    // The energy maps read back: one per row, each holding the row's friction
    // energy (both maps bin every sample's energy once), and the lateral map
    // its lateral energy. One engine computed maps and KPIs: the CPU sums f32
    // channels in f64 (1e-9); a GPU (`auto` takes a hardware one) sums the
    // KPIs in f32 and the maps in fixed-point quanta, so they agree to f32's
    // tolerance (1e-5 relative, docs/performance.md "Precision"; 1.4e-8 seen
    // on an H200).
    let rel = match s.engine {
        Engine::Gpu => 1e-5,
        _ => 1e-9,
    };
    let maps =
        tirewear::kpi::energy_maps::read_energy_maps(&dir.path().join("kpis.energy_maps.parquet"))
            .unwrap();
    assert_eq!(maps.len(), rows.len());
    for r in &rows {
        let m = &maps[&r.tire_run()];
        let close = |what: &str, got: f64, want: f64| {
            assert!(
                (got - want).abs() <= rel * want.abs(),
                "{} {}: {what} {got} vs {want}",
                r.run,
                r.wheel
            );
        };
        close("total", m.total(), r.friction_energy_j);
        close(
            "speed map",
            m.speed_surface.iter().sum(),
            r.friction_energy_j,
        );
        // The lateral map holds the lateral part, friction_energy_y_j.
        close(
            "lateral",
            m.lateral_surface_inner.iter().sum(),
            r.friction_energy_y_j,
        );
    }
    // The condition maps read back (format version checked): every
    // condition's map holds the row's friction energy, its longitudinal and
    // its lateral part, as the telemetry reduction summed them (quanta of
    // 6e-8 J per sample: 1e-3 J of slack, besides the engine's `rel`); so does every pair map, read
    // back through the side table's pair rows.
    let path = dir.path().join("kpis.condition_maps.parquet");
    let cmaps = tirewear::kpi::cpu::condition_map::read_condition_maps(&path).unwrap();
    assert_eq!(cmaps.len(), rows.len());
    use tirewear::kpi::cpu::condition_map::{CONDITIONS, Component, N_PAIRS, pair_name};
    for r in &rows {
        let m = &cmaps[&r.tire_run()];
        assert!(m.pairs_held);
        for p in 0..N_PAIRS {
            let got: f64 = m.pair_map(p).iter().sum();
            let want = r.friction_energy_j;
            assert!(
                (got - want).abs() <= rel * want.abs() + 1e-3,
                "{} {}: {} {got} vs {want}",
                r.run,
                r.wheel,
                pair_name(p)
            );
        }
        for (c, cd) in CONDITIONS.iter().enumerate() {
            for (comp, want) in [
                (Component::Total, r.friction_energy_j),
                (Component::Longitudinal, r.friction_energy_x_j),
                (Component::Lateral, r.friction_energy_y_j),
            ] {
                let got: f64 = m.map(comp, c).iter().sum();
                assert!(
                    (got - want).abs() <= rel * want.abs() + 1e-3,
                    "{} {}: {} {comp:?} {got} vs {want}",
                    r.run,
                    r.wheel,
                    cd.name
                );
            }
        }
    }
    // The extracted wear target tracks the simulator's truth (readings noise and
    // the virtual-rib interpolation of a non-uniform profile: within 3 points),
    // except on nearly bald tires, where the tread bottoms out before the law's wear.
    #[derive(serde::Deserialize)]
    struct T {
        run: String,
        wheel: String,
        wear_total_pct: f64,
    }
    let truth: Vec<T> = csv::Reader::from_path(dir.path().join("truth/wear_truth.csv"))
        .unwrap()
        .deserialize()
        .map(Result::unwrap)
        .collect();
    for r in &rows {
        let t = truth
            .iter()
            .find(|t| t.run == r.run && t.wheel == r.wheel.name())
            .unwrap();
        if t.wear_total_pct > 80.0 {
            continue;
        }
        assert!(
            (r.wear_mean_pct - t.wear_total_pct).abs() < 3.0,
            "{} {}: {} vs {}",
            r.run,
            r.wheel,
            r.wear_mean_pct,
            t.wear_total_pct
        );
    }
}

#[test]
fn a_damaged_run_fails_alone() {
    let dir = tempfile::tempdir().unwrap();
    sim(dir.path(), Preset::Tiny, 20.0);
    let season = Season::open(dir.path()).unwrap();
    let victim = season.manifest.runs[1].clone();
    let path = season.path(&victim.telemetry);
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() / 3]).unwrap();
    let s = extract(&opts(dir.path(), dir.path())).unwrap();
    assert_eq!(s.skipped.len(), 1);
    assert_eq!(s.skipped[0].run, victim.id);
    assert!(
        s.skipped[0].reason.contains(&victim.telemetry),
        "{}",
        s.skipped[0].reason
    );
    assert_eq!(s.rows, 12);
    // The same on the GPU engine.
    if tirewear::engine::gpu_for_tests("a_damaged_run_fails_alone").is_some() {
        let mut o = opts(dir.path(), dir.path());
        o.engine = Engine::Gpu;
        let g = extract(&o).unwrap();
        assert_eq!((g.rows, g.skipped.len()), (12, 1));
        assert_eq!(g.skipped[0].run, victim.id);
    }
}

/// Every file an extraction into `dir` wrote (`kpis*`), with its bytes.
fn outputs(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("kpis"))
        .map(|n| (n.clone(), std::fs::read(dir.join(&n)).unwrap()))
        .collect();
    files.sort();
    files
}

/// Before 2026-12-02 an extraction that could read none of its runs (every
/// telemetry file cut short, as a sync half done leaves them) wrote an
/// empty KPI table over the last good one and exited 3; a manifest with no
/// runs wrote an empty table and exited 0. Now both are errors naming what
/// was wrong, and the last good outputs stay byte for byte.
#[test]
fn an_extraction_that_reads_no_run_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let season_dir = dir.path().join("season");
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    sim(&season_dir, Preset::Tiny, 20.0);
    let good = extract(&opts(&season_dir, &out)).unwrap();
    assert_eq!((good.rows, good.skipped.len()), (16, 0));
    let before = outputs(&out);
    assert_eq!(before.len(), 6, "the table, three side tables, report, CSV");

    let season = Season::open(&season_dir).unwrap();
    for run in &season.manifest.runs {
        let path = season.path(&run.telemetry);
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    }
    let e = extract(&opts(&season_dir, &out)).unwrap_err().to_string();
    assert!(e.contains("none of its 4 runs could be read"), "{e}");
    assert!(e.contains("nothing was written"), "{e}");
    let first = &season.manifest.runs[0];
    assert!(e.contains(&format!("run {}: ", first.id)), "{e}");
    assert!(e.contains(&first.telemetry), "{e}");
    assert!(e.contains("and 1 more"), "{e}");
    assert_eq!(outputs(&out), before, "the last good outputs are kept");

    // A manifest that lists no runs (an archive started by hand).
    let manifest = season_dir.join("season.toml");
    let text = std::fs::read_to_string(&manifest).unwrap();
    let head = &text[..text.find("[[runs]]").unwrap()];
    let first_table = head.find("\n[").unwrap() + 1;
    let no_runs = format!(
        "{}runs = []\n{}",
        &head[..first_table],
        &head[first_table..]
    );
    std::fs::write(&manifest, no_runs).unwrap();
    let e = extract(&opts(&season_dir, &out)).unwrap_err().to_string();
    assert!(
        e.contains("season.toml: runs: the manifest lists no runs"),
        "{e}"
    );
    assert!(e.contains("docs/import.md"), "{e}");
    assert_eq!(outputs(&out), before);
}

/// A run that alone needs more memory than `--memory-limit` is skipped by
/// name (exit 3) and the others extracted as without a limit; the same on
/// the GPU engine's pipelined route.
/// A telemetry file that is a FIFO: opening it waits for a writer, so
/// before 2026-12-01 the extraction hung there (in the run's memory
/// estimate). Now the run is skipped, naming the file, and the rest are
/// extracted (on a timer: a hang fails the test instead of CI).
#[cfg(unix)]
#[test]
fn a_telemetry_file_that_is_a_fifo_is_skipped_not_waited_on() {
    let dir = tempfile::tempdir().unwrap();
    sim(dir.path(), Preset::Tiny, 5.0);
    let season = Season::open(dir.path()).unwrap();
    let victim = &season.manifest.runs[0];
    let mcap = dir.path().join(&victim.telemetry);
    std::fs::remove_file(&mcap).unwrap();
    let made = std::process::Command::new("mkfifo").arg(&mcap).status();
    assert!(made.is_ok_and(|s| s.success()), "mkfifo");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_tirewear"))
        .args(["--quiet", "--log", "error", "extract", "--engine", "cpu"])
        .arg(dir.path())
        .arg("--out")
        .arg(dir.path().join("k.parquet"))
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if start.elapsed() > std::time::Duration::from_secs(120) {
            child.kill().unwrap();
            panic!("extract still waiting on the FIFO after 120 s");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    };
    let mut text = String::new();
    std::io::Read::read_to_string(&mut child.stdout.take().unwrap(), &mut text).unwrap();
    assert_eq!(status.code(), Some(3), "{text}");
    assert!(
        text.contains(&format!("skipped run {}", victim.id)) && text.contains("not a regular file"),
        "{text}"
    );
    let rows = read_parquet(&dir.path().join("k.parquet")).unwrap();
    assert_eq!(rows.len(), 4 * (season.manifest.runs.len() - 1));
}

#[test]
fn a_run_above_the_memory_limit_is_skipped_alone() {
    let dir = tempfile::tempdir().unwrap();
    sim(dir.path(), Preset::Tiny, 20.0);
    let season = Season::open(dir.path()).unwrap();
    let (victim, largest, next) = common::hungriest_run(&season);
    assert!(next < largest);
    let free = extract(&opts(dir.path(), &dir.path().join("free"))).unwrap();
    let unlimited = read_parquet(&dir.path().join("free/kpis.parquet")).unwrap();
    assert!(free.skipped.is_empty());

    let out = std::process::Command::new(env!("CARGO_BIN_EXE_tirewear"))
        .args(["--quiet", "--log", "error", "extract", "--engine", "cpu"])
        .arg(dir.path())
        .arg("--out")
        .arg(dir.path().join("k.parquet"))
        .args(["--memory-limit", &(largest - 1).to_string()])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(3));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains(&format!("skipped run {}", victim.id)),
        "{text}"
    );
    assert!(
        text.contains(&victim.telemetry) && text.contains("of memory"),
        "{text}"
    );
    assert!(!text.contains("NaN"), "{text}");
    let limited = read_parquet(&dir.path().join("k.parquet")).unwrap();
    let kept: Vec<&KpiRow> = unlimited.iter().filter(|r| r.run != victim.id).collect();
    assert_eq!(limited.len(), kept.len());
    for (a, b) in limited.iter().zip(&kept) {
        assert_eq!(format!("{a:?}"), format!("{b:?}"));
    }
    if tirewear::engine::gpu_for_tests("a_run_above_the_memory_limit_is_skipped_alone").is_some() {
        let g = extract(&ExtractOptions {
            engine: Engine::Gpu,
            memory_limit: tirewear::memory::MemoryLimit::Bytes(largest - 1),
            ..opts(dir.path(), &dir.path().join("gpu"))
        })
        .unwrap();
        assert_eq!((g.rows, g.skipped.len()), (kept.len(), 1));
        assert_eq!(g.skipped[0].run, victim.id);
    }
}

#[test]
fn a_bad_energy_map_record_is_named() {
    use arrow_array::{ArrayRef, Float64Array, RecordBatch, StringArray, UInt32Array};
    use arrow_schema::{DataType, Field, Schema};
    use std::sync::Arc;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.energy_maps.parquet");
    let schema = Arc::new(Schema::new(vec![
        Field::new("run", DataType::Utf8, false),
        Field::new("wheel", DataType::Utf8, false),
        Field::new("map", DataType::Utf8, false),
        Field::new("i", DataType::UInt32, false),
        Field::new("j", DataType::UInt32, false),
        Field::new("energy_j", DataType::Float64, false),
    ]));
    let write = |i: Vec<u32>, j: Vec<u32>, map: &str, wheel: &str| {
        let cols: Vec<ArrayRef> = vec![
            Arc::new(StringArray::from(vec!["R1"; 3])),
            Arc::new(StringArray::from(vec!["FL", "FL", wheel])),
            Arc::new(StringArray::from(vec![
                "surface_inner",
                "surface_inner",
                map,
            ])),
            Arc::new(UInt32Array::from(i)),
            Arc::new(UInt32Array::from(j)),
            Arc::new(Float64Array::from(vec![10.0, 5.0, 2.0])),
        ];
        let batch = RecordBatch::try_new(schema.clone(), cols).unwrap();
        tirewear::kpi::table::write_batch(&path, &batch).unwrap();
        tirewear::kpi::energy_maps::read_energy_maps(&path)
    };
    let err = write(vec![3, 40, 0], vec![4, 2, 0], "surface_inner", "FL")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("bad.energy_maps.parquet")
            && err.contains("record 2")
            && err.contains("(40, 2)"),
        "{err}"
    );
    // A bin given twice for one tire is refused, not added up (a table
    // holds each bin of a tire once); the same bin of another map or
    // another wheel is not the same bin.
    let err = write(vec![3, 5, 3], vec![4, 6, 4], "surface_inner", "FL")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("record 3") && err.contains("(3, 4)") && err.contains("given twice"),
        "{err}"
    );
    for (map, wheel) in [("lateral_surface_inner", "FL"), ("surface_inner", "RR")] {
        let maps = write(vec![3, 5, 3], vec![4, 6, 4], map, wheel).unwrap();
        let fl = &maps[&("R1".to_string(), tirewear::Wheel::FL)];
        assert_eq!(fl.surface_inner.iter().sum::<f64>(), 15.0, "{map} {wheel}");
    }
}

/// A run on a machine without a display prints nothing but its own output:
/// Mesa's device-selection layer, which every Vulkan instance loads where
/// Mesa is installed (CI's lavapipe), printed "error: XDG_RUNTIME_DIR is
/// invalid or not set" twice from Wayland's client library until the
/// binary turned it off. Where no Vulkan layer is installed there is
/// nothing to print, and the test holds trivially.
#[test]
fn extract_without_a_display_prints_no_stray_errors() {
    let dir = tempfile::tempdir().unwrap();
    sim(dir.path(), Preset::Tiny, 5.0);
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_tirewear"))
        .args(["--quiet", "--log", "error", "extract", "--engine", "auto"])
        .arg(dir.path())
        .arg("--out")
        .arg(dir.path().join("kpis.parquet"))
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("DISPLAY")
        .env_remove("NODEVICE_SELECT")
        .env_remove("MESA_VK_DEVICE_SELECT")
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.trim().is_empty(), "stderr: {stderr}");
}

/// `extract` killed (SIGKILL) at random moments, as a nightly job can be:
/// the files visible afterwards always come from one extraction or carry a
/// journal that the next run completes; the next run leaves one complete set
/// (same extraction id everywhere) and no temporary file.
#[cfg(unix)]
#[test]
fn a_killed_extract_leaves_one_consistent_set() {
    use rand::{Rng, SeedableRng};
    use tirewear::kpi::table::read_extraction_id;
    let dir = tempfile::tempdir().unwrap();
    sim(dir.path(), Preset::Tiny, 5.0);
    let out = dir.path().join("out");
    let run = || {
        std::process::Command::new(env!("CARGO_BIN_EXE_tirewear"))
            .args(["--quiet", "--log", "error", "extract", "--engine", "cpu"])
            .arg(dir.path())
            .arg("--out")
            .arg(out.join("kpis.parquet"))
            .arg("--csv")
            .arg(out.join("kpis.csv"))
            .stdout(std::process::Stdio::null())
            .spawn()
            .unwrap()
    };
    let ids = || -> Vec<Option<String>> {
        [
            "kpis.parquet",
            "kpis.road.parquet",
            "kpis.energy_maps.parquet",
        ]
        .iter()
        .map(|f| {
            let p = out.join(f);
            p.exists().then(|| read_extraction_id(&p).unwrap().unwrap())
        })
        .collect()
    };
    let report_id = || -> Option<String> {
        let text = std::fs::read_to_string(out.join("kpis.report.json")).ok()?;
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        Some(v["extraction_id"].as_str().unwrap().to_string())
    };
    let t0 = std::time::Instant::now();
    assert!(run().wait().unwrap().success());
    let full_ms = t0.elapsed().as_millis() as u64;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let mut mixed_without_journal = 0;
    for trial in 0..16 {
        let mut child = run();
        std::thread::sleep(std::time::Duration::from_millis(
            rng.random_range(0..full_ms.max(10) + 50),
        ));
        let _ = child.kill();
        child.wait().unwrap();
        let journal = out.join(".kpis.commit.json").exists();
        let mut seen: Vec<String> = ids().into_iter().flatten().collect();
        seen.extend(report_id());
        seen.dedup();
        if seen.len() > 1 && !journal {
            mixed_without_journal += 1;
            eprintln!("trial {trial}: mixed set {seen:?} and no journal");
        }
        // The next run completes or replaces the set, whatever state it found.
        assert!(run().wait().unwrap().success(), "trial {trial}");
        let after = ids();
        assert!(
            after.iter().all(|i| i.is_some() && *i == after[0]),
            "{after:?}"
        );
        assert_eq!(report_id(), after[0]);
        let left: Vec<String> = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".tmp") || n.ends_with(".commit.json"))
            .collect();
        assert!(left.is_empty(), "trial {trial}: left behind {left:?}");
    }
    assert_eq!(mixed_without_journal, 0);
}

/// Problems confined to one run, compound or track cost only those, named;
/// the rest of the season is extracted (docs/reliability.md).
#[test]
fn bad_inputs_cost_only_their_run_compound_or_track() {
    let dir = tempfile::tempdir().unwrap();
    sim(dir.path(), Preset::Tiny, 5.0);
    let season = Season::open(dir.path()).unwrap();
    let m = &season.manifest;
    let total_rows = 4 * m.runs.len();

    // A wear row whose tire set is not the one the manifest mounts, and rows
    // of a run the manifest does not know.
    let victim = &m.runs[0];
    let wear_path = season.path(&m.wear_readings[0]);
    let text = std::fs::read_to_string(&wear_path).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let line = lines
        .iter()
        .position(|l| l.starts_with(&format!("{},FL,", victim.id)))
        .unwrap();
    lines[line] = lines[line].replacen(&victim.tire_sets.fl, "TS-WRONG", 1);
    let ghost = lines[1].replacen(&lines[1][..lines[1].find(',').unwrap()], "ghost-run", 1);
    lines.push(ghost);
    std::fs::write(&wear_path, lines.join("\n") + "\n").unwrap();
    let s = extract(&opts(dir.path(), dir.path())).unwrap();
    assert_eq!(s.skipped.len(), 1, "{:?}", s.skipped);
    let reason = &s.skipped[0].reason;
    assert_eq!(s.skipped[0].run, victim.id);
    assert!(
        reason.contains("readings.csv")
            && reason.contains(&format!("line {}", line + 1))
            && reason.contains("TS-WRONG"),
        "{reason}"
    );
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("ghost-run") && w.contains("not in the manifest")),
        "{:?}",
        s.warnings
    );
    assert_eq!(s.rows, total_rows - 4);
    std::fs::write(&wear_path, &text).unwrap();

    // A compound file whose id is not the manifest's: its runs are skipped.
    let c = &m.compounds[0];
    let cpath = season.path(&c.file);
    let ctext = std::fs::read_to_string(&cpath).unwrap();
    std::fs::write(
        &cpath,
        ctext.replacen(&format!("id = \"{}\"", c.id), "id = \"other\"", 1),
    )
    .unwrap();
    let s = extract(&opts(dir.path(), dir.path())).unwrap();
    let on_c = m.runs.iter().filter(|r| r.compound == c.id).count();
    assert_eq!(s.skipped.len(), on_c);
    assert!(s.skipped.iter().all(|k| k.reason.contains("'other'")));
    std::fs::write(&cpath, &ctext).unwrap();

    // WLF t_ref_c = NaN (it panicked in the master-curve lookup before).
    std::fs::write(
        &cpath,
        common::with_line(&ctext, "t_ref_c", "t_ref_c = nan"),
    )
    .unwrap();
    let s = extract(&opts(dir.path(), dir.path())).unwrap();
    assert_eq!(s.skipped.len(), on_c);
    assert!(s.skipped.iter().all(|k| k.reason.contains("t_ref_c")));
    std::fs::write(&cpath, &ctext).unwrap();

    // A flat road profile for every location of one track (the bulk file
    // rewritten): that track's rows keep their telemetry KPIs and flag the
    // road ones; the other tracks' rows are complete.
    let bulk = season.path(m.road_profiles.as_ref().unwrap());
    let profiles = tirewear::ingest::road::read_profiles_parquet(&bulk).unwrap();
    let flat_track = m.events[0].track.clone();
    let mut changed = profiles.clone();
    for p in changed.iter_mut().filter(|p| p.track == flat_track) {
        p.z_mm.iter_mut().for_each(|z| *z = 0.0);
    }
    tirewear::ingest::road::write_profiles_parquet(&bulk, &changed).unwrap();
    for t in &m.tracks {
        for p in t.profiles.iter().filter(|_| t.id == flat_track) {
            std::fs::remove_file(season.path(&p.file)).unwrap();
        }
    }
    let s = extract(&opts(dir.path(), dir.path())).unwrap();
    assert_eq!((s.rows, s.skipped.len()), (total_rows, 0));
    assert!(
        s.warnings.iter().any(|w| w.contains("flat")),
        "{:?}",
        s.warnings
    );
    let rows = read_parquet(&dir.path().join("kpis.parquet")).unwrap();
    for r in &rows {
        if r.track == flat_track {
            assert!(r.hurst.is_nan() && r.friction_energy_j.is_finite());
            assert!(
                r.quality.contains("no usable road profile")
                    && r.quality.contains("not finite: ")
                    && r.quality.contains("hurst"),
                "{}",
                r.quality
            );
        } else {
            assert_eq!(r.quality, "ok");
        }
    }
}

/// Manifest paths that leave the archive are refused unless allowed.
#[test]
fn manifest_paths_stay_inside_the_archive() {
    let dir = tempfile::tempdir().unwrap();
    sim(dir.path(), Preset::Tiny, 5.0);
    let man = dir.path().join("season.toml");
    let text = std::fs::read_to_string(&man).unwrap();
    let season = Season::open(dir.path()).unwrap();
    let tel = season.manifest.runs[0].telemetry.clone();
    let outside = dir.path().join("elsewhere.mcap");
    std::fs::copy(season.path(&tel), &outside).unwrap();
    std::fs::write(
        &man,
        text.replacen(
            &format!("\"{tel}\""),
            &format!("\"{}\"", outside.display()),
            1,
        ),
    )
    .unwrap();
    let err = extract(&opts(dir.path(), dir.path()))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("season.toml") && err.contains("leaves the archive folder"),
        "{err}"
    );
    let mut o = opts(dir.path(), dir.path());
    o.allow_external_paths = true;
    assert_eq!(extract(&o).unwrap().skipped.len(), 0);
}

/// `tirewear bench --season DIR` with a folder that is no season archive
/// fails (exit 1) naming it, and writes no bench.json: a bench that
/// measured the demo instead would mislead the comparison.
#[test]
fn bench_refuses_a_season_it_cannot_open() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench.json");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_tirewear"))
        .args([
            "--quiet", "bench", "--only", "decode", "--small", "--season",
        ])
        .arg(dir.path().join("no-season"))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(1));
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        err.contains("--season") && err.contains("no-season"),
        "{err}"
    );
    assert!(!out.exists());
}

/// `tirewear bench --out` that would lose a file is refused before the
/// minutes of measuring (exit 1, the file named, every file as it was): a
/// file of the season measured, a folder, a file where a folder would be
/// made, and a file that is no earlier bench result (a KPI table, a model).
/// `bench --out season.toml` once replaced the manifest with the results.
#[test]
fn bench_refuses_an_out_that_would_lose_a_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let season = d.join("season");
    common::copy_dir(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/handwritten"),
        &season,
    );
    std::fs::write(d.join("kpis.parquet"), b"PAR1 not really").unwrap();
    std::fs::write(d.join("physical.json"), b"{\"method\": \"physical\"}").unwrap();
    let files = |d: &std::path::Path| {
        let mut all = Vec::new();
        let mut stack = vec![d.to_path_buf()];
        while let Some(f) = stack.pop() {
            for e in std::fs::read_dir(&f).unwrap() {
                let p = e.unwrap().path();
                if p.is_dir() {
                    stack.push(p);
                } else {
                    all.push((p.clone(), std::fs::read(&p).unwrap()));
                }
            }
        }
        all.sort();
        all
    };
    let before = files(d);
    for (out, said) in [
        (
            "season/season.toml",
            "is an input of this command (the season manifest)",
        ),
        (
            "season/telemetry/H1-car1-R1.mcap",
            "is an input of this command (telemetry of run",
        ),
        ("season", "is a folder"),
        ("kpis.parquet/bench.json", "which is a file, not a folder"),
        (
            "kpis.parquet",
            "is not an earlier `tirewear bench` result (it is a Parquet file)",
        ),
        (
            "physical.json",
            "is not an earlier `tirewear bench` result (it is JSON without",
        ),
    ] {
        let run = std::process::Command::new(env!("CARGO_BIN_EXE_tirewear"))
            .args([
                "--quiet", "bench", "--only", "decode", "--small", "--season",
            ])
            .arg(&season)
            .arg("--out")
            .arg(d.join(out))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(1), "{out}: {err}");
        assert!(err.contains(said), "{out}: {err}");
        assert!(err.contains(&*d.join(out).to_string_lossy()), "{err}");
    }
    assert!(files(d) == before, "a file changed or appeared");
}

/// `tirewear bench --only decode --season DIR` measures the given archive:
/// its lines name it, count every sample the simulator wrote (without
/// sensor noise no sample is dropped), and nothing is skipped.
#[test]
fn bench_decode_lines_measure_a_given_season() {
    use tirewear::bench::{BenchOptions, BenchParts, run_bench};
    let dir = tempfile::tempdir().unwrap();
    let season = dir.path().join("season");
    let summary = simulate(&SimOptions {
        preset: Preset::Tiny,
        scale: 1.0,
        tracks: None,
        seed: 3,
        effects: vec![],
        generated: None,
        scatter: tirewear::sim::WearScatter::NONE,
        encoding: Encoding::Sample,
        rate_hz: Some(10.0),
        out: season.clone(),
        sensor_noise: false,
        logger_export: None,
        progress: false,
    })
    .unwrap();
    let r = run_bench(&BenchOptions {
        small: true,
        gpu: false,
        repeats: 1,
        parts: BenchParts::Decode,
        season: Some(season),
    });
    assert!(r.notes.is_empty(), "{:?}", r.notes);
    let engines: Vec<&str> = r.lines.iter().map(|l| l.engine.as_str()).collect();
    for e in [
        "zstd only, 1 thread",
        "tirewear, 1 thread",
        "extract, 1 thread",
    ] {
        assert!(engines.contains(&e), "{engines:?}");
    }
    assert_eq!(r.lines.len(), 6, "{engines:?}");
    for l in &r.lines {
        assert_eq!(l.kernel, "decode, season");
        assert!(
            l.size.starts_with(&format!("{} runs, ", summary.runs)),
            "{}",
            l.size
        );
        // The simulator counts time steps; each logs four wheels.
        let (samples, want) = (l.items_per_s * l.seconds, 4.0 * summary.samples as f64);
        assert!(
            (samples - want).abs() < 1e-6 * want,
            "{samples} against {want}"
        );
        assert!(l.vs_memory_pass > 0.0 && l.vs_memory_pass.is_finite());
    }
    // The one-thread extraction's split: its stages were timed inside the
    // runs, one after another on one thread, so together they fit in the
    // wall time the line measured, and each took some time.
    let [x] = &r.extract_splits[..] else {
        panic!("one split expected: {:?}", r.extract_splits)
    };
    let line = |e: &str| r.lines.iter().find(|l| l.engine == e).unwrap().seconds;
    assert_eq!(x.kernel, "decode, season");
    assert_eq!(x.wall_s, line("extract, 1 thread"));
    assert_eq!(x.zstd_s, line("zstd only, 1 thread"));
    assert!(
        x.decode_s > 0.0 && x.cleaning_s > 0.0 && x.reductions_s > 0.0,
        "{x:?}"
    );
    assert!(
        x.decode_s + x.cleaning_s + x.reductions_s <= x.wall_s && x.rest_s >= 0.0,
        "{x:?}"
    );
}

/// Outputs that would replace the season's own files, or each other, or
/// that name a folder are refused before any run is read, naming the file
/// and both roles; the archive is left byte for byte as it was
/// (`--out DIR/season.toml` once replaced the manifest with the KPI table).
#[test]
fn outputs_over_the_inputs_or_each_other_are_refused_before_the_work() {
    let dir = tempfile::tempdir().unwrap();
    let season = dir.path().join("season");
    sim(&season, Preset::Tiny, 5.0);
    let man = season.join("season.toml");
    let before = std::fs::read(&man).unwrap();
    let tel = Season::open(&season).unwrap().manifest.runs[0]
        .telemetry
        .clone();
    let refused = |out: &Path, csv: Option<&Path>| {
        let o = ExtractOptions {
            csv: csv.map(Path::to_path_buf),
            engine: Engine::Cpu,
            ..ExtractOptions::new(&season, out)
        };
        extract(&o).unwrap_err().to_string()
    };
    let e = refused(&man, None);
    assert!(
        e.contains("season.toml") && e.contains("the season manifest") && e.contains("KPI table"),
        "{e}"
    );
    let e = refused(&season.join(&tel), None);
    assert!(e.contains("telemetry of run"), "{e}");
    let e = refused(&season.join("wear/readings.csv"), None);
    assert!(e.contains("wear readings"), "{e}");
    let k = dir.path().join("k.parquet");
    let e = refused(&k, Some(&k));
    assert!(e.contains("both the KPI table and the CSV copy"), "{e}");
    let e = refused(&k, Some(&dir.path().join("k.road.parquet")));
    assert!(
        e.contains("both the road side table and the CSV copy"),
        "{e}"
    );
    let e = refused(dir.path(), None);
    assert!(
        e.contains("is a folder")
            && e.contains(&dir.path().join("kpis.parquet").display().to_string()),
        "{e}"
    );
    assert_eq!(std::fs::read(&man).unwrap(), before);
    // Nothing written anywhere: no table, no journal, no temporary file.
    let mut left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    left.sort();
    assert_eq!(left, ["season"]);
    assert!(!season.join(".season.commit.json").exists());
}

/// A wear or road file put in the archive's `wear/` or `road/` folder but
/// not listed in season.toml is never read; where tires lack readings or a
/// track lacks profiles, extract now names it (it said only "no wear
/// readings"). The hand-written archive, every file listed, has no such
/// warning.
#[test]
fn files_in_the_archive_the_manifest_does_not_list_are_named() {
    let unlisted = |w: &[String]| -> Vec<String> {
        w.iter()
            .filter(|w| w.contains("so not read"))
            .cloned()
            .collect()
    };
    let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/handwritten");
    let dir = tempfile::tempdir().unwrap();
    // Its telemetry (0.4 s) is below the 10 s an extraction needs, and an
    // extraction that reads no run writes nothing: a simulated run's
    // telemetry stands in, so the summary's warnings can be read.
    let sim_dir = dir.path().join("sim");
    sim(&sim_dir, Preset::Tiny, 20.0);
    let sim_season = Season::open(&sim_dir).unwrap();
    let sim_telemetry = sim_season.path(&sim_season.manifest.runs[0].telemetry);
    let whole = dir.path().join("whole");
    common::copy_dir(&source, &whole);
    let telemetry = whole.join("telemetry/H1-car1-R1.mcap");
    std::fs::copy(&sim_telemetry, &telemetry).unwrap();
    let s = extract(&ExtractOptions::new(&whole, whole.join("kpis.parquet"))).unwrap();
    assert_eq!(unlisted(&s.warnings), Vec::<String>::new());

    assert_eq!(s.skipped.len(), 0, "{:?}", s.skipped);
    let bare = dir.path().join("bare");
    common::copy_dir(&source, &bare);
    std::fs::copy(&sim_telemetry, bare.join("telemetry/H1-car1-R1.mcap")).unwrap();
    let manifest = std::fs::read_to_string(bare.join("season.toml")).unwrap();
    let manifest = manifest
        .replace(
            "wear_readings = [\"wear/readings.csv\"]",
            "wear_readings = []",
        )
        .replace("road_profiles = \"road/profiles.parquet\"\n", "")
        .replace(
            "[[tracks.profiles]]\nlocation = \"L3\"\nfile = \"road/paper-ring-L3.csv\"\n",
            "",
        );
    std::fs::write(bare.join("season.toml"), &manifest).unwrap();
    let s = extract(&ExtractOptions::new(&bare, bare.join("kpis.parquet"))).unwrap();
    let said = unlisted(&s.warnings);
    assert_eq!(said.len(), 2, "{:?}", s.warnings);
    assert!(
        said[0].starts_with("wear/readings.csv: in the archive's wear/ folder but not listed in")
            && said[0].contains("(wear_readings)"),
        "{}",
        said[0]
    );
    assert!(
        said[1].starts_with(
            "road/paper-ring-L3.csv, road/profiles.parquet: in the archive's road/ folder"
        ) && said[1].contains("road_profiles or a track's [[tracks.profiles]]"),
        "{}",
        said[1]
    );
}
