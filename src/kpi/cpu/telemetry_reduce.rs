//! CPU twin of `shaders/telemetry_reduce.wgsl`: per-sample slip, sliding
//! velocities and friction power, reduced into the sums behind table 4.
//! Written loop-for-loop like the shader (same workgroup size, same items per
//! thread, same tree) but in f64, so it is the reference the GPU is held to.
//!
//! Each workgroup reduces one chunk of up to `CHUNK` samples of one wheel
//! into `SUMS` partial sums; partials are merged per wheel in f64 on the CPU
//! (both engines), so the GPU's f32 error stays that of ≤ 1024 samples.

use bytemuck::{Pod, Zeroable};
use rayon::prelude::*;

/// Threads per workgroup. Must match `WG_SIZE` in shaders/telemetry_reduce.wgsl (checked by tests/shader_contract.rs).
pub const WG_SIZE: usize = 128;
/// Samples per thread. Must match `ITEMS` in the shader (checked by tests/shader_contract.rs).
pub const ITEMS: usize = 8;
/// Samples per chunk (one workgroup).
pub const CHUNK: usize = WG_SIZE * ITEMS;
/// Sums per chunk. Must match `SUMS` in the shader (checked by tests/shader_contract.rs); the order is [`Sum`]'s (the engine parity tests catch a mismatch).
pub const SUMS: usize = 22;

/// What each sum is (index into a chunk's partials).
pub struct Sum;
impl Sum {
    /// Σ(q − ref) for q = T_surf, T_inner, Fx, Fy, Fz, |v_sx|, |v_sy| (indices 0..7).
    pub const SHIFTED: usize = 0;
    /// Σ(q − ref)² for the same seven quantities (indices 7..14).
    pub const SHIFTED_SQ: usize = 7;
    /// Σ −Fx·v_sx·dt (J).
    pub const ENERGY_X: usize = 14;
    /// Σ −Fy·v_sy·dt (J).
    pub const ENERGY_Y: usize = 15;
    /// Σ |v_s|·dt (m).
    pub const SLIDING_DISTANCE: usize = 16;
    /// Σ dt (s).
    pub const DURATION: usize = 17;
    pub const CAMBER: usize = 18;
    pub const PRESSURE: usize = 19;
    /// Σ Fz/(p + p_carcass)·1e6 (mm²).
    pub const CONTACT_PATCH: usize = 20;
    pub const COUNT: usize = 21;
}

/// One kept sample, as uploaded. Must match `Sample` in the shader (checked by tests/shader_contract.rs).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct ReduceSample {
    pub vx: f32,
    pub vy: f32,
    pub omega: f32,
    pub radius: f32,
    pub fx: f32,
    pub fy: f32,
    pub fz: f32,
    pub t_surface: f32,
    pub t_inner: f32,
    pub pressure: f32,
    pub camber: f32,
    /// Derived by the host from the wheel's kept samples (docs/kpis.md,
    /// "Condition energy maps"); only the condition maps read them.
    /// dT_surface/dt over the kept samples within ±0.5 s (K/s).
    pub t_surface_rate: f32,
    /// dT_inner/dt over the kept samples within ±0.5 s (K/s).
    pub t_inner_rate: f32,
    /// F_z over the wheel's mean F_z in the run.
    pub load_rel: f32,
    /// Time since the wheel's first kept sample (s).
    pub time_s: f32,
    /// Σ v_x·Δt over the kept samples before this one (m).
    pub distance_m: f32,
    /// dv_x/dt over the kept samples within ±0.5 s (m/s²): the wheel
    /// centre's longitudinal acceleration, braking negative.
    pub accel_x: f32,
    /// |Σ F_y| / m over the car's four wheels at this sample (m/s²): the
    /// car's lateral acceleration; NaN where the wheel was reduced alone.
    pub accel_y: f32,
    /// Time this sample stands for (s), from the cleaning rule, as f32 …
    pub dt: f32,
    /// … and the rest of the f64 value (dt − dt as f32): the CPU adds it, so
    /// its sums are those of the f64 times; the shader ignores it.
    pub dt_lo: f32,
}

impl ReduceSample {
    /// Splits an f64 time step into its f32 value and remainder.
    pub fn split_dt(dt: f64) -> (f32, f32) {
        let hi = dt as f32;
        (hi, (dt - hi as f64) as f32)
    }
}

/// One workgroup's slice of the samples. Must match `Chunk` in the shader (checked by tests/shader_contract.rs).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct ReduceChunk {
    pub start: u32,
    pub count: u32,
    pub wheel: u32,
    pub pad: u32,
}

/// Per-wheel shift of the seven moment quantities (first kept sample), so
/// that f32 sums of squares do not cancel. Must match `Reference` (checked by tests/shader_contract.rs).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct ReduceRef {
    pub v: [f32; 8],
}

