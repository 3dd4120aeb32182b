//! `tirewear extract` end to end: the demo season gives at least 280 complete
//! rows; a damaged telemetry file fails only its own run, named; outputs and
//! side tables are written.

use std::path::Path;
use tirewear::ingest::manifest::Season;
use tirewear::ingest::telemetry::Encoding;
use tirewear::kpi::table::read_parquet;
use tirewear::kpi::{Engine, ExtractOptions, KpiRow, extract};
use tirewear::sim::{Preset, SimOptions, simulate};

fn sim(out: &Path, preset: Preset, rate: f64) {
    simulate(&SimOptions {
        preset,
        scale: 1.0,
        seed: 7,
        effects: vec![],
        encoding: Encoding::Block,
        rate_hz: Some(rate),
        out: out.to_path_buf(),
        sensor_noise: true,
        progress: false,
    })
    .unwrap();
}

fn opts(season: &Path, out: &Path) -> ExtractOptions {
    ExtractOptions {
        season: season.to_path_buf(),
        out: out.join("kpis.parquet"),
        csv: Some(out.join("kpis.csv")),
        engine: Engine::Auto,
        progress: false,
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
        "kpis.report.json",
    ] {
        assert!(dir.path().join(side).exists(), "{side}");
    }
    // The energy maps read back: one per row, each holding the row's friction
    // energy (both maps bin every sample's energy once; f32 channels: 1e-9),
    // and the lateral map its lateral energy.
    let maps =
        tirewear::kpi::energy_map::read_energy_maps(&dir.path().join("kpis.energy_maps.parquet"))
            .unwrap();
    assert_eq!(maps.len(), rows.len());
    for r in &rows {
        let m = &maps[&(r.run.clone(), r.wheel.clone())];
        let close = |what: &str, got: f64, want: f64| {
            assert!(
                (got - want).abs() <= 1e-9 * want.abs(),
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
            .find(|t| t.run == r.run && t.wheel == r.wheel)
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
    let cols: Vec<ArrayRef> = vec![
        Arc::new(StringArray::from(vec!["R1", "R1"])),
        Arc::new(StringArray::from(vec!["FL", "FL"])),
        Arc::new(StringArray::from(vec!["surface_inner", "surface_inner"])),
        Arc::new(UInt32Array::from(vec![3, 40])),
        Arc::new(UInt32Array::from(vec![4, 2])),
        Arc::new(Float64Array::from(vec![10.0, 5.0])),
    ];
    tirewear::kpi::table::write_batch(&path, &RecordBatch::try_new(schema, cols).unwrap()).unwrap();
    let err = tirewear::kpi::energy_map::read_energy_maps(&path)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("bad.energy_maps.parquet")
            && err.contains("record 2")
            && err.contains("(40, 2)"),
        "{err}"
    );
}
