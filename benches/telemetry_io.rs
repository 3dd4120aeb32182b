//! Telemetry I/O and simulation throughput on one simulated run: the
//! parallel chunk reader against the linear reader, in sample steps/s and
//! MB/s of MCAP.
//!
//! `cargo bench --bench telemetry_io`; with TIREWEAR_BENCH_SMALL=1 the run is
//! short so CI can check the bench runs (`-- --test`). Throughput is reported
//! per telemetry sample step (5 topics: four wheels and the vehicle).

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use tirewear::ingest::telemetry::{Encoding, read_telemetry, read_telemetry_linear};
use tirewear::sim::{Preset, SimOptions, simulate};

fn bench(c: &mut Criterion) {
    let small = std::env::var_os("TIREWEAR_BENCH_SMALL").is_some();
    let dir = tempfile::tempdir().unwrap();
    for encoding in [Encoding::Block, Encoding::Sample] {
        let out = dir.path().join(format!("{encoding:?}"));
        let opts = SimOptions {
            preset: Preset::Tiny,
            scale: 1.0,
            tracks: None,
            seed: 1,
            effects: vec![],
            generated: None,
            scatter: tirewear::sim::WearScatter::NONE,
            encoding,
            rate_hz: Some(if small { 20.0 } else { 200.0 }),
            out: out.clone(),
            sensor_noise: true,
            logger_export: None,
            progress: false,
        };
        let summary = simulate(&opts).unwrap();
        let season = tirewear::ingest::manifest::Season::open(&out).unwrap();
        let path = season.path(&season.manifest.runs[0].telemetry);
        let steps = read_telemetry(&path).unwrap().vehicle.len() as u64;
        let bytes = std::fs::metadata(&path).unwrap().len();

        let mut g = c.benchmark_group(format!("read_telemetry/{encoding:?}"));
        g.throughput(Throughput::Elements(steps));
        g.bench_function("parallel_chunks", |b| {
            b.iter(|| read_telemetry(&path).unwrap())
        });
        g.bench_function("linear", |b| {
            b.iter(|| read_telemetry_linear(&path).unwrap())
        });
        g.throughput(Throughput::Bytes(bytes));
        g.bench_function("parallel_chunks_bytes", |b| {
            b.iter(|| read_telemetry(&path).unwrap())
        });
        g.finish();

        let mut g = c.benchmark_group(format!("simulate_tiny_season/{encoding:?}"));
        g.sample_size(10);
        g.throughput(Throughput::Elements(summary.samples));
        g.bench_function("samples", |b| b.iter(|| simulate(&opts).unwrap()));
        g.finish();
    }
}

/// KPI extraction of a whole season (the demo at its 20 Hz, or the tiny one when small):
/// telemetry sample steps per second, all cores.
fn bench_extract(c: &mut Criterion) {
    let small = std::env::var_os("TIREWEAR_BENCH_SMALL").is_some();
    let dir = tempfile::tempdir().unwrap();
    let season = dir.path().join("season");
    let s = simulate(&SimOptions {
        preset: if small { Preset::Tiny } else { Preset::Demo },
        scale: 1.0,
        tracks: None,
        seed: 7,
        effects: vec![],
        generated: None,
        scatter: tirewear::sim::WearScatter::NONE,
        encoding: Encoding::Block,
        rate_hz: None,
        out: season.clone(),
        sensor_noise: true,
        logger_export: None,
        progress: false,
    })
    .unwrap();
    let opts = tirewear::kpi::ExtractOptions::new(&season, dir.path().join("kpis.parquet"));
    let mut g = c.benchmark_group("extract_season");
    g.sample_size(10);
    g.throughput(Throughput::Elements(s.samples));
    g.bench_function(if small { "tiny" } else { "demo" }, |b| {
        b.iter(|| tirewear::kpi::extract(&opts).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench, bench_extract);
criterion_main!(benches);
