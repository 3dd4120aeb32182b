//! The archive in datasets/handwritten/ was written from docs/formats.md
//! alone (by hand, pyarrow and Python mcap): tirewear must read all of it.

use std::path::PathBuf;
use tirewear::Wheel;
use tirewear::ingest::compound::Compound;
use tirewear::ingest::manifest::Season;
use tirewear::ingest::road::{read_profile_csv, read_profiles_parquet};
use tirewear::ingest::telemetry::{Encoding, read_telemetry};
use tirewear::ingest::wear::read_wear_csv;

fn season() -> Season {
    Season::open(&PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("datasets/handwritten")).unwrap()
}

#[test]
fn manifest_and_compound() {
    let s = season();
    assert_eq!(s.manifest.runs[0].tire_sets.get(Wheel::RR), "HS-4");
    let c = Compound::load(&s.path(&s.manifest.compounds[0].file)).unwrap();
    // By hand: halfway between 40 °C (100 MPa) and 80 °C (40 MPa) in log10 E': sqrt(100·40) = 63.246 MPa.
    assert!((c.storage_modulus_mpa(60.0) - 4000f64.sqrt()).abs() < 1e-9);
    assert!((c.loss_factor(60.0) - 0.325).abs() < 1e-12);
}

#[test]
fn road_profiles_from_csv_and_pyarrow_parquet() {
    let s = season();
    let t = &s.manifest.tracks[0];
    let p = read_profile_csv(&s.path(&t.profiles[0].file), &t.id, "L3").unwrap();
    assert_eq!(p.z_mm.len(), 64);
    assert_eq!(p.dx_mm, 0.125);
    let bulk = read_profiles_parquet(&s.path(s.manifest.road_profiles.as_ref().unwrap())).unwrap();
    let names: Vec<_> = bulk
        .iter()
        .map(|p| (p.track.as_str(), p.location.as_str(), p.z_mm.len()))
        .collect();
    assert_eq!(names, [("paper-ring", "L1", 32), ("paper-ring", "L2", 32)]);
    assert!((bulk[1].z_mm[2] - (0.1 * 1f64.sin() + 0.1)).abs() < 1e-15);
}

#[test]
fn wear_readings_and_python_telemetry() {
    let s = season();
    let rows = read_wear_csv(&s.path(&s.manifest.wear_readings[0])).unwrap();
    assert_eq!(rows.len(), 15);
    assert_eq!(rows.iter().filter(|r| r.wheel == Wheel::FL).count(), 6);
    let tel = read_telemetry(&s.path(&s.manifest.runs[0].telemetry)).unwrap();
    assert_eq!(tel.encoding, Some(Encoding::Sample));
    assert_eq!(tel.vehicle.len(), 35); // 40 samples minus a 5-sample dropout
}
