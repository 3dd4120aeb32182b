//! `tirewear bench`: the figures a user compares machines with, measured in
//! one run: each kernel on the CPU engine (1 thread and all threads) and the
//! GPU engine (upload, compute, readback apart), against a plain memory pass
//! over the same buffer (the bandwidth reference). Best of a few repeats.

use crate::engine::{CpuEngine, GpuEngine, ReduceEngine};
use crate::ingest::road::Profile;
use crate::kpi::cpu::telemetry_reduce::{ReduceBatch, ReduceSample};
use crate::kpi::road::spectral;
use crate::kpi::roughness_batch::batches;
use rayon::prelude::*;
use std::fmt::Write;
use std::time::{Duration, Instant};

/// Settings of a bench run.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    /// Small sizes (for CI's check that the bench runs).
    pub small: bool,
    /// Run the GPU engine (skipped with a message when there is no adapter).
    pub gpu: bool,
    pub repeats: usize,
    /// Which parts to measure.
    pub parts: BenchParts,
    /// Decode lines on this season archive instead of simulated ones.
    pub season: Option<std::path::PathBuf>,
}

/// The parts of a bench run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BenchParts {
    /// The kernels and the decoding.
    All,
    /// The engines' kernels on synthetic buffers.
    Kernels,
    /// Telemetry decoding against zstd alone, on a simulated season.
    Decode,
    /// The gap diagnosis of simulated seasons, against its 10 s target.
    Gap,
    /// Levenberg–Marquardt's step in either space, and the demo's network.
    Fit,
}

/// One measured line.
#[derive(Debug, Clone, serde::Serialize)]
pub struct BenchLine {
    pub kernel: String,
    pub size: String,
    pub engine: String,
    pub seconds: f64,
    /// Items per second (samples or profiles).
    pub items_per_s: f64,
    pub unit: String,
    /// Bytes of input per second.
    pub gb_per_s: f64,
    /// Time of the reference pass over the same bytes divided by this time:
    /// a memory pass for the kernels, zstd-only decompression for decoding.
    pub vs_memory_pass: f64,
    /// What `vs_memory_pass` compares with: "memory pass" or "zstd only".
    pub reference: String,
    /// GPU only: upload / compute / readback seconds.
    pub gpu_split_s: Option<[f64; 3]>,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct BenchReport {
    pub cpu: String,
    pub gpu: Option<String>,
    pub threads: usize,
    pub lines: Vec<BenchLine>,
    /// Where each season's one-thread extraction spent its time.
    pub extract_splits: Vec<ExtractSplit>,
    /// Problems met (a GPU kernel that failed, an engine skipped).
    pub notes: Vec<String>,
}

/// Where a one-thread extraction's time went (seconds), from its summary
/// (the best repeat's): which stage bounds the ratio to zstd. `rest` is
/// the wall time outside the runs: reading the season, the road KPIs and
/// writing the tables.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ExtractSplit {
    pub kernel: String,
    pub wall_s: f64,
    pub zstd_s: f64,
    pub decode_s: f64,
    pub cleaning_s: f64,
    pub reductions_s: f64,
    pub rest_s: f64,
}

impl ExtractSplit {
    fn new(kernel: &str, wall: Duration, zstd: Duration, s: &crate::kpi::ExtractSummary) -> Self {
        let wall_s = wall.as_secs_f64();
        ExtractSplit {
            kernel: kernel.into(),
            wall_s,
            zstd_s: zstd.as_secs_f64(),
            decode_s: s.decode_seconds,
            cleaning_s: s.prepare_seconds,
            reductions_s: s.reduce_seconds - s.prepare_seconds,
            rest_s: wall_s - s.decode_seconds - s.reduce_seconds,
        }
    }
}

/// One kernel's input, shared by its measured lines.
struct Workload {
    kernel: &'static str,
    size: String,
    /// Items (samples or profiles) in the input.
    items: f64,
    unit: &'static str,
    bytes: f64,
    /// The plain memory pass over the same bytes (or decoding's reference).
    memory_pass: Duration,
    reference: &'static str,
}

impl Workload {
    fn line(&self, engine: &str, d: Duration, gpu_split_s: Option<[f64; 3]>) -> BenchLine {
        let t = d.as_secs_f64();
        BenchLine {
            kernel: self.kernel.into(),
            size: self.size.clone(),
            engine: engine.into(),
            seconds: t,
            items_per_s: self.items / t,
            unit: self.unit.into(),
            gb_per_s: self.bytes / t / 1e9,
            vs_memory_pass: self.memory_pass.as_secs_f64() / t,
            reference: self.reference.into(),
            gpu_split_s,
        }
    }
}

impl Workload {
    /// The CPU-only lines of one workload: its time on one thread and on all.
    fn push_thread_lines(&self, report: &mut BenchReport, one: Duration, all: Duration) {
        report
            .lines
            .push(self.line("tirewear, 1 thread", one, None));
        let threads = format!("tirewear, {} threads", report.threads);
        report.lines.push(self.line(&threads, all, None));
    }
}

