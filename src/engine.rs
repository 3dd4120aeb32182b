//! The engines that run the heavy reductions: a small trait implemented by
//! the CPU engine (the Rust twins of the shaders, rayon) and the GPU engine
//! (wgpu). Tests are written once against the trait and run for both.

use crate::gpu::{GpuContext, GpuError, GpuTimings};
use crate::ingest::road::Profile;
use crate::kpi::cpu::condition_map::{
    ConditionMaps, condition_map_by_wheel, condition_maps_from_quanta, histograms_by_wheel,
};
use crate::kpi::cpu::energy_map::{energy_map, maps_from_quanta};
use crate::kpi::cpu::telemetry_reduce::{ReduceBatch, SUMS, merge, telemetry_reduce};
use crate::kpi::energy_maps::EnergyMaps;
use crate::kpi::road::{RoadCurves, RoadIndices, profile_indices, profile_indices_on};
use crate::kpi::roughness_batch::{RoughnessBatch, Spectral, cpu_twins};
use crate::kpi::telemetry::finish_wheel;
use std::sync::Mutex;

/// Why an engine could not compute: only the GPU engine can fail (its
/// device, a buffer readback, a validation error); the CPU engine cannot.
#[derive(Debug, thiserror::Error)]
pub enum EngineError {
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// Everything the engines compute from one batch of wheel samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Reductions {
    /// Every chunk's partial sums of the telemetry reduction (merge with
    /// `telemetry_reduce::merge`).
    pub partials: Vec<[f64; SUMS]>,
    /// Every wheel's friction-energy maps.
    pub energy_maps: Vec<EnergyMaps>,
    /// Every wheel's condition energy maps.
    pub condition_maps: Vec<ConditionMaps>,
}

/// A reduction engine.
pub trait ReduceEngine: Send + Sync {
    /// "cpu" or "gpu".
    fn name(&self) -> &'static str;
    /// Human-readable device (CPU threads, or the GPU adapter and driver).
    fn device(&self) -> String;
    /// Every chunk's partial sums of the telemetry reduction
    /// (`shaders/telemetry_reduce.wgsl`); merge with `telemetry_reduce::merge`.
    fn telemetry_reduce(&self, batch: &ReduceBatch) -> Result<Vec<[f64; SUMS]>, EngineError>;
    /// Every wheel's friction-energy maps (`shaders/energy_map.wgsl`).
    fn energy_map(&self, batch: &ReduceBatch) -> Result<Vec<EnergyMaps>, EngineError>;
    /// Every wheel's condition energy maps (`shaders/condition_map.wgsl`).
    fn condition_map(&self, batch: &ReduceBatch) -> Result<Vec<ConditionMaps>, EngineError>;
    /// The three above on one batch (the GPU uploads the samples once).
    fn reductions(&self, batch: &ReduceBatch) -> Result<Reductions, EngineError> {
        Ok(Reductions {
            partials: self.telemetry_reduce(batch)?,
            energy_maps: self.energy_map(batch)?,
            condition_maps: self.condition_map(batch)?,
        })
    }
    /// Height moments, HDC and Welch PSD of every profile (the roughness
    /// kernels); finish with `road::profile_indices_from`.
    fn roughness(&self, batch: &RoughnessBatch) -> Result<Vec<Spectral>, EngineError>;
    /// Road indices and curves of every profile, as extraction computes
    /// them: the CPU engine by one real FFT per Welch segment (rayon over
    /// profiles; the `roughness` twins are the reference the GPU is held
    /// to, this route is 5× faster and checked against the same oracles),
    /// the GPU engine by its roughness kernels in batches.
    fn road_indices(
        &self,
        profiles: Vec<Profile>,
    ) -> Result<Vec<(Profile, RoadIndices, RoadCurves)>, EngineError>;
}

/// The CPU engine: the shaders' Rust twins in f64, parallel over chunks.
pub struct CpuEngine;

/// The processor's name as the system gives it (Linux: `/proc/cpuinfo`'s
/// first `model name`), so that a bench file says which machine measured
/// it; "CPU" where the system does not say.
fn cpu_model() -> &'static str {
    static MODEL: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    MODEL.get_or_init(|| {
        std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|info| model_name(&info))
            .unwrap_or_else(|| "CPU".into())
    })
}

