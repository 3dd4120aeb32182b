//! Each GPU kernel against its CPU twin: the CPU engine on 1 thread and on
//! all threads, the GPU engine (when an adapter opens), and a plain memory
//! pass over the same buffer, over a size grid in samples per wheel.
//!
//! `cargo bench --bench kernels`; with TIREWEAR_BENCH_SMALL=1 the grid is one
//! small size so CI can check the bench runs (`-- --test`).

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use tirewear::bench::{memory_pass, one_thread, telemetry_batch};
use tirewear::engine::{CpuEngine, GpuEngine, ReduceEngine};

fn bench(c: &mut Criterion) {
    let small = std::env::var_os("TIREWEAR_BENCH_SMALL").is_some();
    let sizes: &[usize] = if small {
        &[1 << 12]
    } else {
        &[1 << 14, 1 << 18, 1 << 21]
    };
    let gpu = match GpuEngine::new() {
        Ok(g) => Some(g),
        Err(e) => {
            eprintln!("kernels bench: GPU engine skipped: {e}");
            None
        }
    };
    for &n in sizes {
        let batch = telemetry_batch(n);
        let bytes: &[u8] = bytemuck::cast_slice(&batch.samples);
        let mut g = c.benchmark_group(format!("telemetry_reduce/4x{n}"));
        g.throughput(Throughput::Elements(batch.samples.len() as u64));
        g.sample_size(10);
        g.bench_function("memory_pass", |b| b.iter(|| memory_pass(bytes)));
        g.bench_function("cpu_1_thread", |b| {
            b.iter(|| one_thread(|| CpuEngine.telemetry_reduce(&batch).unwrap()))
        });
        g.bench_function("cpu_all_threads", |b| {
            b.iter(|| CpuEngine.telemetry_reduce(&batch).unwrap())
        });
        if let Some(gpu) = &gpu {
            g.bench_function("gpu", |b| b.iter(|| gpu.telemetry_reduce(&batch).unwrap()));
        }
        g.finish();
        let mut g = c.benchmark_group(format!("energy_map/4x{n}"));
        g.throughput(Throughput::Elements(batch.samples.len() as u64));
        g.sample_size(10);
        g.bench_function("cpu_1_thread", |b| {
            b.iter(|| one_thread(|| CpuEngine.energy_map(&batch).unwrap()))
        });
        g.bench_function("cpu_all_threads", |b| {
            b.iter(|| CpuEngine.energy_map(&batch).unwrap())
        });
        if let Some(gpu) = &gpu {
            g.bench_function("gpu", |b| b.iter(|| gpu.energy_map(&batch).unwrap()));
        }
        g.finish();
    }
}

/// Roughness (moments, HDC, Welch PSD) of profiles of 2^14 and 2^18 samples.
fn roughness(c: &mut Criterion) {
    let small = std::env::var_os("TIREWEAR_BENCH_SMALL").is_some();
    let sizes: &[(u32, usize)] = if small {
        &[(13, 2)]
    } else {
        &[(14, 64), (18, 4)]
    };
    let gpu = GpuEngine::new().ok();
    for &(log2, count) in sizes {
        let heights: Vec<Vec<f64>> = (0..count)
            .map(|k| {
                (0..1usize << log2)
                    .map(|i| (i as f64 * 0.007 + k as f64).sin() + 0.1 * (i as f64 * 0.31).cos())
                    .collect()
            })
            .collect();
        let refs: Vec<(&[f64], f64)> = heights.iter().map(|z| (z.as_slice(), 0.01)).collect();
        let batch = &tirewear::kpi::roughness_batch::batches(&refs)[0].1;
        let mut g = c.benchmark_group(format!("roughness/{count}x2^{log2}"));
        g.throughput(Throughput::Elements(count as u64));
        g.sample_size(10);
        g.bench_function("cpu_1_thread", |b| {
            b.iter(|| one_thread(|| CpuEngine.roughness(batch).unwrap()))
        });
        g.bench_function("cpu_all_threads", |b| {
            b.iter(|| CpuEngine.roughness(batch).unwrap())
        });
        if let Some(gpu) = &gpu {
            g.bench_function("gpu", |b| b.iter(|| gpu.roughness(batch).unwrap()));
        }
        g.finish();
    }
}

criterion_group!(benches, bench, roughness);
criterion_main!(benches);