/// The best time of `repeats` calls, with that call's result.
fn best<T>(repeats: usize, mut f: impl FnMut() -> T) -> (Duration, T) {
    let mut out = None;
    let mut best = Duration::MAX;
    for _ in 0..repeats.max(1) {
        let t = Instant::now();
        let r = f();
        let d = t.elapsed();
        if out.is_none() || d < best {
            best = d;
            out = Some(r);
        }
    }
    (best, out.expect("one repeat"))
}

/// A plain pass over the bytes (sum of u32 words, all threads): the bandwidth reference.
pub fn memory_pass(bytes: &[u8]) -> u64 {
    let words: &[u32] = bytemuck::cast_slice(&bytes[..bytes.len() / 4 * 4]);
    words
        .par_chunks(1 << 16)
        .map(|c| c.iter().map(|&w| w as u64).sum::<u64>())
        .sum()
}

/// Four wheels of `samples` each, smooth signals (benchmarks only).
pub fn telemetry_batch(samples: usize) -> ReduceBatch {
    let mut b = ReduceBatch::default();
    for w in 0..4 {
        let wheel: Vec<ReduceSample> = (0..samples)
            .map(|i| {
                let t = i as f32 * 1e-3 + w as f32;
                let (dt, dt_lo) = ReduceSample::split_dt(1e-3);
                ReduceSample {
                    vx: 45.0 + 20.0 * (0.05 * t).sin(),
                    vy: 0.8 * (0.9 * t).sin(),
                    omega: 130.0 + 60.0 * (0.05 * t).sin(),
                    radius: 0.33,
                    fx: 3000.0 * (1.3 * t).sin(),
                    fy: -4000.0 * (0.9 * t).sin(),
                    fz: 4000.0 + 1000.0 * (0.3 * t).sin(),
                    t_surface: 80.0 + 10.0 * (0.01 * t).sin(),
                    t_inner: 110.0,
                    pressure: 160_000.0,
                    camber: -2.0,
                    t_surface_rate: 0.1 * (0.01 * t).cos(),
                    t_inner_rate: 0.0,
                    load_rel: 1.0 + 0.25 * (0.3 * t).sin(),
                    time_s: i as f32 * 1e-3,
                    distance_m: i as f32 * 0.045,
                    accel_x: 20.0 * 0.05 * (0.05 * t).cos(),
                    accel_y: 15.0 * (0.9 * t).sin().abs(),
                    dt,
                    dt_lo,
                }
            })
            .collect();
        b.push_wheel(&wheel);
    }
    b
}

/// A GPU kernel's best wall time over the repeats (after one warm-up call that
/// allocates the reusable buffers), with that call's upload/compute/readback split.
fn gpu_best(
    repeats: usize,
    notes: &mut Vec<String>,
    mut f: impl FnMut() -> Result<crate::gpu::GpuTimings, crate::gpu::GpuError>,
) -> Option<(Duration, [f64; 3])> {
    let _ = f();
    let mut fastest: Option<(Duration, [f64; 3])> = None;
    for _ in 0..repeats.max(1) {
        let t0 = Instant::now();
        match f() {
            Ok(t) => {
                let d = t0.elapsed();
                if fastest.is_none_or(|(b, _)| d < b) {
                    fastest = Some((
                        d,
                        [
                            t.upload.as_secs_f64(),
                            t.compute.as_secs_f64(),
                            t.readback.as_secs_f64(),
                        ],
                    ));
                }
            }
            Err(e) => notes.push(format!("GPU kernel failed: {e}")),
        }
    }
    fastest
}

/// Runs `f` on a 1-thread rayon pool.
pub fn one_thread<T: Send>(f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("1-thread pool")
        .install(f)
}

/// Checks, before anything is measured, that the results can go to `out`:
/// not a folder, not a file of the season measured, and, where a file is
/// already there, an earlier `tirewear bench` result (a JSON object with a
/// `lines` array, as the report reads it) or an empty file. Anything else
/// (a KPI table, a model, a page) would be replaced by the results.
pub fn check_output(
    out: &std::path::Path,
    season: Option<&crate::ingest::manifest::Season>,
) -> Result<(), crate::atomic::Clash> {
    let inputs = season.map(|s| s.input_files()).unwrap_or_default();
    crate::atomic::check_replaceable(
        out,
        "bench result",
        &inputs,
        "an earlier `tirewear bench` result",
        |head| earlier_result(out, head),
    )
}

/// Largest file read whole to tell whether it is a bench result: a season
/// bench's JSON is a few tens of kilobytes.
const MAX_RESULT_BYTES: u64 = 16 << 20;

