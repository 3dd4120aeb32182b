//! Helpers shared by the integration tests.
#![allow(dead_code)] // each test binary uses a subset

use std::path::Path;
use tirewear::kpi::KpiRow;

/// Simulates the demo season (seed 7) at 5 Hz into `dir`: the findings do
/// not need 20 Hz, and it keeps the tests quick.
pub fn simulate_demo(dir: &Path) {
    tirewear::sim::simulate(&tirewear::sim::SimOptions {
        preset: tirewear::sim::Preset::Demo,
        scale: 1.0,
        seed: 7,
        effects: vec![],
        generated: None,
        scatter: tirewear::sim::WearScatter::NONE,
        encoding: tirewear::ingest::telemetry::Encoding::Block,
        rate_hz: Some(5.0),
        out: dir.to_path_buf(),
        sensor_noise: true,
        progress: false,
    })
    .unwrap();
}

/// The demo season simulated and extracted on the CPU engine into `dir/kpis.parquet`.
pub fn demo_kpis(dir: &Path) -> Vec<KpiRow> {
    simulate_demo(dir);
    tirewear::kpi::extract(&tirewear::kpi::ExtractOptions::new(
        dir,
        dir.join("kpis.parquet"),
    ))
    .unwrap();
    tirewear::kpi::table::read_parquet(&dir.join("kpis.parquet")).unwrap()
}