/// The first `model name` of a `/proc/cpuinfo` text, spaces collapsed.
fn model_name(cpuinfo: &str) -> Option<String> {
    cpuinfo
        .lines()
        .filter_map(|l| l.split_once(':'))
        .find(|(key, _)| key.trim() == "model name")
        .map(|(_, v)| v.split_whitespace().collect::<Vec<_>>().join(" "))
        .filter(|v| !v.is_empty())
}

impl ReduceEngine for CpuEngine {
    fn name(&self) -> &'static str {
        "cpu"
    }
    fn device(&self) -> String {
        match rayon::current_num_threads() {
            1 => format!("{}, 1 thread", cpu_model()),
            n => format!("{}, {n} threads", cpu_model()),
        }
    }
    fn telemetry_reduce(&self, batch: &ReduceBatch) -> Result<Vec<[f64; SUMS]>, EngineError> {
        Ok(telemetry_reduce(batch))
    }
    fn energy_map(&self, batch: &ReduceBatch) -> Result<Vec<EnergyMaps>, EngineError> {
        Ok(maps_from_quanta(&energy_map(batch)))
    }
    fn condition_map(&self, batch: &ReduceBatch) -> Result<Vec<ConditionMaps>, EngineError> {
        Ok(condition_maps_from_quanta(&condition_map_by_wheel(batch)))
    }
    /// Both histograms in one pass over the samples (the same sums as
    /// `energy_map` and `condition_map`, bit for bit).
    fn reductions(&self, batch: &ReduceBatch) -> Result<Reductions, EngineError> {
        let (energy, conditions) = histograms_by_wheel(batch);
        Ok(Reductions {
            partials: self.telemetry_reduce(batch)?,
            energy_maps: maps_from_quanta(&energy),
            condition_maps: condition_maps_from_quanta(&conditions),
        })
    }
    fn roughness(&self, batch: &RoughnessBatch) -> Result<Vec<Spectral>, EngineError> {
        Ok(cpu_twins(batch))
    }
    fn road_indices(
        &self,
        profiles: Vec<Profile>,
    ) -> Result<Vec<(Profile, RoadIndices, RoadCurves)>, EngineError> {
        use rayon::prelude::*;
        Ok(profiles
            .into_par_iter()
            .map(|p| {
                let (i, c) = profile_indices(&p);
                (p, i, c)
            })
            .collect())
    }
}

/// The GPU engine: one context (device, pipelines, reusable buffers) for all
/// runs; calls from several threads take turns on the queue.
pub struct GpuEngine {
    pub ctx: GpuContext,
    timings: Mutex<GpuTimings>,
}

impl GpuEngine {
    pub fn new() -> Result<GpuEngine, GpuError> {
        Ok(Self::with(GpuContext::new()?))
    }
    /// A hardware GPU's engine, or the software adapter's description
    /// (nothing built on it): see [`GpuContext::new_hardware`].
    pub fn new_hardware() -> Result<Result<GpuEngine, wgpu::AdapterInfo>, GpuError> {
        Ok(GpuContext::new_hardware()?.map(Self::with))
    }
    fn with(ctx: GpuContext) -> GpuEngine {
        GpuEngine {
            ctx,
            timings: Mutex::new(GpuTimings::default()),
        }
    }
    /// Upload, compute and readback time summed over every call so far.
    pub fn timings(&self) -> GpuTimings {
        *self.timings.lock().expect("timings lock")
    }
}