/// Whether the file whose first bytes are `head` is empty or an earlier
/// bench result; if not, what it is instead.
fn earlier_result(path: &std::path::Path, head: &[u8]) -> Result<(), String> {
    let start = head.iter().position(|b| !b.is_ascii_whitespace());
    match start {
        None if head.is_empty() => return Ok(()),
        Some(i) if head[i] == b'{' => {}
        _ => return Err(crate::ingest::checksum::what_it_is(head)),
    }
    let text = crate::ingest::read_text(path, MAX_RESULT_BYTES)
        .map_err(|e| crate::ingest::unnamed(path, e))?;
    match serde_json::from_str::<serde_json::Value>(&text) {
        Ok(v) if v.get("lines").is_some_and(|l| l.is_array()) => Ok(()),
        Ok(_) => Err("it is JSON without a bench result's `lines` array".into()),
        Err(_) => Err(crate::ingest::checksum::what_it_is(head)),
    }
}

/// Runs the benchmarks.
pub fn run_bench(o: &BenchOptions) -> BenchReport {
    let threads = rayon::current_num_threads();
    let mut report = BenchReport {
        cpu: CpuEngine.device(),
        gpu: None,
        threads,
        lines: Vec::new(),
        extract_splits: Vec::new(),
        notes: Vec::new(),
    };
    let gpu = if o.gpu {
        match GpuEngine::new() {
            Ok(g) => {
                report.gpu = Some(g.device());
                Some(g)
            }
            Err(e) => {
                report.notes.push(format!("GPU engine skipped: {e}"));
                None
            }
        }
    } else {
        None
    };

    if matches!(o.parts, BenchParts::All | BenchParts::Kernels) {
        kernel_lines(o, gpu.as_ref(), &mut report);
    }
    if matches!(o.parts, BenchParts::All | BenchParts::Decode) {
        decode_lines(o, &mut report);
    }
    if matches!(o.parts, BenchParts::All | BenchParts::Gap) {
        gap_lines(o, &mut report);
    }
    if matches!(o.parts, BenchParts::All | BenchParts::Fit) {
        fit_lines(o, &mut report);
    }
    report
}