/// Mean contact pressure model (Pa): `telemetry::CARCASS_PRESSURE_PA` in
/// the shader's f32 (tests/shader_contract.rs checks the shader's copy).
pub const CARCASS_PRESSURE_PA: f32 = crate::kpi::telemetry::CARCASS_PRESSURE_PA as f32;

/// A batch of wheels: their samples back to back, cut into chunks.
#[derive(Debug, Clone, Default)]
pub struct ReduceBatch {
    pub samples: Vec<ReduceSample>,
    pub chunks: Vec<ReduceChunk>,
    pub refs: Vec<ReduceRef>,
}

impl ReduceBatch {
    /// Appends one wheel's kept samples; returns its index in the batch.
    pub fn push_wheel(&mut self, samples: &[ReduceSample]) -> usize {
        let start = self.samples.len();
        self.samples.extend_from_slice(samples);
        self.register_wheel(start)
    }

    /// Appends one wheel whose samples `fill` writes straight onto the
    /// batch's (no copy through a vector of its own); a wheel `fill`
    /// rejects leaves the batch as it was.
    pub(crate) fn push_wheel_with<R, E>(
        &mut self,
        fill: impl FnOnce(&mut Vec<ReduceSample>) -> Result<R, E>,
    ) -> Result<R, E> {
        let start = self.samples.len();
        match fill(&mut self.samples) {
            Ok(r) => {
                self.register_wheel(start);
                Ok(r)
            }
            Err(e) => {
                self.samples.truncate(start);
                Err(e)
            }
        }
    }

    /// Makes the samples from `start` on one more wheel: its reference and
    /// chunks. Returns its index.
    fn register_wheel(&mut self, start: usize) -> usize {
        let wheel = self.refs.len();
        let samples = &self.samples[start..];
        let first = samples.first().copied().unwrap_or_default();
        let vsx = (first.vx - first.omega * first.radius).abs();
        self.refs.push(ReduceRef {
            v: [
                first.t_surface,
                first.t_inner,
                first.fx,
                first.fy,
                first.fz,
                vsx,
                first.vy.abs(),
                0.0,
            ],
        });
        for (k, c) in samples.chunks(CHUNK).enumerate() {
            self.chunks.push(ReduceChunk {
                start: (start + k * CHUNK) as u32,
                count: c.len() as u32,
                wheel: wheel as u32,
                pad: 0,
            });
        }
        wheel
    }

    pub fn wheels(&self) -> usize {
        self.refs.len()
    }
}

/// The per-sample terms of the sums (shader: the body of the item loop).
#[inline]
fn terms(p: &ReduceSample, r: &ReduceRef, s: &mut [f64; SUMS]) {
    let f = |x: f32| x as f64;
    let dt = f(p.dt) + f(p.dt_lo);
    let v_sx = f(p.vx) - f(p.omega) * f(p.radius); // eq. 21
    let v_sy = f(p.vy); // eq. 22
    let p_x = -f(p.fx) * v_sx; // eq. 23, dissipation sign
    let p_y = -f(p.fy) * v_sy; // eq. 24
    let v_s = (v_sx * v_sx + v_sy * v_sy).sqrt();
    let q = [
        f(p.t_surface) - f(r.v[0]),
        f(p.t_inner) - f(r.v[1]),
        f(p.fx) - f(r.v[2]),
        f(p.fy) - f(r.v[3]),
        f(p.fz) - f(r.v[4]),
        v_sx.abs() - f(r.v[5]),
        v_sy.abs() - f(r.v[6]),
    ];
    for m in 0..7 {
        s[Sum::SHIFTED + m] += q[m];
        s[Sum::SHIFTED_SQ + m] += q[m] * q[m];
    }
    s[Sum::ENERGY_X] += p_x * dt;
    s[Sum::ENERGY_Y] += p_y * dt;
    s[Sum::SLIDING_DISTANCE] += v_s * dt;
    s[Sum::DURATION] += dt;
    s[Sum::CAMBER] += f(p.camber);
    s[Sum::PRESSURE] += f(p.pressure);
    s[Sum::CONTACT_PATCH] += f(p.fz) / (f(p.pressure) + f(CARCASS_PRESSURE_PA)) * 1e6;
    s[Sum::COUNT] += 1.0;
}

/// One workgroup: per-thread accumulation, then the shared-memory tree.
fn workgroup(batch: &ReduceBatch, chunk: &ReduceChunk) -> [f64; SUMS] {
    let r = &batch.refs[chunk.wheel as usize];
    let mut acc = [[0.0f64; SUMS]; WG_SIZE];
    for (lid, s) in acc.iter_mut().enumerate() {
        for k in 0..ITEMS {
            let j = lid + k * WG_SIZE; // the shader's coalesced stride
            if j < chunk.count as usize {
                terms(&batch.samples[chunk.start as usize + j], r, s);
            }
        }
    }
    let mut stride = WG_SIZE / 2;
    while stride > 0 {
        for lid in 0..stride {
            let other = acc[lid + stride];
            for (a, o) in acc[lid].iter_mut().zip(other) {
                *a += o;
            }
        }
        stride /= 2;
    }
    acc[0]
}