impl ReduceEngine for GpuEngine {
    fn name(&self) -> &'static str {
        "gpu"
    }
    fn device(&self) -> String {
        let a = &self.ctx.adapter;
        format!(
            "{} ({:?}, {:?}, {})",
            a.name, a.device_type, a.backend, a.driver_info
        )
    }
    fn telemetry_reduce(&self, batch: &ReduceBatch) -> Result<Vec<[f64; SUMS]>, EngineError> {
        let (p, t) = self.ctx.telemetry_reduce(batch)?;
        self.timings.lock().expect("timings lock").add(&t);
        Ok(p)
    }
    fn energy_map(&self, batch: &ReduceBatch) -> Result<Vec<EnergyMaps>, EngineError> {
        let (p, t) = self.ctx.energy_map(batch)?;
        self.timings.lock().expect("timings lock").add(&t);
        Ok(p)
    }
    fn condition_map(&self, batch: &ReduceBatch) -> Result<Vec<ConditionMaps>, EngineError> {
        let (p, t) = self.ctx.condition_map(batch)?;
        self.timings.lock().expect("timings lock").add(&t);
        Ok(p)
    }
    fn reductions(&self, batch: &ReduceBatch) -> Result<Reductions, EngineError> {
        let (p, t) = self.ctx.reductions(batch)?;
        self.timings.lock().expect("timings lock").add(&t);
        Ok(p)
    }
    fn roughness(&self, batch: &RoughnessBatch) -> Result<Vec<Spectral>, EngineError> {
        let (p, t) = self.ctx.roughness(batch)?;
        self.timings.lock().expect("timings lock").add(&t);
        Ok(p)
    }
    fn road_indices(
        &self,
        profiles: Vec<Profile>,
    ) -> Result<Vec<(Profile, RoadIndices, RoadCurves)>, EngineError> {
        profile_indices_on(profiles, self)
    }
}

/// The GPU engine for a test, or None with a message when this machine has no
/// adapter. With `TIREWEAR_REQUIRE_GPU=1` (set by `.ci/run`, which installs
/// Mesa's lavapipe) a missing adapter fails the test instead.
pub fn gpu_for_tests(test: &str) -> Option<GpuEngine> {
    match GpuEngine::new() {
        Ok(g) => Some(g),
        Err(e) if std::env::var("TIREWEAR_REQUIRE_GPU").is_ok_and(|v| v == "1") => {
            panic!("{test}: TIREWEAR_REQUIRE_GPU=1 but {e}")
        }
        Err(e) => {
            eprintln!("{test}: GPU part skipped: {e}");
            None
        }
    }
}

/// Tolerance of the GPU telemetry reduction against the CPU's f64: relative
/// 1e-5 of each index, and for a mean of |mean| + standard deviation (a mean
/// near zero, such as Fy's, is judged against its spread). Why: f32 rounds at
/// 6e-8; a chunk's sum sees at most 8 sequential and 7 tree additions
/// (≈ 1e-6 of Σ|terms|), chunks are merged in f64, and the per-sample slip
/// v_x − ω·r loses a few ulps of v_x. Measured on the demo season: ≤ 1e-7,
/// except Fy's mean (1e-5 of its value, 1e-8 of its spread).
pub const TELEMETRY_TOLERANCE: f64 = 1e-5;

/// Largest scaled difference between two engines on one batch, per index.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Comparison {
    /// (index name, largest scaled difference over the batch's wheels).
    pub errors: Vec<(String, f64)>,
    pub tolerance: f64,
}

impl Comparison {
    pub fn worst(&self) -> (&str, f64) {
        self.errors
            .iter()
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map_or(("", 0.0), |(n, e)| (n.as_str(), *e))
    }
    pub fn passes(&self) -> bool {
        self.worst().1 <= self.tolerance
    }
}

/// Runs the telemetry reduction on both engines and compares the finished
/// table-4 indices of every wheel (the one helper every parity test uses).
pub fn compare_telemetry(
    reference: &dyn ReduceEngine,
    other: &dyn ReduceEngine,
    batch: &ReduceBatch,
) -> Result<Comparison, EngineError> {
    let finish = |e: &dyn ReduceEngine| -> Result<Vec<serde_json::Value>, EngineError> {
        let sums = merge(batch, &e.telemetry_reduce(batch)?);
        Ok(sums
            .iter()
            .zip(&batch.refs)
            .map(|(s, r)| {
                finish_wheel(s, r).map_or(serde_json::Value::Null, |k| {
                    serde_json::to_value(k).expect("indices")
                })
            })
            .collect())
    };
    let (a, b) = (finish(reference)?, finish(other)?);
    let mut errors: Vec<(String, f64)> = Vec::new();
    for (x, y) in a.iter().zip(&b) {
        let (Some(x), Some(y)) = (x.as_object(), y.as_object()) else {
            continue;
        };
        for (name, v) in x {
            let (v, w) = (
                v.as_f64().unwrap_or(f64::NAN),
                y[name].as_f64().unwrap_or(f64::NAN),
            );
            let spread = x
                .get(&name.replace("_avg_", "_std_"))
                .filter(|_| name.contains("_avg_"))
                .and_then(|s| s.as_f64())
                .unwrap_or(0.0);
            let scale = v.abs() + spread;
            let e = if scale > 0.0 {
                (v - w).abs() / scale
            } else {
                (v - w).abs()
            };
            match errors.iter_mut().find(|(n, _)| n == name) {
                Some(slot) => slot.1 = slot.1.max(e),
                None => errors.push((name.clone(), e)),
            }
        }
    }
    Ok(Comparison {
        errors,
        tolerance: TELEMETRY_TOLERANCE,
    })
}