/// Each kernel on the CPU engine and the GPU engine, against a memory pass.
fn kernel_lines(o: &BenchOptions, gpu: Option<&GpuEngine>, report: &mut BenchReport) {
    let threads = report.threads;
    // Telemetry reduction: 4 wheels × 1 h at 1 kHz (small: 4 × 2 min).
    let per_wheel = if o.small { 120_000 } else { 3_600_000 };
    let batch = telemetry_batch(per_wheel);
    let bytes: &[u8] = bytemuck::cast_slice(&batch.samples);
    let n = batch.samples.len() as f64;
    let (mem, _) = best(o.repeats, || memory_pass(bytes));
    let size = format!(
        "4 × {per_wheel} samples ({:.0} MB)",
        bytes.len() as f64 / 1e6
    );
    let mut w = Workload {
        kernel: "telemetry_reduce",
        size,
        items: n,
        unit: "samples/s",
        bytes: bytes.len() as f64,
        memory_pass: mem,
        reference: "memory pass",
    };
    report.lines.push(w.line("memory pass", mem, None));
    let (d, _) = best(o.repeats, || {
        one_thread(|| CpuEngine.telemetry_reduce(&batch))
    });
    report.lines.push(w.line("cpu, 1 thread", d, None));
    let (d, _) = best(o.repeats, || CpuEngine.telemetry_reduce(&batch));
    report
        .lines
        .push(w.line(&format!("cpu, {threads} threads"), d, None));
    if let Some(g) = &gpu
        && let Some((d, split)) = gpu_best(o.repeats, &mut report.notes, || {
            g.ctx.telemetry_reduce(&batch).map(|r| r.1)
        })
    {
        report.lines.push(w.line("gpu", d, Some(split)));
    }

    // Energy maps over the same samples.
    w.kernel = "energy_map";
    let (d, _) = best(o.repeats, || one_thread(|| CpuEngine.energy_map(&batch)));
    report.lines.push(w.line("cpu, 1 thread", d, None));
    let (d, _) = best(o.repeats, || CpuEngine.energy_map(&batch));
    report
        .lines
        .push(w.line(&format!("cpu, {threads} threads"), d, None));
    if let Some(g) = &gpu
        && let Some((d, split)) = gpu_best(o.repeats, &mut report.notes, || {
            g.ctx.energy_map(&batch).map(|r| r.1)
        })
    {
        report.lines.push(w.line("gpu", d, Some(split)));
    }

    // Condition maps over the same samples.
    w.kernel = "condition_map";
    let (d, _) = best(o.repeats, || {
        one_thread(|| crate::kpi::cpu::condition_map::condition_map(&batch))
    });
    report.lines.push(w.line("cpu twin, 1 thread", d, None));
    let (d, _) = best(o.repeats, || one_thread(|| CpuEngine.condition_map(&batch)));
    report.lines.push(w.line("cpu, 1 thread", d, None));
    let (d, _) = best(o.repeats, || CpuEngine.condition_map(&batch));
    report
        .lines
        .push(w.line(&format!("cpu, {threads} threads"), d, None));
    if let Some(g) = &gpu
        && let Some((d, split)) = gpu_best(o.repeats, &mut report.notes, || {
            g.ctx.condition_map(&batch).map(|r| r.1)
        })
    {
        report.lines.push(w.line("gpu", d, Some(split)));
    }

    // All three, as extraction calls them: the GPU uploads the samples once.
    w.kernel = "all three";
    let (d, _) = best(o.repeats, || one_thread(|| CpuEngine.reductions(&batch)));
    report.lines.push(w.line("cpu, 1 thread", d, None));
    let (d, _) = best(o.repeats, || CpuEngine.reductions(&batch));
    report
        .lines
        .push(w.line(&format!("cpu, {threads} threads"), d, None));
    if let Some(g) = &gpu
        && let Some((d, split)) = gpu_best(o.repeats, &mut report.notes, || {
            g.ctx.reductions(&batch).map(|r| r.1)
        })
    {
        report.lines.push(w.line("gpu, one upload", d, Some(split)));
    }

    // Roughness: moments, Welch PSD and HDC per profile (the engines' part).
    for log2 in [14u32, 18] {
        let len = 1usize << log2;
        let count = match (o.small, log2) {
            (true, _) => 2,
            (false, 14) => 256,
            _ => 16,
        };
        let heights: Vec<Vec<f64>> = (0..count)
            .map(|k| {
                (0..len)
                    .map(|i| {
                        let x = i as f64 * 0.01;
                        (x * 0.7 + k as f64).sin()
                            + 0.3 * (x * 13.0).sin()
                            + 0.05 * (x * 171.0).cos()
                    })
                    .collect()
            })
            .collect();
        let refs: Vec<(&[f64], f64)> = heights.iter().map(|z| (z.as_slice(), 0.01)).collect();
        let groups = batches(&refs);
        // The kernels read f32 heights: the reference pass reads the same bytes.
        let bytes: Vec<u8> = groups
            .iter()
            .flat_map(|(_, b)| bytemuck::cast_slice::<f32, u8>(&b.heights).to_vec())
            .collect();
        let (pmem, _) = best(o.repeats, || memory_pass(&bytes));
        let w = Workload {
            kernel: "roughness",
            size: format!("{count} × 2^{log2} samples"),
            items: count as f64,
            unit: "profiles/s",
            bytes: bytes.len() as f64,
            memory_pass: pmem,
            reference: "memory pass",
        };
        report.lines.push(w.line("memory pass", pmem, None));
        let profiles: Vec<Profile> = heights
            .iter()
            .map(|z| Profile {
                track: "bench".into(),
                location: String::new(),
                x0_mm: 0.0,
                dx_mm: 0.01,
                z_mm: z.clone(),
            })
            .collect();
        let (d, _) = best(o.repeats, || {
            profiles
                .par_iter()
                .map(|p| spectral(p).moments.1)
                .sum::<f64>()
        });
        report
            .lines
            .push(w.line(&format!("cpu realfft, {threads} thr"), d, None));
        let (d, _) = best(o.repeats, || {
            groups
                .iter()
                .map(|(_, b)| CpuEngine.roughness(b).map(|r| r.len()).unwrap_or(0))
                .sum::<usize>()
        });
        report
            .lines
            .push(w.line(&format!("cpu twins, {threads} thr"), d, None));
        if let Some(g) = &gpu
            && let Some((d, split)) = gpu_best(o.repeats, &mut report.notes, || {
                let mut total = crate::gpu::GpuTimings::default();
                for (_, b) in &groups {
                    total.add(&g.ctx.roughness(b)?.1);
                }
                Ok(total)
            })
        {
            report.lines.push(w.line("gpu", d, Some(split)));
        }
    }
}

/// Telemetry decoding against its physical reference, in one run: every
/// MCAP file of a season (by default simulated: the demo at 20 Hz, `--small`
/// the tiny one, in the block and the per-sample form; or the user's own
/// with `--season`), read from the page cache by `read_telemetry` (CRC
/// checks, decompression, protobuf decoding into channels) and by zstd alone
/// over the same chunks, on one thread and on all; then the whole extraction
/// of the season (`kpi::extract`, CPU engine: decoding, every reduction and
/// the Parquet outputs) against the same reference. Files in parallel on all
/// threads, as `extract` reads them.
fn decode_lines(o: &BenchOptions, report: &mut BenchReport) {
    let Ok(dir) = tempfile::tempdir() else {
        report
            .notes
            .push("decode skipped: no temporary folder".into());
        return;
    };
    let seasons: Vec<(&'static str, std::path::PathBuf)> = match &o.season {
        Some(season) => vec![("decode, season", season.clone())],
        None => {
            use crate::ingest::telemetry::Encoding;
            let mut seasons = Vec::new();
            for (encoding, label) in [
                (Encoding::Block, "decode, block"),
                (Encoding::Sample, "decode, sample"),
            ] {
                let out = dir.path().join(label.replace(", ", "-"));
                match simulate_for_decode(o, encoding, &out) {
                    Ok(()) => seasons.push((label, out)),
                    Err(e) => report.notes.push(format!("{label} skipped: {e}")),
                }
            }
            seasons
        }
    };
    for (label, season) in seasons {
        if let Err(e) = season_decode_lines(o, label, &season, dir.path(), report) {
            report.notes.push(format!("{label} skipped: {e}"));
        }
    }
}