/// The CPU engine's kernel: every chunk's partial sums (rayon over chunks).
pub fn telemetry_reduce(batch: &ReduceBatch) -> Vec<[f64; SUMS]> {
    batch
        .chunks
        .par_iter()
        .map(|c| workgroup(batch, c))
        .collect()
}

/// Merges chunk partials into per-wheel sums (f64, chunk order).
pub fn merge(batch: &ReduceBatch, partials: &[[f64; SUMS]]) -> Vec<[f64; SUMS]> {
    let mut out = vec![[0.0; SUMS]; batch.wheels()];
    for (c, p) in batch.chunks.iter().zip(partials) {
        for m in 0..SUMS {
            out[c.wheel as usize][m] += p[m];
        }
    }
    out
}

/// Means and population standard deviations of the seven moment quantities.
pub fn moments(sums: &[f64; SUMS], r: &ReduceRef) -> [(f64, f64); 7] {
    let n = sums[Sum::COUNT].max(1.0);
    std::array::from_fn(|m| {
        let mean_shifted = sums[Sum::SHIFTED + m] / n;
        let var = (sums[Sum::SHIFTED_SQ + m] / n - mean_shifted * mean_shifted).max(0.0);
        (r.v[m] as f64 + mean_shifted, var.sqrt())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_wheel_filled_in_place_is_a_pushed_wheel_and_a_rejected_one_nothing() {
        let s = |vx: f32| ReduceSample {
            vx,
            fz: 4000.0,
            ..Default::default()
        };
        let first: Vec<_> = (0..3).map(|i| s(i as f32)).collect();
        let second: Vec<_> = (0..CHUNK + 5).map(|i| s(10.0 + i as f32)).collect();
        let mut pushed = ReduceBatch::default();
        pushed.push_wheel(&first);
        pushed.push_wheel(&second);
        let mut filled = ReduceBatch::default();
        filled.push_wheel(&first);
        let rejected: Result<(), &str> = filled.push_wheel_with(|out| {
            out.push(s(99.0));
            Err("bad wheel")
        });
        assert_eq!(rejected, Err("bad wheel"));
        filled
            .push_wheel_with(|out| {
                out.extend_from_slice(&second);
                Ok::<(), ()>(())
            })
            .unwrap();
        assert_eq!(filled.samples, pushed.samples);
        assert_eq!(filled.refs, pushed.refs);
        assert_eq!(
            format!("{:?}", filled.chunks),
            format!("{:?}", pushed.chunks)
        );
    }

    #[test]
    fn chunks_cover_each_wheel_and_merge_by_hand() {
        let mut b = ReduceBatch::default();
        let (dt, dt_lo) = ReduceSample::split_dt(0.001);
        let s = ReduceSample {
            vx: 50.5,
            omega: 100.0,
            radius: 0.5,
            fx: 1000.0,
            fz: 4000.0,
            pressure: 160_000.0,
            t_surface: 80.0,
            dt,
            dt_lo,
            ..Default::default()
        };
        b.push_wheel(&vec![s; 2500]);
        b.push_wheel(&vec![s; 10]);
        assert_eq!(b.chunks.len(), 4); // 1024 + 1024 + 452, then 10
        assert_eq!(b.chunks[2].count, 452);
        assert_eq!(b.chunks[3].wheel, 1);
        let sums = merge(&b, &telemetry_reduce(&b));
        // v_sx = 50.5 − 50 = 0.5 m/s (exact in f32); P_x = −1000·0.5 = −500 W; 2500 samples of 1 ms.
        assert!((sums[0][Sum::ENERGY_X] - (-500.0 * 2.5)).abs() < 1e-9);
        assert!((sums[0][Sum::DURATION] - 2.5).abs() < 1e-12);
        assert_eq!(sums[0][Sum::COUNT], 2500.0);
        assert_eq!(sums[1][Sum::COUNT], 10.0);
        // Contact patch: 4000/(160 000 + 40 000)·1e6 = 20 000 mm² per sample.
        assert!((sums[1][Sum::CONTACT_PATCH] - 200_000.0).abs() < 1e-6);
        let m = moments(&sums[0], &b.refs[0]);
        assert!((m[0].0 - 80.0).abs() < 1e-12 && m[0].1 == 0.0);
        assert!((m[5].0 - 0.5).abs() < 1e-12);
    }
}