/// Tolerance of the GPU energy maps against the CPU's, per wheel: the summed
/// |difference| over all bins at most 1e-4 of the summed |energy|. Why: both
/// engines sum exact fixed-point quanta, so only each sample's energy differs
/// (f32 against f64, ≈ 1e-7 relative, rounded to 6e-8 J), and a sample whose
/// sliding speed or temperature lies within f32 rounding (~1e-6) of a bin
/// edge may fall in the neighbouring bin on one side only; such samples are
/// rare, each moves one sample's energy (3.5e-5 measured on a whole season).
pub const ENERGY_MAP_TOLERANCE: f64 = 1e-4;

/// Largest per-wheel L1 difference of the maps, relative to the wheel's summed |energy|.
pub fn compare_energy_maps(
    reference: &dyn ReduceEngine,
    other: &dyn ReduceEngine,
    batch: &ReduceBatch,
) -> Result<f64, EngineError> {
    let a = reference.energy_map(batch)?;
    let b = other.energy_map(batch)?;
    let mut worst = 0.0f64;
    for (x, y) in a.iter().zip(&b) {
        let bins = |m: &EnergyMaps| -> Vec<f64> {
            m.surface_inner
                .iter()
                .chain(&m.speed_surface)
                .chain(&m.lateral_surface_inner)
                .copied()
                .collect()
        };
        let (x, y) = (bins(x), bins(y));
        let scale: f64 = x.iter().map(|v| v.abs()).sum();
        let diff: f64 = x.iter().zip(&y).map(|(u, v)| (u - v).abs()).sum();
        worst = worst.max(if scale > 0.0 { diff / scale } else { diff });
    }
    Ok(worst)
}

/// Tolerance of the GPU condition maps against the CPU's: for every wheel,
/// condition (or pair of conditions) and energy component, the summed
/// |difference| over the map's bins at most 1e-3 of its summed |energy|. Why: the sums are
/// exact integers on both engines, and raw channels are binned from the same
/// f32 value with correctly rounded f32 operations on both, so they agree
/// bin for bin; the ratios (slip ratio, lateral and combined slip, friction
/// utilisation) take a square root and a division, which the GPU rounds
/// within a few ulps and the CPU computes in f64. A value within that of a
/// bin edge may land on either side — and a simulator's tire force that
/// saturates at μ·F_z holds the utilisation exactly on an edge for a whole
/// slide. Measured on a whole season on an H100: median 2e-8, worst 3.2e-4
/// (friction utilisation).
pub const CONDITION_MAP_TOLERANCE: f64 = 1e-3;

/// Tolerance of the GPU pair maps against the CPU's, per wheel and pair,
/// as for the 1-D maps. Why wider: the same flips at an edge, on finer bins
/// (the slips' pair bins are 0.01–0.015 wide against 0.02) — a smooth slip
/// signal whose peak sits on an edge (±0.03 in `tests/engines.rs`'s
/// full-length run) flips a few samples at every peak: measured 1.2e-3 on a
/// 20 s wheel on lavapipe, 1.3e-4 on the 1 h one.
pub const PAIR_MAP_TOLERANCE: f64 = 2e-3;