/// A simulated season in one telemetry form, for the decode lines.
fn simulate_for_decode(
    o: &BenchOptions,
    encoding: crate::ingest::telemetry::Encoding,
    out: &std::path::Path,
) -> Result<(), crate::sim::SimError> {
    let preset = if o.small {
        crate::sim::Preset::Tiny
    } else {
        crate::sim::Preset::Demo
    };
    let season = BenchSeason {
        preset,
        scale: 1.0,
        rate_hz: None,
        effect: None,
    };
    crate::sim::simulate(&season.options(encoding, out)).map(|_| ())
}

/// A simulated season the bench measures (seed 1, sensor noise on).
struct BenchSeason {
    preset: crate::sim::Preset,
    scale: f64,
    rate_hz: Option<f64>,
    /// A planted effect (`tirewear simulate --effect` syntax).
    effect: Option<&'static str>,
}

impl BenchSeason {
    fn options(
        &self,
        encoding: crate::ingest::telemetry::Encoding,
        out: &std::path::Path,
    ) -> crate::sim::SimOptions {
        crate::sim::SimOptions {
            preset: self.preset,
            scale: self.scale,
            tracks: None,
            seed: 1,
            effects: self
                .effect
                .iter()
                .map(|e| e.parse().expect("the bench's effects parse"))
                .collect(),
            generated: None,
            scatter: crate::sim::WearScatter::NONE,
            encoding,
            rate_hz: self.rate_hz,
            out: out.to_path_buf(),
            sensor_noise: true,
            logger_export: None,
            progress: false,
        }
    }
}

/// The decode and extraction lines of one season.
fn season_decode_lines(
    o: &BenchOptions,
    label: &'static str,
    season: &std::path::Path,
    scratch: &std::path::Path,
    report: &mut BenchReport,
) -> Result<(), String> {
    use crate::ingest::manifest::Season;
    use crate::ingest::telemetry::{decompress_only, read_telemetry};
    let threads = report.threads;
    let manifest = Season::open(season).map_err(|e| e.to_string())?;
    let files: Vec<std::path::PathBuf> = manifest
        .manifest
        .runs
        .iter()
        .map(|r| manifest.path(&r.telemetry))
        .collect();
    let bytes: u64 = files
        .iter()
        .filter_map(|f| std::fs::metadata(f).ok())
        .map(|m| m.len())
        .sum();
    let decode = |f: &std::path::PathBuf| {
        read_telemetry(f)
            .map(|t| t.wheels.iter().map(|w| w.len() as u64).sum::<u64>())
            .unwrap_or(0)
    };
    let zstd = || {
        files
            .par_iter()
            .map(|f| decompress_only(f).unwrap_or(0))
            .sum::<u64>()
    };
    let (z1, _) = best(o.repeats, || one_thread(zstd));
    // The timed decode also counts the samples (no extra untimed pass).
    let (d, samples) = best(o.repeats, || {
        one_thread(|| files.iter().map(decode).sum::<u64>())
    });
    let w = Workload {
        kernel: label,
        size: format!("{} runs, {:.0} MB MCAP", files.len(), bytes as f64 / 1e6),
        items: samples as f64,
        unit: "samples/s",
        bytes: bytes as f64,
        memory_pass: z1,
        reference: "zstd only",
    };
    report.lines.push(w.line("zstd only, 1 thread", z1, None));
    report.lines.push(w.line("tirewear, 1 thread", d, None));
    let extract = || {
        crate::kpi::extract(&crate::kpi::ExtractOptions::new(
            season,
            scratch.join("bench-kpis.parquet"),
        ))
    };
    let (e1, summary) = best(o.repeats, || one_thread(extract));
    let summary = summary.map_err(|e| format!("extract: {e}"))?;
    report.lines.push(w.line("extract, 1 thread", e1, None));
    report
        .extract_splits
        .push(ExtractSplit::new(label, e1, z1, &summary));
    if o.gpu {
        gpu_extract_lines(o, season, scratch, &w, report);
    }
    let (zn, _) = best(o.repeats, zstd);
    let wn = Workload {
        memory_pass: zn,
        ..w
    };
    report
        .lines
        .push(wn.line(&format!("zstd only, {threads} thr"), zn, None));
    let (d, _) = best(o.repeats, || files.par_iter().map(decode).sum::<u64>());
    report
        .lines
        .push(wn.line(&format!("tirewear, {threads} threads"), d, None));
    let (en, _) = best(o.repeats, extract);
    report
        .lines
        .push(wn.line(&format!("extract, {threads} threads"), en, None));
    Ok(())
}

