//! The engines that run the heavy reductions: a small trait implemented by
//! the CPU engine (the Rust twins of the shaders, rayon) and the GPU engine
//! (wgpu). Tests are written once against the trait and run for both.

use crate::gpu::{GpuContext, GpuError, GpuTimings};
use crate::kpi::telemetry_reduce::{ReduceBatch, SUMS, telemetry_reduce};
use std::sync::Mutex;

/// A reduction engine.
pub trait ReduceEngine: Send + Sync {
    /// "cpu" or "gpu".
    fn name(&self) -> &'static str;
    /// Human-readable device (CPU threads, or the GPU adapter and driver).
    fn device(&self) -> String;
    /// Every chunk's partial sums of the telemetry reduction
    /// (`shaders/telemetry_reduce.wgsl`); merge with `telemetry_reduce::merge`.
    fn telemetry_reduce(&self, batch: &ReduceBatch) -> Result<Vec<[f64; SUMS]>, GpuError>;
}

/// The CPU engine: the shaders' Rust twins in f64, parallel over chunks.
pub struct CpuEngine;

impl ReduceEngine for CpuEngine {
    fn name(&self) -> &'static str {
        "cpu"
    }
    fn device(&self) -> String {
        format!("CPU, {} threads", rayon::current_num_threads())
    }
    fn telemetry_reduce(&self, batch: &ReduceBatch) -> Result<Vec<[f64; SUMS]>, GpuError> {
        Ok(telemetry_reduce(batch))
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
        Ok(GpuEngine {
            ctx: GpuContext::new()?,
            timings: Mutex::new(GpuTimings::default()),
        })
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
    fn telemetry_reduce(&self, batch: &ReduceBatch) -> Result<Vec<[f64; SUMS]>, GpuError> {
        let (p, t) = self.ctx.telemetry_reduce(batch)?;
        self.timings.lock().expect("timings lock").add(&t);
        Ok(p)
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