/// Largest L1 difference of one condition map of one component and wheel,
/// relative to that map's summed |energy|: (the 1-D maps, the pair maps).
pub fn compare_condition_maps(
    reference: &dyn ReduceEngine,
    other: &dyn ReduceEngine,
    batch: &ReduceBatch,
) -> Result<(f64, f64), EngineError> {
    use crate::kpi::cpu::condition_map::{CONDITIONS, Component, N_PAIRS};
    let (a, b) = (reference.condition_map(batch)?, other.condition_map(batch)?);
    let (mut worst, mut worst_pair) = (0.0f64, 0.0f64);
    for (x, y) in a.iter().zip(&b) {
        // The 1-D maps, then the pairs' 2-D maps (total energy only).
        for k in 0..CONDITIONS.len() + N_PAIRS {
            for comp in Component::ALL {
                let (u, v) = if k < CONDITIONS.len() {
                    (x.map(comp, k), y.map(comp, k))
                } else if comp == Component::Total {
                    let p = k - CONDITIONS.len();
                    (x.pair_map(p), y.pair_map(p))
                } else {
                    continue;
                };
                let scale: f64 = u.iter().map(|e| e.abs()).sum();
                let diff: f64 = u.iter().zip(v).map(|(p, q)| (p - q).abs()).sum();
                let d = if scale > 0.0 { diff / scale } else { diff };
                if k < CONDITIONS.len() {
                    worst = worst.max(d);
                } else {
                    worst_pair = worst_pair.max(d);
                }
            }
        }
    }
    Ok((worst, worst_pair))
}

/// Tolerances of the GPU roughness against the CPU's f64: (moments and HDC,
/// PSD per log band in the Hurst band). Moments and HDC: f32 sums over ≤ 1024
/// samples merged in f64 (skewness compared absolutely, being near 0). PSD:
/// 48 log bands inside 0.1–5 mm, where H is fitted; an f32 FFT of 4096 points
/// has a noise floor near 1e-14 of the peak power, far below the band, and
/// the spectrum above a profile's own cut-off is that floor on both sides.
pub const ROUGHNESS_TOLERANCE: (f64, f64) = (1e-5, 1e-5);

/// Largest differences between two engines' roughness on one batch:
/// (moments, HDC, PSD per log band in the Hurst band), each relative.
pub fn compare_roughness(
    reference: &dyn ReduceEngine,
    other: &dyn ReduceEngine,
    batch: &RoughnessBatch,
) -> Result<(f64, f64, f64), EngineError> {
    use crate::kpi::road::{HURST_BAND_MM, log_bin};
    let (a, b) = (reference.roughness(batch)?, other.roughness(batch)?);
    let band = (
        std::f64::consts::TAU / HURST_BAND_MM.1,
        std::f64::consts::TAU / HURST_BAND_MM.0,
    );
    let (mut m, mut h, mut p) = (0.0f64, 0.0f64, 0.0f64);
    for (x, y) in a.iter().zip(&b) {
        let rel = |u: f64, v: f64| (u - v).abs() / u.abs().max(1e-300);
        m = m
            .max(rel(x.moments.0, y.moments.0))
            .max(rel(x.moments.1, y.moments.1))
            .max((x.moments.2 - y.moments.2).abs())
            .max(rel(x.moments.3, y.moments.3));
        for (u, v) in x.hdc_c.iter().zip(&y.hdc_c) {
            h = h.max(rel(*u, *v));
        }
        let (bq, bx) = log_bin(&x.psd_q, &x.psd_c, 48);
        let (_, by) = log_bin(&y.psd_q, &y.psd_c, 48);
        for ((q, u), v) in bq.iter().zip(&bx).zip(&by) {
            if *q >= band.0 && *q <= band.1 {
                p = p.max(rel(*u, *v));
            }
        }
    }
    Ok((m, h, p))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn model_name_is_the_first_one_spaces_collapsed() {
        let info = "processor\t: 0\nvendor_id\t: AuthenticAMD\nmodel name\t: AMD EPYC  7B13 64-Core Processor\n\n\
                    processor\t: 1\nmodel name\t: other\n";
        assert_eq!(
            model_name(info).as_deref(),
            Some("AMD EPYC 7B13 64-Core Processor")
        );
        // ARM's cpuinfo has no model name; an empty one does not count.
        assert_eq!(model_name("processor\t: 0\nBogoMIPS\t: 50.00\n"), None);
        assert_eq!(model_name("model name\t:   \n"), None);
    }
}