/// The whole extraction on the GPU engine with one decoding thread, each
/// run decoded and then reduced in turn against the pipelined route (the
/// next run decoded while the GPU reduces), and a note on how much of the
/// possible overlap the pipeline got: (in turn − pipelined) over the
/// smaller of the two sides (decoding and cleaning on the CPU; upload,
/// compute and readback on the GPU). Each extraction opens its own device,
/// in both routes alike.
fn gpu_extract_lines(
    o: &BenchOptions,
    season: &std::path::Path,
    scratch: &std::path::Path,
    w: &Workload,
    report: &mut BenchReport,
) {
    use crate::kpi::{Engine, ExtractOptions, extract};
    let mut times = Vec::new();
    for (pipeline, engine) in [(false, "extract gpu, serial"), (true, "extract gpu, piped")] {
        let run = || {
            extract(&ExtractOptions {
                engine: Engine::Gpu,
                pipeline,
                ..ExtractOptions::new(season, scratch.join("bench-gpu-kpis.parquet"))
            })
        };
        let (d, summary) = best(o.repeats, || one_thread(run));
        let summary = match summary {
            Ok(s) => s,
            Err(e) => {
                report.notes.push(format!("{engine} skipped: {e}"));
                return;
            }
        };
        let gpu = summary.gpu_timings.unwrap_or_default();
        let split = [gpu.upload, gpu.compute, gpu.readback].map(|t| t.as_secs_f64());
        report.lines.push(w.line(engine, d, Some(split)));
        let gpu_s = gpu.total().as_secs_f64();
        let cpu_s = summary.decode_seconds + (summary.reduce_seconds - gpu_s).max(0.0);
        times.push((summary.runs_seconds, cpu_s, gpu_s));
    }
    if let [(serial, cpu_s, gpu_s), (piped, ..)] = times[..] {
        let (saved, bound) = (serial - piped, cpu_s.min(gpu_s));
        // The bound comes from the serial route's own split: a saving above
        // it is the two routes' difference beyond overlap, not overlap.
        let beyond = if saved > bound {
            "; more than the overlap can save: the two routes differ by more than their \
             overlap (timing noise, or a software GPU sharing the decoding core)"
        } else {
            ""
        };
        report.notes.push(format!(
            "{}, GPU engine, 1 decoding thread: the runs took {serial:.3} s reduced in \
             turn and {piped:.3} s pipelined, {saved:.3} s saved of at most {bound:.3} s (the \
             smaller of decoding and cleaning, {cpu_s:.3} s, and the GPU's upload, compute and \
             readback, {gpu_s:.3} s){beyond}",
            w.kernel,
        ));
    }
}

/// What a diagnosis of the demo season may take on this machine (issue
/// target, docs/gap.md): the gap lines' reference time.
const GAP_TARGET_S: f64 = 10.0;

/// The gap diagnosis (`gap::report::diagnose`, physics baseline, default
/// settings: 1999 permutations per candidate) of the demo season and of the
/// season preset `gap validate` diagnoses (scale 0.5, 5 Hz), on one thread
/// and on all, against the 10 s target (`vs ref` = 10 s / time). The
/// simulation and extraction are not timed; reading the tables is.
fn gap_lines(o: &BenchOptions, report: &mut BenchReport) {
    use crate::sim::Preset;
    let Ok(dir) = tempfile::tempdir() else {
        report.notes.push("gap skipped: no temporary folder".into());
        return;
    };
    let season = |preset, scale, rate_hz, effect| BenchSeason {
        preset,
        scale,
        rate_hz,
        effect,
    };
    // A clean season adds no term; a planted effect makes forward selection
    // score every candidate again per term added (the slow path).
    let graining = Some("graining=1");
    let seasons = if o.small {
        // The tiny season has too few tires for a diagnosis.
        vec![("gap, demo", season(Preset::Demo, 1.0, None, None))]
    } else {
        vec![
            ("gap, demo", season(Preset::Demo, 1.0, None, None)),
            (
                "gap, demo+grain.",
                season(Preset::Demo, 1.0, None, graining),
            ),
            (
                "gap, season 0.5",
                season(Preset::Season, 0.5, Some(5.0), None),
            ),
            (
                "gap, seas.+grain.",
                season(Preset::Season, 0.5, Some(5.0), graining),
            ),
        ]
    };
    for (label, s) in seasons {
        let out = dir.path().join(label.replace([',', ' ', '+', '.'], "-"));
        if let Err(e) = season_gap_lines(o, label, &s, &out, report) {
            report.notes.push(format!("{label} skipped: {e}"));
        }
    }
}

