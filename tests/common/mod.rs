//! Helpers shared by the integration tests.
#![allow(dead_code)] // each test binary uses a subset

use std::path::Path;
use tirewear::kpi::KpiRow;

/// Simulates a preset season at `rate_hz` into `dir`, without planted
/// effects, with sensor noise, and optionally its logger export.
pub fn simulate_preset(
    preset: tirewear::sim::Preset,
    seed: u64,
    rate_hz: f64,
    logger_export: Option<tirewear::sim::logger::LoggerFormat>,
    dir: &Path,
) {
    simulate_encoded(
        preset,
        seed,
        rate_hz,
        tirewear::ingest::telemetry::Encoding::Block,
        logger_export,
        dir,
    );
}

/// [`simulate_preset`] with its telemetry in `encoding`.
pub fn simulate_encoded(
    preset: tirewear::sim::Preset,
    seed: u64,
    rate_hz: f64,
    encoding: tirewear::ingest::telemetry::Encoding,
    logger_export: Option<tirewear::sim::logger::LoggerFormat>,
    dir: &Path,
) {
    tirewear::sim::simulate(&tirewear::sim::SimOptions {
        preset,
        scale: 1.0,
        tracks: None,
        seed,
        effects: vec![],
        generated: None,
        scatter: tirewear::sim::WearScatter::NONE,
        encoding,
        rate_hz: Some(rate_hz),
        out: dir.to_path_buf(),
        sensor_noise: true,
        logger_export,
        progress: false,
    })
    .unwrap();
}

/// Simulates a preset season at 5 Hz into `dir`, without planted effects.
fn simulate_at_5_hz(preset: tirewear::sim::Preset, seed: u64, dir: &Path) {
    simulate_preset(preset, seed, 5.0, None, dir);
}

/// Simulates the demo season (seed 7) at 5 Hz into `dir`: the findings do
/// not need 20 Hz, and it keeps the tests quick.
pub fn simulate_demo(dir: &Path) {
    simulate_at_5_hz(tirewear::sim::Preset::Demo, 7, dir);
}

/// The tiny season (2 events, 4 runs) at 5 Hz.
pub fn simulate_tiny(dir: &Path, seed: u64) {
    simulate_at_5_hz(tirewear::sim::Preset::Tiny, seed, dir);
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

/// The run of `season` that needs the most memory to extract
/// (`run_memory_need`), its need, and the largest need of the others.
pub fn hungriest_run(
    season: &tirewear::ingest::manifest::Season,
) -> (tirewear::ingest::manifest::Run, u64, u64) {
    let mut needs: Vec<(u64, &tirewear::ingest::manifest::Run)> = season
        .manifest
        .runs
        .iter()
        .map(|r| {
            (
                tirewear::kpi::run_memory_need(&season.path(&r.telemetry)).unwrap(),
                r,
            )
        })
        .collect();
    needs.sort_by_key(|(n, _)| std::cmp::Reverse(*n));
    let (need, run) = needs[0];
    (run.clone(), need, needs.get(1).map_or(0, |n| n.0))
}

/// `text` with every line that starts with `prefix` replaced by `line`
/// (one field of a TOML file changed by hand).
pub fn with_line(text: &str, prefix: &str, line: &str) -> String {
    text.lines()
        .map(|l| if l.starts_with(prefix) { line } else { l })
        .collect::<Vec<_>>()
        .join("\n")
}

/// Copies a folder recursively.
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let target = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &target);
        } else {
            std::fs::copy(e.path(), target).unwrap();
        }
    }
}