/// Simulates and extracts one season, then times its diagnosis.
fn season_gap_lines(
    o: &BenchOptions,
    label: &'static str,
    season: &BenchSeason,
    out: &std::path::Path,
    report: &mut BenchReport,
) -> Result<(), String> {
    use crate::gap::report::{Baseline, GapSettings, diagnose};
    let encoding = crate::ingest::telemetry::Encoding::Block;
    let kpis = crate::validate::simulate_and_extract(&season.options(encoding, out))
        .map_err(|e| e.to_string())?;
    let settings = GapSettings {
        wlf: crate::ingest::compound::read_wlf(&out.join("compounds"))
            .map_err(|e| e.to_string())?,
        ..GapSettings::default()
    };
    let run = || -> Result<usize, String> {
        let rows = crate::kpi::table::read_parquet(&kpis).map_err(|e| e.to_string())?;
        let maps = crate::kpi::energy_maps::read_tire_maps(&kpis).map_err(|e| e.to_string())?;
        diagnose(&rows, &maps, &Baseline::Physics, &settings).map_err(|e| e.to_string())?;
        Ok(rows.len())
    };
    let (t1, tires) = best(o.repeats, || one_thread(run));
    let tires = tires?;
    let w = Workload {
        kernel: label,
        size: format!("{tires} tire-runs"),
        items: tires as f64,
        unit: "tires/s",
        bytes: 0.0,
        memory_pass: Duration::from_secs_f64(GAP_TARGET_S),
        reference: "target 10 s",
    };
    let (tn, _) = best(o.repeats, run);
    w.push_thread_lines(report, t1, tn);
    Ok(())
}

/// Levenberg–Marquardt's step solved in the residuals' space and in the
/// parameters' on one problem of the demo network's shape (more weights
/// than residuals) and one of a season's (more residuals), each line's
/// `vs ref` the other space's time over its own, the space `step` picks
/// marked; then the network method on the demo's KPI table (docs/models.md,
/// "In the residuals' space when they are fewer than the weights").
fn fit_lines(o: &BenchOptions, report: &mut BenchReport) {
    use crate::model::lm::{LmSettings, LmSolver, RandomLinear, StepSpace};
    let shapes: &[(&'static str, usize, usize)] = if o.small {
        &[("LM step, small", 40, 300)]
    } else {
        // The demo network at its widest (22 inputs, 26 in the second
        // layer) on 177 training residuals; the season preset's (19, 23)
        // on 870.
        &[("LM step, demo", 177, 1131), ("LM step, season", 870, 864)]
    };
    for &(label, n, m) in shapes {
        let problem = RandomLinear::new(1, n, m);
        let time = |space| {
            best(o.repeats, || {
                let mut solver = LmSolver::new(&problem, &vec![0.0; m], LmSettings::default())
                    .expect("the start point has the problem's size");
                solver.step_in(&problem, space)
            })
            .0
        };
        let (residuals, parameters) = (time(StepSpace::Residuals), time(StepSpace::Parameters));
        let chosen = StepSpace::for_shape(n, m);
        for (space, t, other, name, other_name) in [
            (
                StepSpace::Residuals,
                residuals,
                parameters,
                "n × n (residuals')",
                "the m × m step",
            ),
            (
                StepSpace::Parameters,
                parameters,
                residuals,
                "m × m (weights')",
                "the n × n step",
            ),
        ] {
            let w = Workload {
                kernel: label,
                size: format!("{n} residuals, {m} weights"),
                items: 1.0,
                unit: "steps/s",
                bytes: 0.0,
                memory_pass: other,
                reference: other_name,
            };
            // The space `step` picks for this shape.
            let engine = if space == chosen {
                format!("{name} *")
            } else {
                name.to_string()
            };
            report.lines.push(w.line(&engine, t, None));
        }
    }
    if let Err(e) = demo_network_lines(o, report) {
        report.notes.push(format!("fit, network skipped: {e}"));
    }
}

/// The network method (`fit --method ffnn`: every width and the retrained
/// pair, then the refits without each training event for the new-event
/// intervals) on the demo season's KPI table (the tiny one with
/// `--small`), one thread and all.
fn demo_network_lines(o: &BenchOptions, report: &mut BenchReport) -> Result<(), String> {
    use crate::model::fit::{FitSettings, Method, fit_method, split};
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let season = BenchSeason {
        preset: if o.small {
            crate::sim::Preset::Tiny
        } else {
            crate::sim::Preset::Demo
        },
        scale: 1.0,
        rate_hz: None,
        effect: None,
    };
    let out = dir.path().join("season");
    let kpis = crate::validate::simulate_and_extract(
        &season.options(crate::ingest::telemetry::Encoding::Block, &out),
    )
    .map_err(|e| e.to_string())?;
    let rows = crate::kpi::table::read_parquet_rows(&kpis).map_err(|e| e.to_string())?;
    let s = split(&rows, None).map_err(|e| e.to_string())?;
    let settings = FitSettings::default();
    let run = || fit_method(Method::Ffnn, &s, &settings).map(|_| ());
    let (t1, fitted) = best(o.repeats, || one_thread(run));
    fitted.map_err(|e| e.to_string())?;
    let w = Workload {
        kernel: "fit, network",
        size: format!("{} tire-runs", rows.len()),
        items: rows.len() as f64,
        unit: "tires/s",
        bytes: 0.0,
        memory_pass: Duration::ZERO,
        reference: "none",
    };
    let (tn, _) = best(o.repeats, run);
    w.push_thread_lines(report, t1, tn);
    Ok(())
}

/// The report as a table.
pub fn render(r: &BenchReport) -> String {
    let mut s = String::new();
    // `cpu` names the model and the thread count (the CPU engine's device).
    let _ = writeln!(s, "CPU: {}", r.cpu);
    let _ = writeln!(s, "GPU: {}", r.gpu.as_deref().unwrap_or("none"));
    let _ = writeln!(
        s,
        "{:<17} {:<28} {:<20} {:>10} {:>14} {:>9} {:>8}  gpu upload/compute/readback",
        "kernel", "size", "engine", "time ms", "rate", "GB/s", "vs ref"
    );
    for l in &r.lines {
        let split = l.gpu_split_s.map_or(String::new(), |[u, c, b]| {
            format!("{:.1} / {:.1} / {:.1} ms", u * 1e3, c * 1e3, b * 1e3)
        });
        let _ = writeln!(
            s,
            "{:<17} {:<28} {:<20} {:>10.2} {:>10.3e} {:>3} {:>9.2} {:>8.2}  {split}",
            l.kernel,
            l.size,
            l.engine,
            l.seconds * 1e3,
            l.items_per_s,
            match l.unit.as_str() {
                "samples/s" => "S/s",
                "tires/s" => "T/s",
                "steps/s" => "st/s",
                _ => "P/s",
            },
            l.gb_per_s,
            l.vs_memory_pass
        );
    }
    let _ = writeln!(
        s,
        "vs ref: the reference's time over this time (kernels: a memory pass over \
         the same bytes; decode: zstd alone decompressing the same chunks; gap: \
         its 10 s target; LM step: the step solved in the other space on the same \
         problem, * the space fit uses; fit, network: none, 0)"
    );
    for x in &r.extract_splits {
        let ms = |v: f64| v * 1e3;
        let _ = writeln!(
            s,
            "{}: extract, 1 thread, {:.0} ms = decoding {:.0} ms (zstd alone {:.0} ms) + \
             cleaning {:.0} ms + reductions and rows {:.0} ms + the rest {:.0} ms \
             (season, road KPIs, writing)",
            x.kernel,
            ms(x.wall_s),
            ms(x.decode_s),
            ms(x.zstd_s),
            ms(x.cleaning_s),
            ms(x.reductions_s),
            ms(x.rest_s)
        );
    }
    for n in &r.notes {
        let _ = writeln!(s, "note: {n}");
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An earlier result (as this build writes it, or pretty-printed by
    /// hand), an empty file or nothing may be replaced; other files may not.
    #[test]
    fn only_an_earlier_result_or_an_empty_file_is_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let at = |name: &str, body: &[u8]| {
            let p = dir.path().join(name);
            std::fs::write(&p, body).unwrap();
            p
        };
        let report = BenchReport {
            cpu: "a CPU".into(),
            gpu: None,
            threads: 2,
            lines: Vec::new(),
            extract_splits: Vec::new(),
            notes: Vec::new(),
        };
        let written = at("bench.json", &serde_json::to_vec_pretty(&report).unwrap());
        let replaceable = [
            written,
            at("hand.json", b"\n  {\"lines\": [], \"cpu\": \"x\"}"),
            at("empty.json", b""),
            dir.path().join("absent.json"),
        ];
        for p in &replaceable {
            assert_eq!(check_output(p, None), Ok(()), "{}", p.display());
        }
        for (name, body, what) in [
            ("k.parquet", &b"PAR1...."[..], "(it is a Parquet file)"),
            ("m.json", b"{\"lines\": 3}", "(it is JSON without"),
            (
                "broken.json",
                b"{\"lines\": [",
                "(it is text, beginning `{\"lines\": [`)",
            ),
            (
                "notes.txt",
                b"  my notes",
                "(it is text, beginning `  my notes`)",
            ),
        ] {
            let p = at(name, body);
            let e = check_output(&p, None).unwrap_err();
            assert_eq!(e.dest, p);
            assert!(e.reason.contains(what), "{e}");
        }
    }
}
